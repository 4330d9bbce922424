"""The frames of the side-by-side video: what each frame shows (`FramePlan`, computed once by
`render_tracks`) and the renderer that draws and encodes any range of them (`FrameWriter`), in this
thread or in several drawing threads (`runner.render.parallel`)."""
from __future__ import annotations

import copy
import time
from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np

from runner.render.encode import FrameEncoder
from runner.render.gl import make_renderer
from runner.render.overlays import (
    KEYFRAME_CAPTION_SECONDS,
    Overlay,
    Panel,
    current_keyframes,
    deep_sites,
    ghost_alphas,
    ghost_data,
)
from runner.render.tracks import (
    Camera,
    Track,
    azimuth_path,
    frame_times,
    interpolate_samples,
    lookat_path,
    root_poses,
    sample_track,
)


@dataclass(frozen=True, eq=False)
class FramePlan:
    """What every frame of a video shows, computed once (read only while the frames are drawn).

    Every thread that draws frames of the video makes its own OpenGL context and scene from this, so
    frame i is the same picture whichever thread draws it.

    Attributes:
        model: MjModel of the scene (not changed).
        tracks: the paths, one panel each, left to right (their keyframe poses are the ghosts when
            `kf_q` is None: `ghost_data`).
        times: (n,) [s] motion time of each video frame.
        qposes: per panel the (n, nq) pose of each frame.
        depths: per panel (n, s) [m] contact-site depths inside a surface, or None.
        planted: per panel (n, s) bool planted sites, or None.
        site_ids: per panel (s,) MuJoCo site ids of the track's `sites`.
        lookat: (n, 3) [m] the camera's look-at point per frame (`lookat_path`).
        azimuth: (n,) [deg] the camera's azimuth per frame (`azimuth_path`).
        currents: (n,) the keyframe captioned in each frame, -1 for none (`current_keyframes`).
        kf_t: (m,) [s] keyframe times or None. kf_q: (m, nq) keyframe poses or None.
        camera: distance and elevation of the camera.
        quality: a `QUALITIES` preset. shadow_size: [px] the shadow map's cap (`shadow_map_size`).
        width, height: [px] of the whole video. panel_w, panel_h: [px] of one panel.
        title: caption above the panels, or None. fps: [1/s]. speed: playback speed.
        t0, t1: [s] the time range shown (the union of the tracks'; the timeline's ends).
    """

    model: object
    tracks: tuple[Track, ...]
    times: np.ndarray
    qposes: tuple[np.ndarray, ...]
    depths: tuple[np.ndarray | None, ...]
    planted: tuple[np.ndarray | None, ...]
    site_ids: tuple[np.ndarray, ...]
    lookat: np.ndarray
    azimuth: np.ndarray
    currents: np.ndarray
    kf_t: np.ndarray | None
    kf_q: np.ndarray | None
    camera: Camera
    quality: str
    shadow_size: int
    width: int
    height: int
    panel_w: int
    panel_h: int
    title: str | None
    fps: float
    speed: float
    t0: float
    t1: float

    @property
    def n_frames(self) -> int:
        """Number of video frames."""
        return int(self.times.size)

    @classmethod
    def build(cls, model, tracks, site_ids, kf_t, kf_q, *, fps: float, speed: float, camera: Camera,
              quality: str, shadow_size: int, size: tuple[int, int], panel_size: tuple[int, int],
              title: str | None) -> FramePlan:
        """The plan of `render_tracks` from its checked arguments: frame times over the union of the
        tracks' time ranges at `speed` (`frame_times`), each track sampled at them (`sample_track`),
        the camera's path (`lookat_path`, `azimuth_path`) and the captioned keyframes."""
        t0 = min(float(tr.times[0]) for tr in tracks)
        t1 = max(float(tr.times[-1]) for tr in tracks)
        times = frame_times(t0, t1, fps, speed)
        qposes = tuple(sample_track(tr, times) for tr in tracks)
        depths = tuple(None if tr.penetration is None else interpolate_samples(tr.times, tr.penetration, times)
                       for tr in tracks)
        planted = tuple(None if tr.planted is None else
                        interpolate_samples(tr.times, tr.planted.astype(float), times) > 0.5 for tr in tracks)
        data = mujoco.MjData(model)
        positions, facing = root_poses(model, data, qposes)
        lookat = lookat_path(model, data, qposes, speed / fps, camera, positions)
        azimuth = azimuth_path(positions, speed / fps, camera, facing)
        currents = current_keyframes(times, kf_t, KEYFRAME_CAPTION_SECONDS * speed)
        return cls(model=model, tracks=tuple(tracks), times=times, qposes=qposes, depths=depths,
                   planted=planted, site_ids=tuple(site_ids), lookat=np.asarray(lookat, float),
                   azimuth=np.asarray(azimuth, float), currents=np.asarray(currents, int), kf_t=kf_t,
                   kf_q=kf_q, camera=camera, quality=quality, shadow_size=int(shadow_size), width=size[0],
                   height=size[1], panel_w=panel_size[0], panel_h=panel_size[1], title=title, fps=fps,
                   speed=speed, t0=t0, t1=t1)


