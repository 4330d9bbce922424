"""Offscreen video of paths side by side, with the keyframes marked (the paper's figures 11 and 12).

`render_tracks` draws each `Track` (a label and dense `qpos` samples in time) as one panel of the
video, all panels over the same time range, seen by the same camera, so that the plain spline through
the keyframes and the optimized path can be compared frame by frame. The keyframes are marked three
ways: translucent "ghost" figures at the keyframe poses in every panel, a timeline under each panel
with a tick per keyframe, and a "keyframe k" caption (and a yellow ghost) for a few frames when
playback passes a keyframe time. Contact sites that are inside a surface (a `Track`'s optional
`penetration`) are circled in magenta, on top of everything, so a foot hidden inside the step shows.

Sampling: tracks come as dense samples (`times`, `qpos`) at any rate; the video frame at motion time t
shows each track *linearly interpolated* between its two samples around t (held at its first/last
sample outside its time range). Quaternions are interpolated component-wise and not normalized here:
MuJoCo normalizes them when it computes the kinematics, as it does for the spline's own values (see
DESIGN.md, "State = MuJoCo qpos"). With samples much denser than the video this is exact to the eye.

The model is passed in (loaded once). One `mujoco.Renderer` is made per call, for the one panel size,
and reused for every panel of every frame; its offscreen buffer is made large enough for the panel
(`<visual><global offwidth offheight>` raised while the context is created, then restored), and a
quality preset (`QUALITIES`) trades MuJoCo's defaults for speed on a software renderer. Rendering
needs an OpenGL backend; without a display that is EGL (Mesa's llvmpipe), which `solver` selects
through MUJOCO_GL before mujoco is first imported (and `_headless_fallback` if mujoco came first).
"""
from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from solver.errors import InputError  # first: importing solver sets MUJOCO_GL before mujoco loads

import imageio.v2 as iio  # noqa: E402
import mujoco  # noqa: E402  (after solver, see above)
from PIL import Image, ImageDraw, ImageFont  # noqa: E402

from runner.files import atomic_output, check_writable_dir  # noqa: E402

__all__ = [
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

VIDEO_SUFFIXES = (".mp4", ".mkv", ".mov")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
PENETRATION_SHOWN = 1e-3
"""[m] a contact site deeper than this inside a surface is circled in magenta."""
KEYFRAME_CAPTION_SECONDS = 0.25
"""[s] of video for which "keyframe k" stays on screen after playback passes keyframe k."""

# Colours stay clear of the figure's own (left side blue, right side red, skin, grey trunk).
_GHOST_RGBA = np.array([0.9, 0.93, 1.0, 0.2], np.float32)
_GHOST_CURRENT_RGBA = np.array([1.0, 0.8, 0.1, 0.3], np.float32)
_PENETRATION_RGBA = np.array([1.0, 0.1, 0.9, 1.0], np.float32)
_GHOST_INFLATE = 0.006
"""[m] ghosts of primitive geoms are this much fatter than the figure, so a ghost that coincides
with the figure (playback at its keyframe) is a translucent shell around it instead of z-fighting."""
_PRIMITIVES = frozenset(int(t) for t in (
    mujoco.mjtGeom.mjGEOM_SPHERE, mujoco.mjtGeom.mjGEOM_CAPSULE, mujoco.mjtGeom.mjGEOM_ELLIPSOID,
    mujoco.mjtGeom.mjGEOM_CYLINDER, mujoco.mjtGeom.mjGEOM_BOX))
_GHOST_REACH = 1.1
"""[m] how far a figure reaches from its root body, for culling ghosts outside the view."""
_ROUND_ENDED = frozenset(int(t) for t in (mujoco.mjtGeom.mjGEOM_CAPSULE, mujoco.mjtGeom.mjGEOM_CYLINDER))
_GHOST_TEXT = (225, 235, 255)
_CURRENT_TEXT = (255, 217, 64)
_PENETRATION_TEXT = (255, 40, 230)
_WHITE = (255, 255, 255)
_PAD_COLOR = (24, 24, 28)


@dataclass(frozen=True, eq=False)
class Track:
    """One path to show as a panel: dense `qpos` samples in time, and a label.

    Attributes:
        label: panel caption, e.g. "plain spline" or "optimized".
        times: (n,) [s] strictly increasing sample times.
        qpos: (n, nq) MuJoCo `qpos` at those times (quaternions need not be unit).
        penetration: optional (n, s) [m] depth of each of `sites` inside a surface (>0 inside,
            <=0 outside), e.g. from the ground-penetration term (eq. 12). Where deeper than
            `PENETRATION_SHOWN` the site is circled in magenta and its body drawn magenta.
        sites: s site names, the columns of `penetration` (e.g. "l_heel", "l_toe", ...).

    Raises:
        InputError: shapes or values that do not fit (checked on construction; nq against the model
            in `render_tracks`).
    """

    label: str
    times: np.ndarray
    qpos: np.ndarray
    penetration: np.ndarray | None = None
    sites: tuple[str, ...] = ()

    def __post_init__(self):
        times = np.asarray(self.times, dtype=float)
        qpos = np.asarray(self.qpos, dtype=float)
        name = f"track {self.label!r}"
        if times.ndim != 1 or times.size == 0:
            raise InputError(f"{name}: times must have shape (n,) with n >= 1; got shape {times.shape}")
        if qpos.ndim != 2 or qpos.shape[0] != times.size:
            raise InputError(
                f"{name}: qpos must have shape (n, nq) = ({times.size}, nq) to match times; "
                f"got shape {qpos.shape}")
        if not (np.all(np.isfinite(times)) and np.all(np.isfinite(qpos))):
            raise InputError(f"{name}: times and qpos must be finite (no NaN or inf)")
        if times.size > 1 and np.any(np.diff(times) <= 0):
            i = int(np.flatnonzero(np.diff(times) <= 0)[0])
            raise InputError(
                f"{name}: times must be strictly increasing; times[{i}] = {times[i]:g} s, "
                f"times[{i + 1}] = {times[i + 1]:g} s")
        sites = tuple(self.sites)
        penetration = self.penetration
        if penetration is not None:
            penetration = np.asarray(penetration, dtype=float)
            if penetration.ndim == 1:
                penetration = penetration[:, None]
            if penetration.shape != (times.size, len(sites)):
                raise InputError(
                    f"{name}: penetration must have shape (n, len(sites)) = ({times.size}, {len(sites)}); "
                    f"got shape {penetration.shape}")
        elif sites:
            raise InputError(f"{name}: sites are given but penetration is not")
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "qpos", qpos)
        object.__setattr__(self, "penetration", penetration)
        object.__setattr__(self, "sites", sites)


