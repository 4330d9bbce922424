"""The video of `animate` and `mocap`: the plain spline and the optimized path side by side, keyframes
marked (`render_video`), and the check of the video's name and size made before a long optimization."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from solver.errors import InputError
from solver.layout import CONTACT_SITES
from solver.metrics import sample_times


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


@dataclass(frozen=True)
class VideoOptions:
    """The video's settings: fps [frames per second of output], size (width, height) [pixels], speed
    [x real time], panels (names from PANELS, left to right)."""

    fps: float = 30.0
    size: tuple = (960, 540)
    speed: float = 0.5
    panels: tuple = ("plain", "optimized")


def render_video(out, model, solution, keyframes, args: VideoOptions, reference=None, contacts=(), progress=None):
    """Side-by-side video of the plain spline and the optimized path (and the motion capture, with
    `args.panels` holding "reference"), keyframes marked.

    Args:
        out: video file. model: MjModel. solution: solver Solution. keyframes: Keyframes. args: fps,
            size, speed and optionally panels (names from PANELS, left to right). reference: the
            retargeted motion capture (times, qpos) for a "reference" panel. contacts: the contact schedule
            (`solver.contacts.Contact`s): planted sites are dotted green. progress(i, n): called after
            each of the n frames (None: silent).
    Returns:
        the render's info (n_frames, wall_time_s).
    """
    from runner.render import Track, render_tracks, sample_track
    from solver.terms.penetration import Penetration

    t = sample_times(keyframes.times[0], keyframes.times[-1], 240.0)
    pen = Penetration(model, margin=0.0)
    tracks = []
    planted = None
    if contacts:
        from solver.contacts import contact_mask

        planted = contact_mask(contacts, CONTACT_SITES, t)
    for name in getattr(args, "panels", ("plain", "optimized")):
        if name == "reference":  # over the keyframes' time span, like the other panels
            if reference is None:
                raise InputError("--panels reference: there is no motion-capture clip for this path; drop the "
                                 "reference panel")
            Y = sample_track(Track("reference", reference.times, reference.qpos), t)
        else:
            Y = (solution.initial if name == "plain" else solution.frames).path(t)
        tracks.append(Track(PANELS[name], t, Y, penetration=pen.depths(Y), sites=CONTACT_SITES, planted=planted))
    # keyframes with free components filled: the poses the animator set
    kq = solution.initial.values[solution.initial.is_keyframe]
    return render_tracks(model, tracks, out, fps=args.fps, size=args.size, speed=args.speed,
                         keyframe_times=keyframes.times, keyframe_qpos=kq,
                         title="dynsplines: " + " vs ".join(tr.label for tr in tracks), progress=progress)
