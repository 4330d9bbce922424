"""The OpenGL side: quality presets, the offscreen renderer and its headless fallback, projection."""
from __future__ import annotations

import math
import os
from dataclasses import dataclass

import mujoco
import numpy as np
from PIL import ImageFont

from solver.errors import InputError


@dataclass(frozen=True)
class Quality:
    """A render quality preset.

    Attributes:
        caps: upper bounds for fields of the model's `<visual><quality>` (MSAA samples, shadow map
            size [px], tessellation of round geoms and planes), applied while the GL context is made.
        reflections: draw reflections in reflective materials (the floor): renders the scene twice.
        coarse_floor: draw an infinite floor lit by directional lights as one quad (`coarse_floor`).
    """

    caps: dict
    reflections: bool
    coarse_floor: bool = False


QUALITIES = {
    "fast": Quality({"offsamples": 0, "shadowsize": 1024, "numslices": 12, "numstacks": 6, "numquads": 1},
                    reflections=False, coarse_floor=True),
    "high": Quality({}, reflections=True),
}
"""Render presets. "fast" (the default) takes about half of what MuJoCo's defaults take on Mesa's
software renderer (llvmpipe): no multisampling, a shadow map of at most 1024 px (`render_tracks`
takes the smaller `shadow_map_size` where that draws the same shadow), coarser capsules and spheres
(invisible at these sizes), no reflections. "high" uses the model's own `<visual><quality>` settings
(MuJoCo's defaults: 4x MSAA, 4096 px shadows, reflections), several times slower. "fast" draws an
infinite floor lit by directional lights as one quad (`coarse_floor`; with reflections, as in
"high", the floor's brightness would change by about one level of 255)."""


def check_quality(quality: str) -> None:
    """Raises InputError naming the choices when `quality` is not a `QUALITIES` preset."""
    if quality not in QUALITIES:
        raise InputError(f"unknown render quality {quality!r}; choose one of {list(QUALITIES)}")


def make_renderer(model, width: int, height: int, quality: str = "fast", shadow_size: int | None = None):
    """A `mujoco.Renderer` of width x height with the `quality` preset's GL context settings.

    The model's offscreen buffer size (raised to the image size) and `<visual><quality>` fields
    (capped by the preset) are changed only while the rendering context is made, then restored: the
    caller's model is unchanged. shadow_size: [px] a lower cap for the shadow map of a preset that
    caps it ("fast"), e.g. `shadow_map_size`; None: the preset's.

    Raises:
        InputError: unknown quality; the OpenGL backend cannot be initialized (no EGL/OSMesa, bad
            MUJOCO_GL).
    """
    check_quality(quality)
    _headless_fallback()
    vis = model.vis
    saved_size = (vis.global_.offwidth, vis.global_.offheight)
    saved_quality = {name: getattr(vis.quality, name) for name in QUALITIES[quality].caps}
    vis.global_.offwidth = max(width, vis.global_.offwidth)
    vis.global_.offheight = max(height, vis.global_.offheight)
    caps = dict(QUALITIES[quality].caps)
    if shadow_size is not None and "shadowsize" in caps:
        caps["shadowsize"] = min(caps["shadowsize"], int(shadow_size))
    for name, cap in caps.items():
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


def shadow_map_size(model, panel_height: int, distance: float) -> int:
    """[px] the smallest shadow map (a power of two, 256 to 4096) whose texels are no larger than a
    pixel of the panel at the camera's look-at distance, for directional lights.

    `mjr_render` renders a directional light's shadow map over a square of half-width
    `vis.map.shadowclip * stat.extent` [m] (its `glOrtho`); a panel of `panel_height` px shows
    2 distance tan(fovy / 2) [m] at the look-at point. A larger map is not seen, only paid for (at
    960x540 and the default camera a 512 px map draws the shipped scene's shadows as a 1024 px one);
    a closer camera or a taller video gets a larger one.
    """
    clip = model.vis.map.shadowclip * model.stat.extent
    pixel = 2.0 * distance * math.tan(math.radians(model.vis.global_.fovy) / 2) / max(int(panel_height), 1)
    need = 2.0 * clip / max(pixel, 1e-9)
    return int(min(4096, 2 ** math.ceil(math.log2(max(need, 256.0)))))


_GLFW_CHOICES = ("", "glfw", "enable", "enabled", "on", "true", "1")