@dataclass(frozen=True)
class Camera:
    """A free camera that follows the figure's root body (the pelvis), the same for every panel.

    Attributes:
        distance: [m] from the look-at point.
        azimuth: [deg] MuJoCo free-camera azimuth. -90 puts the camera on +y, the left of a figure
            facing +x, looking along -y: the step is seen in profile and the figure moves from right
            to left on screen (+90: from its right, moving left to right).
        elevation: [deg], negative looks down.
        smoothing: [s] of motion time: the standard deviation of the Gaussian that smooths the
            root's path into the look-at path (removes the running bob). 0: no smoothing.
        height: [m] fixed look-at height; None follows the root's height (smoothed).
    """

    distance: float = 4.0
    azimuth: float = -90.0
    elevation: float = -12.0
    smoothing: float = 0.3
    height: float | None = None


@dataclass(frozen=True)
class RenderInfo:
    """What `render_tracks` wrote.

    Attributes:
        path: the video file.
        n_frames: number of video frames.
        video_time_s: [s] length of the video (n_frames / fps).
        wall_time_s: [s] time the call took.
        ms_per_panel: [ms] mean time to pose, render and read back one panel (excludes encoding).
        size: (width, height) [px] of the video.
    """

    path: Path
    n_frames: int
    video_time_s: float
    wall_time_s: float
    ms_per_panel: float
    size: tuple[int, int]


def parse_size(size) -> tuple[int, int]:
    """Read an image size: a "WxH" string (e.g. "960x540") or a (width, height) pair.

    Returns:
        (width, height) [px], positive integers.

    Raises:
        InputError: anything else, naming what was received.
    """
    if isinstance(size, str):
        parts = size.lower().replace("×", "x").split("x")
        try:
            if len(parts) != 2:
                raise ValueError
            w, h = (int(p.strip()) for p in parts)
        except ValueError:
            raise InputError(f"size must be WIDTHxHEIGHT in pixels, e.g. 960x540; got {size!r}") from None
    else:
        try:
            w, h = size
        except (TypeError, ValueError):
            raise InputError(
                f"size must be (width, height) in pixels, e.g. (960, 540); got {size!r}") from None
        if not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in (w, h)):
            raise InputError(f"size must be two integers (width, height) in pixels; got {size!r}")
        w, h = int(w), int(h)
    if w <= 0 or h <= 0:
        raise InputError(f"size must be positive, e.g. 960x540; got {w}x{h}")
    return w, h


