"""The video of `animate` and `mocap`: the plain spline and the optimized path side by side, keyframes
marked (`render_video` with its `VideoOptions`), the camera's side (`parse_camera`), and the check of the
video's name and size made before a long optimization."""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from solver.errors import InputError
from solver.metrics import sample_times

#: the named sides of `--camera`: where the camera stands around the figure, in degrees from straight
#: ahead (the direction of travel), counter-clockwise seen from above
CAMERA_SIDES = {"front": 0.0, "left": 90.0, "side": 90.0, "back": 180.0, "right": -90.0}
CAMERA_HELP = ("where the video's camera stands around the figure: side (= left: on the left of the "
               "direction of travel, the figure moves right to left), right, front (ahead of the figure, "
               "looking back at it), back, or an angle in degrees from straight ahead, "
               "counter-clockwise seen from above (0 front, 90 left, 180 back, -90 right, 45 front-left). "
               "The camera turns with the direction of travel (the way the figure faces if it hardly moves, "
               "e.g. a sidestep in place) and follows the pelvis' smoothed path [side]")


def parse_camera(text) -> float:
    """The camera's place around the figure from `--camera`: a name of `CAMERA_SIDES` or degrees.

    Args:
        text: "side", "left", "right", "front", "back", or a number of degrees (e.g. "45", "-90").
    Returns:
        [deg] in (-180, 180]: from straight ahead (the direction of travel), counter-clockwise seen from above.
    Raises:
        InputError: anything else, naming the choices.
    """
    key = str(text).strip().lower()
    if key in CAMERA_SIDES:
        return CAMERA_SIDES[key]
    try:
        deg = float(key.removesuffix("deg"))
    except ValueError:
        deg = math.nan
    if not math.isfinite(deg):
        raise InputError(f"--camera {text!r}: expected one of {', '.join(CAMERA_SIDES)} or an angle in degrees "
                         "(e.g. --camera 45 for front-left)")
    deg = math.remainder(deg, 360.0)
    return 180.0 if deg == -180.0 else deg + 0.0  # + 0.0: no -0.0


@dataclass(frozen=True)
class VideoOptions:
    """How the side-by-side video is made (`render_video`).

    Attributes:
        fps: [1/s] video frames per second, > 0.
        size: (width, height) [px] of the whole video, both even (H.264).
        speed: playback speed (motion seconds per video second), > 0.
        panels: names from `PANELS`, left to right.
        camera: [deg] where the camera stands around the figure, from straight ahead (the direction of
            travel) counter-clockwise seen from above (`parse_camera`; 90: the figure's left side).
        quiet: no progress bar while rendering (used by the callers' progress display).
    """

    fps: float = 30.0
    size: tuple[int, int] = (960, 540)
    speed: float = 0.5
    panels: tuple[str, ...] = ("plain", "optimized")
    camera: float = CAMERA_SIDES["side"]
    quiet: bool = False

    def render_camera(self):
        """The renderer's `Camera` for `camera`: MuJoCo's free-camera azimuth is the direction the
        camera looks in, so a camera standing at angle a around the figure looks along a + 180."""
        from runner.render import Camera

        return Camera(azimuth=math.remainder(self.camera + 180.0, 360.0))

    @classmethod
    def from_args(cls, args) -> VideoOptions:
        """From the parsed output options of `runner.animate_options.add_options` (fps, size, speed,
        panels, camera, quiet; the missing ones at their defaults)."""
        d = cls()
        camera = getattr(args, "camera", d.camera)
        return cls(fps=args.fps, size=tuple(args.size), speed=args.speed,
                   panels=tuple(getattr(args, "panels", d.panels)),
                   camera=parse_camera(camera) if isinstance(camera, str) else float(camera),
                   quiet=bool(getattr(args, "quiet", False)))


def check_video_out(out, size) -> None:
    """The video's name and size are checked before the optimization (render_tracks checks again)."""
    from runner.render import VIDEO_SUFFIXES, parse_size

    if Path(out).suffix.lower() not in VIDEO_SUFFIXES:
        raise InputError(f"--out {out}: a video file must end in one of {', '.join(VIDEO_SUFFIXES)}; "
                         "use e.g. --out clip.mp4, or --no-render")
    w, h = parse_size(size)
    if w % 2 or h % 2:
        raise InputError(f"--size {w}x{h}: width and height must be even (H.264 video); e.g. --size "
                         f"{w + w % 2}x{h + h % 2}")


#: the video's panels: a name for `--panels` and the panel's label
PANELS = {"plain": "plain spline", "optimized": "optimized", "reference": "motion capture"}


def render_video(out, model, solution, keyframes, video: VideoOptions, reference=None, contacts=(),
                 progress=None):
    """Side-by-side video of the plain spline and the optimized path (and the motion capture, with
    `video.panels` holding "reference"), keyframes marked, the camera where `video.camera` says.

    Args:
        out: video file. model: MjModel. solution: solver Solution. keyframes: Keyframes. video:
            fps, size, speed, panels (names from PANELS, left to right) and camera. reference: the
            retargeted motion capture (times, qpos) for a "reference" panel. contacts: the contact schedule
            (`solver.contacts.Contact`s): planted sites are dotted green. progress(i, n): called after
            each of the n frames (None: silent).
    Returns:
        the render's info (`runner.render.RenderInfo`: n_frames, wall_time_s, ...).
    Raises:
        InputError: a "reference" panel without `reference`; what `render_tracks` raises.
    """
    from runner.render import Track, render_tracks, sample_track
    from solver.figure import Figure
    from solver.terms.penetration import Penetration

    t = sample_times(keyframes.times[0], keyframes.times[-1], 240.0)
    sites = Figure.from_model(model).contact_sites
    pen = Penetration(model, margin=0.0, sites=sites)
    tracks = []
    planted = None
    if contacts:
        from solver.contacts import contact_mask

        planted = contact_mask(contacts, sites, t)
    for name in video.panels:
        if name == "reference":  # over the keyframes' time span, like the other panels
            if reference is None:
                raise InputError("--panels reference: there is no motion-capture clip for this path; drop the "
                                 "reference panel")
            Y = sample_track(Track("reference", reference.times, reference.qpos), t)
        else:
            Y = (solution.initial if name == "plain" else solution.frames).path(t)
        tracks.append(Track(PANELS[name], t, Y, penetration=pen.depths(Y), sites=sites, planted=planted))
    # keyframes with free components filled: the poses the animator set
    kq = solution.initial.values[solution.initial.is_keyframe]
    return render_tracks(model, tracks, out, fps=video.fps, size=video.size, speed=video.speed,
                         keyframe_times=keyframes.times, keyframe_qpos=kq,
                         title="dynsplines: " + " vs ".join(tr.label for tr in tracks),
                         camera=video.render_camera(), progress=progress)
