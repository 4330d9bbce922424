"""Offscreen video of paths side by side, with the keyframes marked (the paper's figures 11 and 12).

`render_tracks` draws each `Track` (a label and dense `qpos` samples in time) as one panel of the
video, all panels over the same time range, seen by the same camera, so that the plain spline through
the keyframes and the optimized path can be compared frame by frame. The keyframes are marked three
ways: a translucent "ghost" figure at a keyframe pose in every panel, fading in and out while playback
is within 0.3 s of that keyframe, a timeline under each panel with a tick per keyframe, and a
"keyframe k" caption (and a yellow ghost) as playback reaches a keyframe time, gone once it has passed.
The title sits in a band above the panels; the camera follows the root's smoothed path from one side
of its direction of travel (`Camera`; the commands' `--camera` chooses the side, `side_by_side.VideoOptions`);
videos smaller than 320x180 get no text. Keyframes are numbered as in the keyframe file, from 0. Contact sites that are inside a surface (a `Track`'s optional
`penetration`) are circled in magenta, on top of everything, so a foot hidden inside the step shows.

Sampling: tracks come as dense samples (`times`, `qpos`) at any rate; the video frame at motion time t
shows each track *linearly interpolated* between its two samples around t (held at its first/last
sample outside its time range). Quaternions are interpolated component-wise and not normalized here:
MuJoCo normalizes them when it computes the kinematics, as it does for the spline's own values (see
docs/design.md, "State = MuJoCo qpos"). With samples much denser than the video this is exact to the eye.

The model is passed in (loaded once). What every frame shows is computed once (`frames.FramePlan`);
a `frames.FrameWriter` draws frames from it with one `mujoco.Renderer` of the panel size (its own
OpenGL context, made from a copy of the model whose offscreen buffer is raised to the panel size),
reused for every panel of every frame. A frame's picture depends on that frame only (the camera is set
before the scene is updated, so MuJoCo's infinite floor is placed under this frame's camera, not the
previous one's). That lets several threads draw (`parallel.render_threaded`, one per core up to 4):
Mesa's llvmpipe does much of a frame's work on the thread issuing the draw calls and MuJoCo releases
the GIL while it renders, so each thread draws the next frame not yet taken with its own context,
and this thread hands them to one encoder in frame order: the same frames as one thread draws. Each
frame's overlays are drawn and encoded in a background thread (`encode.FrameEncoder`, ffmpeg in its
own process). A quality preset (`QUALITIES`) trades MuJoCo's defaults for speed on a software
renderer. In "fast" an infinite floor under directional light is drawn as one quad
(`gl.coarse_floor`: MuJoCo's own 200 x 200 grid was a third of the render time, for the same
picture). Planes cast no shadows (nothing lies under a floor): the floor's own shadow-map self-test
drew rows of black specks ("shadow acne") on it in every frame. Rendering
needs an OpenGL backend; without a display that is EGL (Mesa's llvmpipe), which `runner.environment`
selects through MUJOCO_GL before mujoco is first imported (and `_headless_fallback` if mujoco came first).
"""
import importlib

#: where each public name lives: imported on first use (PEP 562), so that a command that writes no video
#: (`mocap --no-render`, `export`) does not pay for OpenGL, Pillow and imageio
_HOME = {"QUALITIES": "gl", "Quality": "gl", "IMAGE_SUFFIXES": "tracks", "VIDEO_SUFFIXES": "tracks", "Camera": "tracks",
         "RenderInfo": "tracks", "Track": "tracks", "frame_times": "tracks", "parse_size": "tracks",
         "sample_track": "tracks", "render_still": "video", "render_tracks": "video"}


def __getattr__(name: str):
    """A public name (`_HOME`) or a submodule (`runner.render.gl`, ...), imported on first use."""
    if name in _HOME:
        value = getattr(importlib.import_module(f"{__name__}.{_HOME[name]}"), name)
        globals()[name] = value
        return value
    try:
        return importlib.import_module(f"{__name__}.{name}")
    except ModuleNotFoundError as e:
        if e.name != f"{__name__}.{name}":
            raise
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None


__all__ = [
    "IMAGE_SUFFIXES",
    "VIDEO_SUFFIXES",
    "Camera",
    "QUALITIES",
    "Quality",
    "RenderInfo",
    "Track",
    "frame_times",
    "parse_size",
    "render_still",
    "render_tracks",
    "sample_track",
]