class FrameWriter:
    """Draws frames of a `FramePlan` and encodes ranges of them into video files (H.264).

    Owns one OpenGL renderer of the panel size (made on construction, freed by `close`; use as a
    context manager), reused for every panel of every frame it draws. The renderer is made from a
    copy of the model (`make_renderer` changes the model's `vis` fields while it makes the context),
    so writers can be made in one thread while others draw.

    Attributes:
        render_s: [s] wall time spent posing, rendering and reading back panels (not encoding).
        panels: number of panels drawn.
        child_cpu_s: [s] CPU time of the ffmpeg encoders of the files written.

    Raises:
        InputError: no working OpenGL backend (`make_renderer`).
    """

    def __init__(self, plan: FramePlan):
        self.plan = plan
        self.renderer = make_renderer(copy.copy(plan.model), plan.panel_w, plan.panel_h, plan.quality, plan.shadow_size)
        try:
            self.panel = Panel(plan.model, self.renderer, plan.quality)
            self.ghosts = ghost_data(plan.model, plan.tracks, plan.kf_t, plan.kf_q)
            self.overlay = Overlay(plan.width, plan.height, plan.panel_w, len(plan.tracks), plan.title,
                                   plan.t0, plan.t1, plan.kf_t)
        except BaseException:
            self.renderer.close()
            raise
        self.labels = [tr.label for tr in plan.tracks]
        self.render_s = 0.0
        self.panels = 0
        self.child_cpu_s = 0.0

    def write(self, frames: range, path, tick: Callable[[], None] | None = None) -> None:
        """Write frames `frames` (indices into the plan) as one video file at `path`, in order.

        tick: called after each frame is handed to the encoder (progress, a stop check: an exception
        it raises aborts the file)."""
        plan = self.plan
        with FrameEncoder(path, plan.fps, self.overlay.compose) as encoder:
            for i in frames:
                images, marks, dots = self.frame(i)
                encoder.put(images, self.labels, plan.times[i], plan.speed, int(plan.currents[i]), marks, dots)
                if tick is not None:
                    tick()
        self.child_cpu_s += encoder.child_cpu_s

    def frame(self, i: int):
        """The panels of frame i: (images [(h, w, 3) uint8], magenta marks, green dots), per panel as
        `_panel_frame` returns them."""
        r0 = time.perf_counter()
        plan, panel = self.plan, self.panel
        current = int(plan.currents[i])
        alphas = ghost_alphas(plan.times[i], plan.kf_t)
        images, marks, dots = [], [], []
        for p in range(len(plan.tracks)):
            panel.set_camera(plan.camera, plan.lookat[i], plan.azimuth[i])
            image, mark, dot = _panel_frame(panel, plan.qposes[p][i], self.ghosts[p], current, alphas,
                                            plan.depths[p], plan.planted[p], plan.site_ids[p], i)
            images.append(image)
            marks.append(mark)
            dots.append(dot)
        self.render_s += time.perf_counter() - r0
        self.panels += len(images)
        return images, marks, dots

    def close(self) -> None:
        """Free the OpenGL renderer."""
        self.renderer.close()

    def __enter__(self) -> FrameWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _panel_frame(panel: Panel, qpos, ghosts, current: int, alphas, depth, planted, site_ids, i: int):
    """One panel of video frame i: (image (h, w, 3) uint8, magenta mark or None, green dots or None).

    The mark is (pixel positions (k, 2) of the sites deeper than `PENETRATION_SHOWN`, the deepest
    depth [m]); their bodies are drawn magenta. The dots are the pixel positions (k, 2) of the sites
    the contact schedule has planted (`planted`: (n, s) bool per frame, or None)."""
    model = panel.model
    deep = deep_sites(depth, i, site_ids)
    marked_bodies = {int(model.site_bodyid[s]) for s, _ in deep}
    image = panel.render(qpos, ghosts, current, marked_bodies, alphas if len(ghosts) else None)
    mark = None
    if deep:
        mark = (panel.project(np.array([panel.data.site_xpos[s] for s, _ in deep])), max(d for _, d in deep))
    on = [] if planted is None else [int(s) for s, o in zip(site_ids, planted[i], strict=True) if o]
    dots = panel.project(np.array([panel.data.site_xpos[s] for s in on])) if on else None
    return image, mark, dots