def frame_times(t0: float, t1: float, fps: float, speed: float) -> np.ndarray:
    """Motion times of the video frames: from t0 to t1 in steps of speed / fps, the last one at t1.

    Args:
        t0, t1: [s] first and last motion time, t1 >= t0.
        fps: [1/s] video frame rate, > 0.
        speed: playback speed (motion seconds per video second), > 0; 0.5 is half speed.

    Returns:
        (n_frames,) [s]; n_frames = ceil((t1 - t0) * fps / speed) + 1.
    """
    dt = speed / fps
    n = int(math.ceil((t1 - t0) / dt - 1e-9)) + 1
    return np.minimum(t0 + dt * np.arange(n), t1)


def sample_track(track: Track, times: np.ndarray) -> np.ndarray:
    """The track's `qpos` at `times`, linearly interpolated between samples, held outside its range.

    Args:
        track: the path.
        times: (k,) [s].

    Returns:
        (k, nq) qpos (quaternions not renormalized; MuJoCo normalizes them in the kinematics).
    """
    return _interp(track.times, track.qpos, np.asarray(times, dtype=float))


def _interp(t: np.ndarray, y: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Piecewise-linear interpolation of rows y (n, d) given at t (n,) at times (k,), clamped ends."""
    if t.size == 1:
        return np.repeat(y, times.size, axis=0)
    tc = np.clip(times, t[0], t[-1])
    i = np.clip(np.searchsorted(t, tc, side="right") - 1, 0, t.size - 2)
    w = ((tc - t[i]) / (t[i + 1] - t[i]))[:, None]
    return (1.0 - w) * y[i] + w * y[i + 1]


def _smooth(x: np.ndarray, dt: float, sigma: float) -> np.ndarray:
    """Gaussian smoothing of a path x (n, 3) sampled every dt [s], sigma [s].

    The ends are padded by linear extrapolation (velocity averaged over about sigma), so a figure
    moving at constant speed stays centred at the start and end instead of the camera lagging.
    """
    n = x.shape[0]
    if sigma <= 0 or n < 3:
        return x.copy()
    r = int(math.ceil(3.0 * sigma / dt))
    m = max(1, min(n - 1, int(round(sigma / dt))))
    v0 = (x[m] - x[0]) / m
    v1 = (x[-1] - x[-1 - m]) / m
    steps = np.arange(1, r + 1)[:, None]
    padded = np.concatenate([x[0] - v0 * steps[::-1], x, x[-1] + v1 * steps])
    k = np.exp(-0.5 * (np.arange(-r, r + 1) * dt / sigma) ** 2)
    k /= k.sum()
    return np.stack([np.convolve(padded[:, j], k, mode="valid") for j in range(x.shape[1])], axis=1)


def _root_body(model) -> int:
    """The body the camera follows: the one with the free joint (the pelvis), else the first body."""
    free = np.flatnonzero(model.jnt_type == mujoco.mjtJoint.mjJNT_FREE)
    if free.size:
        return int(model.jnt_bodyid[free[0]])
    return 1 if model.nbody > 1 else 0


def _forward(model, data, qpos) -> None:
    """Pose `data` at qpos: kinematics, centres of mass, cameras and lights (no collision, no dynamics)."""
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    mujoco.mj_camlight(model, data)


def _lookat_path(model, data, qposes: Sequence[np.ndarray], dt: float, camera: Camera) -> np.ndarray:
    """(n, 3) [m] look-at points: the root body's position averaged over the tracks, smoothed."""
    root = _root_body(model)
    pos = np.zeros((qposes[0].shape[0], 3))
    for q in qposes:
        for i in range(q.shape[0]):
            data.qpos[:] = q[i]
            mujoco.mj_kinematics(model, data)
            pos[i] += data.xpos[root]
    pos /= len(qposes)
    pos = _smooth(pos, dt, camera.smoothing)
    if camera.height is not None:
        pos[:, 2] = camera.height
    return pos


@dataclass(frozen=True)
class Quality:
    """A render quality preset.

    Attributes:
        caps: upper bounds for fields of the model's `<visual><quality>` (MSAA samples, shadow map
            size [px], tessellation of round geoms and planes), applied while the GL context is made.
        reflections: draw reflections in reflective materials (the floor): renders the scene twice.
    """

    caps: dict
    reflections: bool


QUALITIES = {
    "fast": Quality({"offsamples": 0, "shadowsize": 1024, "numslices": 12, "numstacks": 6, "numquads": 1},
                    reflections=False),
    "high": Quality({}, reflections=True),
}
"""Render presets. "fast" (the default) renders a 480x540 panel of the run-and-step scene with 8
keyframe ghosts in about 30 ms of CPU on Mesa's software renderer (llvmpipe), half of what MuJoCo's
defaults take: no multisampling, a 1024 px shadow map, coarser capsules and spheres (invisible at
these sizes), no reflections. "high" uses the model's own `<visual><quality>` settings (MuJoCo's
defaults: 4x MSAA, 4096 px shadows, reflections), several times slower."""


def _check_quality(quality: str) -> None:
    if quality not in QUALITIES:
        raise InputError(f"unknown render quality {quality!r}; choose one of {list(QUALITIES)}")


def _make_renderer(model, width: int, height: int, quality: str = "fast"):
    """A `mujoco.Renderer` of width x height with the `quality` preset's GL context settings.

    The model's offscreen buffer size (raised to the image size) and `<visual><quality>` fields
    (capped by the preset) are changed only while the rendering context is made, then restored: the
    caller's model is unchanged.

    Raises:
        InputError: unknown quality; the OpenGL backend cannot be initialized (no EGL/OSMesa, bad
            MUJOCO_GL).
    """
    _check_quality(quality)
    _headless_fallback()
    vis = model.vis
    saved_size = (vis.global_.offwidth, vis.global_.offheight)
    saved_quality = {name: getattr(vis.quality, name) for name in QUALITIES[quality].caps}
    vis.global_.offwidth = max(width, vis.global_.offwidth)
    vis.global_.offheight = max(height, vis.global_.offheight)
    for name, cap in QUALITIES[quality].caps.items():
        setattr(vis.quality, name, min(cap, getattr(vis.quality, name)))
    try:
        renderer_cls = getattr(mujoco, "Renderer", None)
        if renderer_cls is None:
            raise ImportError("mujoco.Renderer could not be imported")
        return renderer_cls(model, height, width)
    except Exception as e:  # the GL backends raise ImportError, RuntimeError, mujoco.FatalError, ...
        raise InputError(
            f"offscreen rendering failed ({_gl_backend()}; {type(e).__name__}: {e}). "
            "Offscreen rendering needs EGL (Mesa): set MUJOCO_GL=egl or osmesa; or use --no-render"
        ) from e
    finally:
        vis.global_.offwidth, vis.global_.offheight = saved_size
        for name, value in saved_quality.items():
            setattr(vis.quality, name, value)


_GLFW_CHOICES = ("", "glfw", "enable", "enabled", "on", "true", "1")


def _headless_fallback() -> None:
    """Use EGL/OSMesa after all if mujoco was imported before MUJOCO_GL was set and there is no display.

    mujoco picks its OpenGL backend once, when first imported. A program (or a test's conftest) that
    imports mujoco before `solver` gets GLFW, which needs a display. When there is none and
    MUJOCO_GL now names "egl" or "osmesa" (as `solver` sets it), point mujoco's offscreen context
    class at that backend, so rendering works whatever the import order. An explicit user choice of
    backend at import time is left alone; if the switch is not possible, nothing changes and
    `_make_renderer` reports the failure.
    """
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        return
    want = (os.environ.get("MUJOCO_GL") or "").lower().strip()
    if want not in ("egl", "osmesa"):
        return
    try:
        from mujoco.rendering.classic import gl_context
    except ImportError:
        return
    used = getattr(gl_context, "_MUJOCO_GL", None)
    if used is None or used == want or used not in _GLFW_CHOICES:
        return
    try:
        if want == "egl":
            from mujoco.egl import GLContext
        else:
            from mujoco.osmesa import GLContext
    except Exception:  # noqa: BLE001  (PyOpenGL already bound to another platform, no libEGL, ...)
        return
    gl_context.GLContext = GLContext
    gl_context._MUJOCO_GL = want


def _gl_backend() -> str:
    """Which OpenGL backend mujoco chose: it reads MUJOCO_GL once, when it is first imported."""
    try:
        from mujoco.rendering.classic import gl_context

        used = getattr(gl_context, "_MUJOCO_GL", None)
    except ImportError:
        used = None
    now = os.environ.get("MUJOCO_GL")
    if used is None:
        return f"MUJOCO_GL={now!r}"
    text = f"mujoco was imported with MUJOCO_GL={used!r}"
    if used in _GLFW_CHOICES:
        text += " (GLFW: needs a display)"
    now_l = (now or "").lower().strip()
    if now_l != used and not (now_l in _GLFW_CHOICES and used in _GLFW_CHOICES):
        text += f"; MUJOCO_GL={now!r} was set after that, too late (import solver or runner before mujoco)"
    return text


def _font(px: int):
    try:
        return ImageFont.load_default(size=px)
    except (TypeError, OSError, ImportError):  # old Pillow or no FreeType: small bitmap font
        return ImageFont.load_default()


def _project(glcam, points: np.ndarray, width: int, height: int) -> np.ndarray:
    """Pixel coordinates (k, 2) (x right, y down) of world points (k, 3) in a rendered panel.

    Uses the scene's OpenGL camera (frustum at the near plane, half-width from the aspect ratio, as
    `mjr_render` sets it). Points behind the camera get NaN.
    """
    pos = np.asarray(glcam.pos, float)
    fwd = np.asarray(glcam.forward, float)
    up = np.asarray(glcam.up, float)
    right = np.cross(fwd, up)
    rel = points - pos
    z = rel @ fwd
    near, top, bottom = glcam.frustum_near, glcam.frustum_top, glcam.frustum_bottom
    half = glcam.frustum_width or 0.5 * width / height * (top - bottom)
    with np.errstate(divide="ignore", invalid="ignore"):
        xn = (rel @ right) * near / z
        yn = (rel @ up) * near / z
    px = (xn - (glcam.frustum_center - half)) / (2 * half) * width
    py = (top - yn) / (top - bottom) * height
    out = np.stack([px, py], axis=1)
    out[z <= 0] = np.nan
    return out


class _Panel:
    """Renders one panel (a pose, keyframe ghosts, marked bodies) into an (h, w, 3) uint8 image.

    Owns its MjData, camera and scene options; one per Renderer, reused for every panel and frame.
    """

    def __init__(self, model, renderer, quality: str = "fast"):
        self.model = model
        self.renderer = renderer
        if not QUALITIES[quality].reflections:
            renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
        self.data = mujoco.MjData(model)
        self.root = _root_body(model)
        self.option = mujoco.MjvOption()
        self.ghost_option = mujoco.MjvOption()
        self.ghost_option.sitegroup[:] = 0
        self.perturb = mujoco.MjvPerturb()
        self.cam = mujoco.MjvCamera()
        self.cam.type = mujoco.mjtCamera.mjCAMERA_FREE

    def set_camera(self, camera: Camera, lookat: np.ndarray) -> None:
        self.cam.distance = camera.distance
        self.cam.azimuth = camera.azimuth
        self.cam.elevation = camera.elevation
        self.cam.lookat[:] = lookat

    def render(self, qpos, ghosts=(), current=-1, marked_bodies=()):
        """Image (h, w, 3) uint8 of the figure at qpos with ghost MjData (posed) drawn translucent."""
        model, scene = self.model, self.renderer.scene
        _forward(model, self.data, qpos)
        self.renderer.update_scene(self.data, self.cam, self.option)
        if len(marked_bodies):
            geom_type = int(mujoco.mjtObj.mjOBJ_GEOM)
            for i in range(scene.ngeom):
                g = scene.geoms[i]
                if g.objtype == geom_type and model.geom_bodyid[g.objid] in marked_bodies:
                    g.rgba[:] = _PENETRATION_RGBA
                    g.matid = -1
        visible = self._visible(ghosts)
        for k, gdata in enumerate(ghosts):
            if not visible[k]:
                continue
            n0 = scene.ngeom
            mujoco.mjv_addGeoms(model, gdata, self.ghost_option, self.perturb,
                                mujoco.mjtCatBit.mjCAT_DYNAMIC, scene)
            rgba = _GHOST_CURRENT_RGBA if k == current else _GHOST_RGBA
            for i in range(n0, scene.ngeom):
                g = scene.geoms[i]
                g.rgba[:] = rgba
                g.matid = -1
                g.transparent = 1
                g.castshadow = 0
                g.reflectance = 0
                if g.type in _PRIMITIVES:
                    if g.type in _ROUND_ENDED:
                        g.size[0] += _GHOST_INFLATE  # radius; size[1] is the half-length
                    else:
                        g.size[:] += _GHOST_INFLATE
        return self.renderer.render()

    def _visible(self, ghosts) -> np.ndarray:
        """(len(ghosts),) bool: False for ghosts surely outside the view (their root farther sideways
        from the look-at point than the half-width of the view there plus `_GHOST_REACH`). MuJoCo
        draws every geom it is given, so culling saves render time on long paths."""
        if not len(ghosts):
            return np.zeros(0, bool)
        az = math.radians(self.cam.azimuth)
        right = np.array([math.sin(az), -math.cos(az), 0.0])
        aspect = self.renderer.width / self.renderer.height
        half = self.cam.distance * math.tan(math.radians(self.model.vis.global_.fovy) / 2) * aspect
        roots = np.array([g.xpos[self.root] for g in ghosts])
        return np.abs((roots - np.asarray(self.cam.lookat)) @ right) <= half + _GHOST_REACH

    def project(self, points: np.ndarray) -> np.ndarray:
        scene = self.renderer.scene
        glcam = mujoco.mjv_averageCamera(scene.camera[0], scene.camera[1])
        return _project(glcam, points, self.renderer.width, self.renderer.height)


def _check_model_fit(model, track: Track) -> np.ndarray:
    """Check the track's nq against the model; return the site ids of its `sites`."""
    if track.qpos.shape[1] != model.nq:
        raise InputError(
            f"track {track.label!r}: qpos has {track.qpos.shape[1]} columns but the model has "
            f"nq = {model.nq}; the path was made for another model")
    ids = []
    for s in track.sites:
        i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s)
        if i < 0:
            names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_SITE, j) for j in range(model.nsite)]
            raise InputError(f"track {track.label!r}: site {s!r} is not in the model; sites: {names}")
        ids.append(i)
    return np.array(ids, dtype=int)