def _headless_fallback() -> None:
    """Use EGL/OSMesa after all if mujoco was imported before MUJOCO_GL was set and there is no display.

    mujoco picks its OpenGL backend once, when first imported. A program (or a test's conftest) that
    imports mujoco before `solver` gets GLFW, which needs a display. When there is none and
    MUJOCO_GL now names "egl" or "osmesa" (as `solver` sets it), point mujoco's offscreen context
    class at that backend, so rendering works whatever the import order. An explicit user choice of
    backend at import time is left alone; if the switch is not possible, nothing changes and
    `make_renderer` reports the failure.
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
        text += (f"; MUJOCO_GL={now!r} was set after that, too late (import runner, which calls "
                 "runner.environment.apply_defaults, before mujoco)")
    return text


def load_font(px: int):
    """A PIL font of `px` pixels (DejaVu Sans if available, else PIL's small bitmap font)."""
    try:
        return ImageFont.load_default(size=px)
    except (TypeError, OSError, ImportError):  # old Pillow or no FreeType: small bitmap font
        return ImageFont.load_default()


def project_points(glcam, points: np.ndarray, width: int, height: int) -> np.ndarray:
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


_PLANE = int(mujoco.mjtGeom.mjGEOM_PLANE)
_MAX_PLANE_GRID = 200
"""MuJoCo's `mjMAXPLANEGRID`: an infinite plane's display list is a 200 x 200 grid of quads."""


def coarse_floor(model, scene) -> None:
    """Draw the scene's infinite planes as one large quad each instead of MuJoCo's 200 x 200 grid.

    `mjr_makeContext` builds an infinite plane (size 0 0) as a 200 x 200 grid of quads (40,000) whose
    extent reaches past the far clipping plane. A software renderer (llvmpipe) transforms all of them
    in every pass (the lit pass, and again for each shadow-casting light): about a third of a panel's
    render time on the shipped scenes. After `mjv_updateScene` this turns each such plane into a
    finite plane of the same extent, drawn with MuJoCo's default plane list (`numquads` x
    `numquads` quads, one in the "fast" preset), and appends a zero-size copy of it, which draws
    nothing but keeps MuJoCo's horizon haze (drawn for the first infinite plane of the scene).

    The picture is unchanged (within rounding): OpenGL's fixed-function lighting is computed at the
    vertices, which for a flat plane lit by directional lights only gives the same colour everywhere
    (scenes with a spot or point light, or fog, keep MuJoCo's grid), and the texture keeps its place: with `texuniform` the default
    list repeats the texture every 2 / texrepeat [m] from a corner of the plane, so the half-size is
    rounded up to a whole number of repeats and the centre moved by half a repeat (as MuJoCo's own
    grid, whose texture is repeated from the plane's centre, `mjr_render`'s `settexture`). Planes
    with a texture that is not `texuniform` (repeated per plane, not per metre) are left as they are.

    Args:
        model: the MjModel (`vis.map.zfar`, `stat.extent`: MuJoCo's extent of an infinite plane).
        scene: the MjvScene, right after `mjv_updateScene` (changed in place; needs one free geom per
            infinite plane, else that plane is left as it is).
    """
    if not _uniform_light(scene):
        return
    zfar = model.vis.map.zfar * model.stat.extent
    n = scene.ngeom
    for i in range(n):
        g = scene.geoms[i]
        if g.type != _PLANE or g.dataid < 0 or g.size[0] != 0 or g.size[1] != 0 or scene.ngeom >= scene.maxgeom:
            continue
        textured, uniform, repeat = _plane_texture(model, g)
        if textured and not uniform:
            continue
        period = np.where(repeat > 0, 2.0 / np.where(repeat > 0, repeat, 1.0), 2.1 * zfar / (_MAX_PLANE_GRID - 2))
        half = (2.1 * zfar + 2 * period) / 2  # MuJoCo's grid extent, from the plane's centre
        size = np.ceil(half / period) * period
        haze = scene.geoms[scene.ngeom]  # zero size: invisible, but MuJoCo draws the haze for it
        mujoco.mjv_initGeom(haze, _PLANE, np.zeros(3), np.asarray(g.pos, float),
                            np.asarray(g.mat, float).ravel(), np.asarray(g.rgba, np.float32))
        haze.dataid, haze.castshadow, haze.reflectance = -1, 0, 0.0
        haze.objtype, haze.objid, haze.segid, haze.category = g.objtype, g.objid, g.segid, g.category
        scene.ngeom += 1
        g.dataid = -1
        g.size[0], g.size[1] = size
        if textured:
            mat = np.asarray(g.mat, float).reshape(3, 3)
            g.pos[:] = np.asarray(g.pos, float) + mat[:, :2] @ (period / 2)


def _plane_texture(model, g) -> tuple[bool, bool, np.ndarray]:
    """(has a texture, texuniform, texrepeat (2,)) of a scene geom (MuJoCo < 3.3: from its material)."""
    if hasattr(g, "texid"):
        return g.texid >= 0, bool(g.texuniform), np.asarray(g.texrepeat, float)
    m = g.matid
    if m < 0:
        return False, False, np.zeros(2)
    return (bool(np.max(model.mat_texid[m]) >= 0), bool(model.mat_texuniform[m]),
            np.asarray(model.mat_texrepeat[m], float))


def _uniform_light(scene) -> bool:
    """Whether a plane is lit the same at every vertex: every light of the scene (the headlight
    included) is directional, and there is no fog."""
    if scene.flags[mujoco.mjtRndFlag.mjRND_FOG]:
        return False
    directional = int(mujoco.mjtLightType.mjLIGHT_DIRECTIONAL) if hasattr(mujoco, "mjtLightType") else None
    for i in range(scene.nlight):
        light = scene.lights[i]
        if directional is not None and hasattr(light, "type"):
            if int(light.type) != directional:
                return False
        elif not getattr(light, "directional", False):
            return False
    return True
