"""`render_tracks` (the side-by-side video) and `render_still` (one image)."""
from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path

import imageio.v2 as iio
import numpy as np
from PIL import Image, ImageDraw

from runner.files import atomic_output, check_writable_dir
from runner.render.encode import children_cpu
from runner.render.frames import FramePlan, FrameWriter
from runner.render.gl import check_quality, load_font, make_renderer, shadow_map_size
from runner.render.overlays import (
    WHITE,
    Panel,
    check_keyframes,
    check_model_fit,
    draw_text,
    labels_shown,
    positive,
    title_band,
)
from runner.render.parallel import render_threaded, worker_count
from runner.render.tracks import (
    IMAGE_SUFFIXES,
    VIDEO_SUFFIXES,
    Camera,
    RenderInfo,
    Track,
    forward_direction,
    parse_size,
    root_body,
)
from solver.errors import InputError


def _layout(size, n_tracks: int, title: str | None, out_path: Path, quality: str, workers):
    """`render_tracks`' checked (width, height, panel width, panel height) [px]; raises its InputErrors."""
    width, height = parse_size(size)
    if not n_tracks:
        raise InputError("render_tracks needs at least one track")
    check_quality(quality)
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise InputError(f"workers must be a whole number >= 1 (or None: one per core); got {workers!r}")
    if out_path.suffix.lower() not in VIDEO_SUFFIXES:
        raise InputError(f"video file must end in one of {list(VIDEO_SUFFIXES)}; got {str(out_path)!r}")
    if width % 2 or height % 2:
        raise InputError(f"video size must be even in both directions (H.264 4:2:0); got {width}x{height}")
    panel_w = width // n_tracks
    panel_h = height - title_band(height, title if labels_shown(width, height) else None)
    if panel_w < 16 or panel_h < 16:
        raise InputError(
            f"size {width}x{height} leaves panels of {panel_w}x{panel_h} px for {n_tracks} tracks; "
            "each panel needs at least 16x16")
    return width, height, panel_w, panel_h


def _draw(plan: FramePlan, path, threads: int, progress) -> tuple[float, int]:
    """Draw and encode every frame of `plan` into `path` on `threads` threads; (render time [s], panels)."""
    if threads > 1:
        stats = render_threaded(plan, path, threads, progress)
        return stats.render_s, stats.panels
    n = plan.n_frames
    with FrameWriter(plan) as writer:
        done = iter(range(1, n + 1))
        writer.write(range(n), path, None if progress is None else lambda: progress(next(done), n))
    return writer.render_s, writer.panels