def _text(draw, xy, s, font, fill, anchor="la"):
    draw.text(xy, s, font=font, fill=fill, anchor=anchor, stroke_width=2, stroke_fill=(0, 0, 0))


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
    camera: Camera = Camera(),
    quality: str = "fast",
    progress: Callable[[int, int], None] | None = None,
) -> RenderInfo:
    """Write a video of the tracks side by side, keyframes marked (paper figures 11, 12).

    Every track is a panel of width size[0] // len(tracks) and height size[1] (a remainder of the
    width is split as dark margins), shown over the union of the tracks' time ranges at `speed` times
    real time. Each panel has its label, the time counter and a timeline with a tick per keyframe;
    translucent ghosts of the keyframe poses are drawn in every panel, and the ghost and a
    "keyframe k" caption (k from 1) light up for `KEYFRAME_CAPTION_SECONDS` of video when playback
    passes keyframe k. All panels use one camera, following the root body (see `Camera`).

    Args:
        model: MjModel of the scene with the figure (loaded once by the caller; not changed).
        tracks: the paths, one panel each, left to right.
        out_path: the video file (.mp4, .mkv or .mov; H.264). Written atomically: on any error an
            earlier file there is left intact.
        fps: [1/s] video frame rate, > 0.
        size: (width, height) [px] or "WxH" of the whole video, both even (H.264 with 4:2:0 colour).
        speed: playback speed, > 0 (0.5: half speed, so a 1.7 s motion lasts 3.4 s).
        keyframe_times: (m,) [s] keyframe times, or None for no keyframe marks.
        keyframe_qpos: (m, nq) keyframe poses for the ghosts, the same in every panel; None: each
            panel's ghosts are its own track at `keyframe_times` (for full keyframes the same poses;
            for partial keyframes it shows how each track completes them).
        title: optional caption at the top centre of the video.
        camera: camera distance, angles and smoothing.
        quality: "fast" or "high", see `QUALITIES`.
        progress: optional callback, called after each frame as progress(frames_done, n_frames).

    Returns:
        RenderInfo (path, n_frames, video_time_s, wall_time_s, ms_per_panel, size).

    Raises:
        InputError: bad size, fps or speed; an output suffix other than .mp4/.mkv/.mov; an output
            folder that cannot be written; tracks whose nq does not match the model; keyframe arrays
            of the wrong shape; no working OpenGL backend (set MUJOCO_GL=egl or osmesa).
    """
    wall0 = time.perf_counter()
    out_path = Path(out_path)
    width, height = parse_size(size)
    fps, speed = _positive(fps, "fps"), _positive(speed, "speed")
    tracks = list(tracks)
    if not tracks:
        raise InputError("render_tracks needs at least one track")
    _check_quality(quality)
    if out_path.suffix.lower() not in VIDEO_SUFFIXES:
        raise InputError(f"video file must end in one of {list(VIDEO_SUFFIXES)}; got {str(out_path)!r}")
    if width % 2 or height % 2:
        raise InputError(f"video size must be even in both directions (H.264 4:2:0); got {width}x{height}")
    panel_w = width // len(tracks)
    if panel_w < 16 or height < 16:
        raise InputError(
            f"size {width}x{height} leaves panels of {panel_w}x{height} px for {len(tracks)} tracks; "
            "each panel needs at least 16x16")
    site_ids = [_check_model_fit(model, tr) for tr in tracks]
    kf_t, kf_q = _check_keyframes(model, keyframe_times, keyframe_qpos)
    check_writable_dir(out_path)

    t0 = min(float(tr.times[0]) for tr in tracks)
    t1 = max(float(tr.times[-1]) for tr in tracks)
    times = frame_times(t0, t1, fps, speed)
    n = times.size
    qposes = [sample_track(tr, times) for tr in tracks]
    depths = [None if tr.penetration is None else _interp(tr.times, tr.penetration, times) for tr in tracks]

    renderer = _make_renderer(model, panel_w, height, quality)
    try:
        panel = _Panel(model, renderer, quality)
        lookat = _lookat_path(model, panel.data, qposes, speed / fps, camera)
        ghosts = _ghost_data(model, tracks, kf_t, kf_q)
        caption_frames = max(1, int(round(KEYFRAME_CAPTION_SECONDS * fps)))
        passed = np.searchsorted(times, kf_t - 1e-9, side="left") if kf_t is not None else np.zeros(0, int)
        overlay = _Overlay(width, height, panel_w, len(tracks), title, t0, t1, kf_t)

        render_seconds = 0.0
        with atomic_output(out_path) as tmp:
            writer = iio.get_writer(
                tmp, format="FFMPEG", mode="I", fps=fps, codec="libx264", quality=8,
                macro_block_size=1, ffmpeg_log_level="error", output_params=["-preset", "veryfast"])
            try:
                for i in range(n):
                    active = np.flatnonzero((passed <= i) & (i < passed + caption_frames))
                    current = int(active[-1]) if active.size else -1
                    images, marks = [], []
                    r0 = time.perf_counter()
                    for p, tr in enumerate(tracks):
                        panel.set_camera(camera, lookat[i])
                        deep = _deep_sites(depths[p], i, site_ids[p])
                        marked_bodies = set(int(model.site_bodyid[s]) for s, _ in deep)
                        images.append(panel.render(qposes[p][i], ghosts[p], current, marked_bodies))
                        if deep:
                            xy = panel.project(np.array([panel.data.site_xpos[s] for s, _ in deep]))
                            marks.append((xy, max(d for _, d in deep)))
                        else:
                            marks.append(None)
                    render_seconds += time.perf_counter() - r0
                    frame = overlay.compose(images, [tr.label for tr in tracks], times[i], speed,
                                            current, marks)
                    writer.append_data(frame)
                    if progress is not None:
                        progress(i + 1, n)
            finally:
                writer.close()
    finally:
        renderer.close()
    return RenderInfo(
        path=out_path, n_frames=n, video_time_s=n / fps,
        wall_time_s=time.perf_counter() - wall0,
        ms_per_panel=1000.0 * render_seconds / (n * len(tracks)), size=(width, height))