def render_tracks(
    model,
    tracks: Sequence[Track],
    out_path,
    *,
    fps: float = 30,
    size=(960, 540),
    speed: float = 0.5,
    keyframe_times=None,
    keyframe_qpos=None,
    title: str | None = None,
    camera: Camera = Camera(),  # noqa: B008 (a frozen dataclass: an immutable default)
    quality: str = "fast",
    progress: Callable[[int, int], None] | None = None,
    workers: int | None = None,
) -> RenderInfo:
    """Write a video of the tracks side by side, keyframes marked (paper figures 11, 12).

    Every track is a panel of width size[0] // len(tracks) (a remainder of the width is split as dark
    margins) and height size[1] less the title band (the title sits above all panels, `title_band`),
    shown over the union of the tracks' time ranges at `speed` times real time. Each panel has its
    label, the time counter and a timeline with a tick per keyframe; a translucent ghost of a keyframe
    pose is drawn in every panel while playback is within `GHOST_WINDOW` of the keyframe, fading in and
    out (`ghost_alphas`), and the ghost turns yellow with a "keyframe k" caption (k from 0: the index in
    the keyframe file, as in its error messages) during the `KEYFRAME_CAPTION_SECONDS` of video before
    playback reaches keyframe k, gone once it has passed (`current_keyframes`); a legend above the first
    panel's timeline says so ("ghosts: keyframe poses, yellow: the next"). Below `LABELS_MIN_SIZE`
    no text is drawn. All panels use one camera, following the root body's smoothed path from a side
    of its direction of travel (see `Camera`). Planes cast no shadows (`Panel.render`).

    Args:
        model: MjModel of the scene with the figure (loaded once by the caller; not changed).
        tracks: the paths, one panel each, left to right.
        out_path: the video file (.mp4, .mkv or .mov; H.264). Written atomically: on any error an
            earlier file there is left intact.
        fps: [1/s] video frame rate, > 0. speed: playback speed, > 0 (0.5: a 1.7 s motion lasts 3.4 s).
        size: (width, height) [px] or "WxH" of the whole video, both even (H.264 with 4:2:0 colour).
        keyframe_times: (m,) [s] keyframe times, or None for no keyframe marks.
        keyframe_qpos: (m, nq) keyframe poses for the ghosts, the same in every panel; None: each
            panel's ghosts are its own track at `keyframe_times` (for full keyframes the same poses;
            for partial keyframes it shows how each track completes them).
        title: optional caption at the top centre of the video. camera: distance, angles and smoothing.
        quality: "fast" or "high", see `QUALITIES`.
        progress: optional callback, called after each frame as progress(frames_done, n_frames).
        workers: threads that draw the frames (`runner.render.parallel`: each with its own OpenGL
            context, frames handed to one encoder in order); None: one per core up to `MAX_WORKERS`,
            one for videos under `MIN_PARALLEL_FRAMES` frames (`worker_count`). The video is the
            same whatever the number.

    Returns:
        RenderInfo (path, frames, video and wall time, ms per panel, size, CPU time, threads).

    Raises:
        InputError: bad size, fps or speed; an output suffix other than .mp4/.mkv/.mov; an output
            folder that cannot be written; tracks whose nq does not match the model; keyframe arrays
            of the wrong shape; workers < 1; no working OpenGL backend (set MUJOCO_GL=egl or osmesa).
        OSError: the video cannot be written (ffmpeg failed, a full disk).
    """
    wall0, cpu0 = time.perf_counter(), time.process_time()
    out_path = Path(out_path)
    tracks = list(tracks)
    fps, speed = positive(fps, "fps"), positive(speed, "speed")
    width, height, panel_w, panel_h = _layout(size, len(tracks), title, out_path, quality, workers)
    site_ids = [check_model_fit(model, tr) for tr in tracks]
    kf_t, kf_q = check_keyframes(model, keyframe_times, keyframe_qpos)
    check_writable_dir(out_path)

    plan = FramePlan.build(model, tracks, site_ids, kf_t, kf_q, fps=fps, speed=speed, camera=camera,
                           quality=quality, shadow_size=shadow_map_size(model, panel_h, camera.distance),
                           size=(width, height), panel_size=(panel_w, panel_h), title=title)
    n = plan.n_frames
    threads = worker_count(n, workers)
    children0 = children_cpu()
    with atomic_output(out_path) as tmp:
        render_s, panels = _draw(plan, tmp, threads, progress)
    return RenderInfo(
        path=out_path, n_frames=n, video_time_s=n / fps,
        wall_time_s=time.perf_counter() - wall0,
        ms_per_panel=1000.0 * render_s / max(panels, 1), size=(width, height),
        cpu_time_s=time.process_time() - cpu0 + children_cpu() - children0, threads=threads)


def render_still(
    model,
    qpos,
    out_path,
    *,
    size=(960, 540),
    camera: Camera = Camera(),  # noqa: B008 (a frozen dataclass: an immutable default)
    lookat=None,
    label: str | None = None,
    quality: str = "high",
) -> Path:
    """Write one image of the model at one pose (for docs, and to look at the figure).

    Args:
        model: MjModel (not changed: the rendering context gets a large enough buffer).
        qpos: (nq,) the pose.
        out_path: .png, .jpg or .jpeg; written atomically.
        size: (width, height) [px] or "WxH".
        camera: camera distance and angles (`smoothing` is unused).
        lookat: (3,) [m] point looked at; None: the root body's position (height from
            `camera.height` if set).
        label: optional caption at the top left.
        quality: "high" (default: one image, take the model's own settings) or "fast".

    Returns:
        The path written.

    Raises:
        InputError: bad size, qpos shape, suffix; unwritable folder; no OpenGL backend.
    """
    out_path = Path(out_path)
    width, height = parse_size(size)
    qpos = np.asarray(qpos, dtype=float)
    if qpos.shape != (model.nq,):
        raise InputError(f"qpos must have shape (nq,) = ({model.nq},); got shape {qpos.shape}")
    check_quality(quality)
    if out_path.suffix.lower() not in IMAGE_SUFFIXES:
        raise InputError(f"image file must end in one of {list(IMAGE_SUFFIXES)}; got {str(out_path)!r}")
    check_writable_dir(out_path)
    renderer = make_renderer(model, width, height, quality)
    try:
        panel = Panel(model, renderer, quality)
        if lookat is None:
            forward_direction(model, panel.data, qpos)
            lookat = panel.data.xpos[root_body(model)].copy()
            if camera.height is not None:
                lookat[2] = camera.height
        panel.set_camera(camera, np.asarray(lookat, dtype=float))
        image = panel.render(qpos)
    finally:
        renderer.close()
    if label:
        im = Image.fromarray(image)
        draw_text(ImageDraw.Draw(im), (10, 8), label, load_font(max(11, height // 28)), WHITE)
        image = np.asarray(im)
    with atomic_output(out_path) as tmp:
        iio.imwrite(tmp, image)
    return out_path