def render_still(
    model,
    qpos,
    out_path,
    *,
    size=(960, 540),
    camera: Camera = Camera(),
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
    _check_quality(quality)
    if out_path.suffix.lower() not in IMAGE_SUFFIXES:
        raise InputError(f"image file must end in one of {list(IMAGE_SUFFIXES)}; got {str(out_path)!r}")
    check_writable_dir(out_path)
    renderer = _make_renderer(model, width, height, quality)
    try:
        panel = _Panel(model, renderer, quality)
        if lookat is None:
            _forward(model, panel.data, qpos)
            lookat = panel.data.xpos[_root_body(model)].copy()
            if camera.height is not None:
                lookat[2] = camera.height
        panel.set_camera(camera, np.asarray(lookat, dtype=float))
        image = panel.render(qpos)
    finally:
        renderer.close()
    if label:
        im = Image.fromarray(image)
        _text(ImageDraw.Draw(im), (10, 8), label, _font(max(11, height // 28)), _WHITE)
        image = np.asarray(im)
    with atomic_output(out_path) as tmp:
        iio.imwrite(tmp, image)
    return out_path


def _positive(value, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a positive number; got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise InputError(f"{name} must be a positive number; got {value!r}")
    return v


def _check_keyframes(model, keyframe_times, keyframe_qpos):
    """Validate the keyframe arrays: times (m,) [s], qpos (m, nq) or None."""
    if keyframe_times is None:
        if keyframe_qpos is not None:
            raise InputError("keyframe_qpos needs keyframe_times (the time of each keyframe pose)")
        return None, None
    kt = np.asarray(keyframe_times, dtype=float)
    if kt.ndim != 1 or not np.all(np.isfinite(kt)):
        raise InputError(f"keyframe_times must be a finite array of shape (m,); got shape {kt.shape}")
    if keyframe_qpos is None:
        return kt, None
    kq = np.asarray(keyframe_qpos, dtype=float)
    if kq.shape != (kt.size, model.nq):
        raise InputError(
            f"keyframe_qpos must have shape (m, nq) = ({kt.size}, {model.nq}); got shape {kq.shape}")
    return kt, kq


def _ghost_data(model, tracks, kf_t, kf_q) -> list[list]:
    """Per panel, one posed MjData per keyframe (kinematics done once, reused every frame)."""
    if kf_t is None:
        return [[] for _ in tracks]

    def posed(q):
        d = mujoco.MjData(model)
        _forward(model, d, q)
        return d

    if kf_q is not None:
        shared = [posed(q) for q in kf_q]
        return [shared for _ in tracks]
    return [[posed(q) for q in sample_track(tr, kf_t)] for tr in tracks]


def _deep_sites(depth, i, site_ids):
    """[(site id, depth [m])] of the sites deeper than PENETRATION_SHOWN at frame i."""
    if depth is None:
        return []
    return [(int(s), float(d)) for s, d in zip(site_ids, depth[i]) if d > PENETRATION_SHOWN]


class _Overlay:
    """Composes panel images into a frame and draws the text, timeline and magenta rings (Pillow)."""

    def __init__(self, width, height, panel_w, n_panels, title, t0, t1, kf_t):
        self.width, self.height, self.panel_w, self.n = width, height, panel_w, n_panels
        self.x0 = (width - panel_w * n_panels) // 2
        self.title = title
        self.t0, self.t1 = t0, t1
        self.kf_t = kf_t if kf_t is not None else np.zeros(0)
        self.fs = max(10, height // 28)
        self.font = _font(self.fs)
        self.small = _font(max(9, int(self.fs * 0.75)))
        self._patches = {}

    def _text(self, im, xy, s, font, fill, anchor="la"):
        """Draw outlined text; each (text, font, colour, anchor) is rasterized once and pasted after
        (labels, tick numbers, captions and most time stamps repeat: this halves the overlay time)."""
        key = (s, id(font), fill, anchor)
        patch = self._patches.get(key)
        if patch is None:
            probe = ImageDraw.Draw(im)
            x0, y0, x1, y1 = probe.textbbox((0, 0), s, font=font, anchor=anchor, stroke_width=2)
            img = Image.new("RGBA", (max(1, x1 - x0), max(1, y1 - y0)), (0, 0, 0, 0))
            ImageDraw.Draw(img).text((-x0, -y0), s, font=font, fill=fill, anchor=anchor,
                                     stroke_width=2, stroke_fill=(0, 0, 0))
            patch = self._patches[key] = (img, x0, y0)
        img, x0, y0 = patch
        im.paste(img, (int(round(xy[0])) + x0, int(round(xy[1])) + y0), img)

    def compose(self, images, labels, t, speed, current, marks) -> np.ndarray:
        frame = np.empty((self.height, self.width, 3), np.uint8)
        frame[:] = _PAD_COLOR
        for p, img in enumerate(images):
            x = self.x0 + p * self.panel_w
            frame[:, x:x + self.panel_w] = img
        im = Image.fromarray(frame)
        draw = ImageDraw.Draw(im)
        fs, pad = self.fs, max(4, self.fs // 2)
        y = pad + (int(1.4 * fs) if self.title else 0)
        for p in range(len(images)):
            x = self.x0 + p * self.panel_w
            if p:
                draw.line([(x, 0), (x, self.height)], fill=(0, 0, 0), width=2)
            right = x + self.panel_w - pad
            self._text(im, (x + pad, y), labels[p], self.font, _WHITE)
            self._text(im, (right, y), f"t = {t:5.2f} s  ({speed:g}x)", self.small, _WHITE, anchor="ra")
            line = y + int(1.4 * fs)
            if current >= 0:
                self._text(im, (x + pad, line), f"keyframe {current + 1}  (t = {self.kf_t[current]:.2f} s)",
                      self.font, _CURRENT_TEXT)
                line += int(1.4 * fs)
            if marks[p] is not None:
                xy, deepest = marks[p]
                self._text(im, (x + pad, line), f"foot inside a surface: {100 * deepest:.1f} cm",
                      self.small, _PENETRATION_TEXT)
                r = max(6, self.height // 36)
                for px, py in xy:
                    if np.isfinite(px) and np.isfinite(py):
                        draw.ellipse([(x + px - r, py - r), (x + px + r, py + r)],
                                     outline=_PENETRATION_TEXT, width=3)
            self._timeline(im, draw, x, t, current)
        if self.title:
            self._text(im, (self.width // 2, pad), self.title, self.font, _WHITE, anchor="ma")
        return np.asarray(im)

    def _timeline(self, im, draw, x, t, current):
        pad = max(6, self.fs // 2)
        y = self.height - pad - self.fs // 2
        a, b = x + 2 * pad, x + self.panel_w - 2 * pad
        span = max(self.t1 - self.t0, 1e-9)

        def at(tt):
            return a + (b - a) * (min(max(tt, self.t0), self.t1) - self.t0) / span

        draw.line([(a, y), (b, y)], fill=(200, 200, 200), width=2)
        h = max(4, self.fs // 3)
        for k, tk in enumerate(self.kf_t):
            if not (self.t0 - 1e-9 <= tk <= self.t1 + 1e-9):
                continue
            xk = at(tk)
            color = _CURRENT_TEXT if k == current else _GHOST_TEXT
            draw.line([(xk, y - h), (xk, y + h)], fill=color, width=3 if k == current else 2)
            self._text(im, (xk, y - h - 2), str(k + 1), self.small, color, anchor="md")
        xt = at(t)
        draw.ellipse([(xt - h, y - h), (xt + h, y + h)], fill=_WHITE, outline=(0, 0, 0))
