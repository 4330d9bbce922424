"""What is drawn on the panels: the figure panel, keyframe ghosts, the penetration circles, captions,
timelines and titles."""
from __future__ import annotations

import math

import mujoco
import numpy as np
from PIL import Image, ImageDraw

from runner.render.gl import QUALITIES, coarse_floor, load_font, project_points
from runner.render.tracks import Camera, Track, forward_direction, root_body, sample_track
from solver.errors import InputError

PENETRATION_SHOWN = 1e-3
"""[m] a contact site deeper than this inside a surface is circled in magenta."""
KEYFRAME_CAPTION_SECONDS = 0.25
"""[s] of video before playback reaches keyframe k during which "keyframe k" and its yellow ghost are
shown; they go at the first frame after the keyframe (they do not linger once it has passed). Keyframes
are numbered as in the keyframe file and its error messages: k is the index in its "keyframes" list,
from 0."""
GHOST_WINDOW = 0.3
"""[s] of motion time: a keyframe's ghost is drawn only while playback is within this of the keyframe,
fading in and out (opacity 1 at the keyframe, 0 at this distance; `ghost_alphas`)."""
LABELS_MIN_SIZE = (320, 180)
"""[px] (width, height) of the video below which no text is drawn (labels, times, captions, title):
at smaller sizes the letters are illegible scraps. The timeline and the magenta rings stay."""

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
_PLANE = int(mujoco.mjtGeom.mjGEOM_PLANE)
_ROUND_ENDED = frozenset(int(t) for t in (mujoco.mjtGeom.mjGEOM_CAPSULE, mujoco.mjtGeom.mjGEOM_CYLINDER))
_GHOST_TEXT = (225, 235, 255)
_PLANTED_FILL = (40, 220, 90)  # a site the contact schedule has planted
_CURRENT_TEXT = (255, 217, 64)
_PENETRATION_TEXT = (255, 40, 230)
WHITE = (255, 255, 255)
_PAD_COLOR = (24, 24, 28)
#: the video's legend of the ghosts (`Overlay._legend`): (text, colour) drawn one after the other
LEGEND = (("ghosts: keyframe poses", _GHOST_TEXT), ("  yellow: the next", _CURRENT_TEXT))


class Panel:
    """Renders one panel (a pose, keyframe ghosts, marked bodies) into an (h, w, 3) uint8 image.

    Owns its MjData, camera and scene options; one per Renderer, reused for every panel and frame.
    """

    def __init__(self, model, renderer, quality: str = "fast"):
        self.model = model
        self.renderer = renderer
        if not QUALITIES[quality].reflections:
            renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
        self.coarse_floor = QUALITIES[quality].coarse_floor
        self.data = mujoco.MjData(model)
        self.root = root_body(model)
        self.option = mujoco.MjvOption()
        self.ghost_option = mujoco.MjvOption()
        self.ghost_option.sitegroup[:] = 0
        self.perturb = mujoco.MjvPerturb()
        self.cam = mujoco.MjvCamera()
        self.cam.type = mujoco.mjtCamera.mjCAMERA_FREE

    def set_camera(self, camera: Camera, lookat: np.ndarray, azimuth: float | None = None) -> None:
        """Look at `lookat` from `camera`'s distance and elevation; azimuth [deg]: this frame's (from
        `azimuth_path`), default `camera.azimuth`."""
        self.cam.distance = camera.distance
        self.cam.azimuth = camera.azimuth if azimuth is None else azimuth
        self.cam.elevation = camera.elevation
        self.cam.lookat[:] = lookat

    def render(self, qpos, ghosts=(), current=-1, marked_bodies=(), alphas=None):
        """Image (h, w, 3) uint8 of the figure at qpos with ghost MjData (posed) drawn translucent.

        alphas: (len(ghosts),) opacity factor of each ghost in [0, 1] (`ghost_alphas`), None: all 1;
        a ghost at 0 is not drawn."""
        model, scene = self.model, self.renderer.scene
        forward_direction(model, self.data, qpos)
        # mjv_updateScene places an infinite plane under the scene's camera of the previous update: set
        # this camera first, so the picture depends on this frame only (not on what was drawn before)
        mujoco.mjv_updateCamera(model, self.data, self.cam, scene)
        self.renderer.update_scene(self.data, self.cam, self.option)
        if self.coarse_floor:
            coarse_floor(model, scene)
        for i in range(scene.ngeom):  # planes cast no shadow: no floor self-shadowing (acne)
            if scene.geoms[i].type == _PLANE:
                scene.geoms[i].castshadow = 0
        if len(marked_bodies):
            geom_type = int(mujoco.mjtObj.mjOBJ_GEOM)
            for i in range(scene.ngeom):
                g = scene.geoms[i]
                if g.objtype == geom_type and model.geom_bodyid[g.objid] in marked_bodies:
                    g.rgba[:] = _PENETRATION_RGBA
                    g.matid = -1
        visible = self._visible(ghosts)
        if alphas is not None:
            visible &= np.asarray(alphas) > 0.01
        for k, gdata in enumerate(ghosts):
            if not visible[k]:
                continue
            n0 = scene.ngeom
            mujoco.mjv_addGeoms(model, gdata, self.ghost_option, self.perturb,
                                mujoco.mjtCatBit.mjCAT_DYNAMIC, scene)
            rgba = (_GHOST_CURRENT_RGBA if k == current else _GHOST_RGBA).copy()
            if alphas is not None:
                rgba[3] *= float(alphas[k])
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
        return project_points(glcam, points, self.renderer.width, self.renderer.height)


def check_model_fit(model, track: Track) -> np.ndarray:
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


def draw_text(draw, xy, s, font, fill, anchor="la"):
    """Draw `s` at `xy` with a black outline (readable on any background)."""
    draw.text(xy, s, font=font, fill=fill, anchor=anchor, stroke_width=2, stroke_fill=(0, 0, 0))


def positive(value, name: str) -> float:
    """`value` as a float if finite and > 0; else InputError naming `name`."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a positive number; got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise InputError(f"{name} must be a positive number; got {value!r}")
    return v


def check_keyframes(model, keyframe_times, keyframe_qpos):
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


def ghost_data(model, tracks, kf_t, kf_q) -> list[list]:
    """Per panel, one posed MjData per keyframe (kinematics done once, reused every frame)."""
    if kf_t is None:
        return [[] for _ in tracks]

    def posed(q):
        d = mujoco.MjData(model)
        forward_direction(model, d, q)
        return d

    if kf_q is not None:
        shared = [posed(q) for q in kf_q]
        return [shared for _ in tracks]
    return [[posed(q) for q in sample_track(tr, kf_t)] for tr in tracks]


def ghost_alphas(t: float, kf_t, window: float = GHOST_WINDOW) -> np.ndarray:
    """(m,) opacity factor of each keyframe's ghost at motion time t [s]: 1 at the keyframe, 0 from
    `window` [s] away on, a smoothstep in between (fades in before the keyframe, out after it)."""
    if kf_t is None:
        return np.zeros(0)
    x = np.clip(1.0 - np.abs(t - np.asarray(kf_t, dtype=float)) / window, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def current_keyframes(times: np.ndarray, kf_t, lead: float) -> np.ndarray:
    """(n,) per video frame the keyframe whose caption and yellow ghost are shown, -1 for none.

    Keyframe k is current from `lead` [s of motion time] before it up to the frame nearest to it
    (at most half a frame step after it): the caption announces the keyframe as playback reaches it
    and goes once it has passed. Where two windows overlap the nearer keyframe wins."""
    n = times.size
    out = np.full(n, -1, int)
    if kf_t is None or not len(kf_t):
        return out
    step = float(np.median(np.diff(times))) if n > 1 else 0.0
    kf = np.asarray(kf_t, dtype=float)
    d = times[:, None] - kf[None, :]  # (n, m) time since keyframe
    on = (d >= -max(lead, 0.0) - 1e-9) & (d <= 0.5 * step + 1e-9)
    dist = np.where(on, np.abs(d), np.inf)
    k = np.argmin(dist, axis=1)
    has = np.isfinite(dist[np.arange(n), k])
    out[has] = k[has]
    return out


def deep_sites(depth, i, site_ids):
    """[(site id, depth [m])] of the sites deeper than PENETRATION_SHOWN at frame i."""
    if depth is None:
        return []
    return [(int(s), float(d)) for s, d in zip(site_ids, depth[i]) if d > PENETRATION_SHOWN]


def labels_shown(width: int, height: int) -> bool:
    """Whether a video of this size gets text (see LABELS_MIN_SIZE)."""
    return width >= LABELS_MIN_SIZE[0] and height >= LABELS_MIN_SIZE[1]


def title_band(height: int, title: str | None) -> int:
    """[px] height of the band above the panels that holds the title (0 without a title); even, so
    the panels keep an even height."""
    if not title:
        return 0
    fs = max(10, height // 28)
    return 2 * ((int(1.6 * fs) + 1) // 2)


class Overlay:
    """Composes panel images into a frame and draws the text, timeline and magenta rings (Pillow)."""

    def __init__(self, width, height, panel_w, n_panels, title, t0, t1, kf_t):
        self.width, self.height, self.panel_w, self.n = width, height, panel_w, n_panels
        self.x0 = (width - panel_w * n_panels) // 2
        self.labels = labels_shown(width, height)
        self.title = title if self.labels else None
        self.band = title_band(height, self.title)
        self.t0, self.t1 = t0, t1
        self.kf_t = kf_t if kf_t is not None else np.zeros(0)
        self.fs = max(10, height // 28)
        self.font = load_font(self.fs)
        self.small_px = max(9, int(self.fs * 0.75))
        self.small = load_font(self.small_px)
        self._patches = {}
        self._background = np.empty((height, width, 3), np.uint8)
        self._background[:] = _PAD_COLOR

    def draw_text(self, im, xy, s, font, fill, anchor="la"):
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

    def compose(self, images, labels, t, speed, current, marks, planted=None) -> np.ndarray:
        """The frame: the title in a band above all panels (never across a divider), then the panels
        side by side, each with its label, time, caption, rings and timeline (no text below
        LABELS_MIN_SIZE); green dots at the projected sites of `planted` (per panel an (m, 2) array of
        pixel positions, or None)."""
        frame = self._background.copy()  # a copy is ~30x faster than filling with a colour tuple
        for p, img in enumerate(images):
            x = self.x0 + p * self.panel_w
            frame[self.band:, x:x + self.panel_w] = img
        im = Image.fromarray(frame)
        draw = ImageDraw.Draw(im)
        fs, pad = self.fs, max(4, self.fs // 2)
        y = self.band + pad
        for p in range(len(images)):
            x = self.x0 + p * self.panel_w
            if p:
                draw.line([(x, self.band), (x, self.height)], fill=(0, 0, 0), width=2)
            if not self.labels:
                if marks[p] is not None:
                    self._rings(draw, x, marks[p][0])
                self._timeline(im, draw, x, t, current)
                continue
            right = x + self.panel_w - pad
            self.draw_text(im, (x + pad, y), labels[p], self.font, WHITE)
            self.draw_text(im, (right, y), f"t = {t:5.2f} s  ({speed:g}x)", self.small, WHITE, anchor="ra")
            line = y + int(1.4 * fs)
            if current >= 0:
                self.draw_text(im, (x + pad, line), f"keyframe {current}  (t = {self.kf_t[current]:.2f} s)",
                      self.font, _CURRENT_TEXT)
                line += int(1.4 * fs)
            if marks[p] is not None:
                xy, deepest = marks[p]
                self.draw_text(im, (x + pad, line), f"foot inside a surface: {100 * deepest:.1f} cm",
                      self.small, _PENETRATION_TEXT)
                self._rings(draw, x, xy)
            if planted is not None and planted[p] is not None:
                r = max(3, self.height // 90)
                for px, py in planted[p]:
                    if np.isfinite(px) and np.isfinite(py):
                        py = py + self.band
                        draw.ellipse([(x + px - r, py - r), (x + px + r, py + r)], fill=_PLANTED_FILL)
            self._timeline(im, draw, x, t, current)
            if p == 0:
                self._legend(im, draw, x)
        if self.title:
            self.draw_text(im, (self.width // 2, self.band // 2), self.title, self.font, WHITE, anchor="mm")
        return np.asarray(im)

    def _legend(self, im, draw, x):
        """What the ghosts are, in their colours, at the left of the first panel just above its timeline:
        "ghosts: keyframe poses" (white, the keyframes within `GHOST_WINDOW` of the playback time) and
        "yellow: the next" (the keyframe playback is about to reach); only the parts that fit the panel,
        and only with keyframes on the timeline."""
        if not len(self.kf_t):
            return
        pad = max(6, self.fs // 2)
        y = self.height - pad - self.fs // 2 - max(4, self.fs // 3) - self.small_px - 6  # above the tick numbers
        xk = x + 2 * pad
        for text, colour in LEGEND:
            w = draw.textlength(text, font=self.small) + 4  # + the outline
            if xk + w > x + self.panel_w - 2 * pad:
                return
            self.draw_text(im, (xk, y), text, self.small, colour, anchor="ld")
            xk += w

    def _rings(self, draw, x, xy):
        r = max(6, self.height // 36)
        for px, py in xy:
            if np.isfinite(px) and np.isfinite(py):
                py = py + self.band
                draw.ellipse([(x + px - r, py - r), (x + px + r, py + r)], outline=_PENETRATION_TEXT, width=3)

    def _timeline(self, im, draw, x, t, current):
        """The timeline under a panel: a tick per keyframe, its number (from 0, as in the keyframe file)
        where it does not overlap another (`timeline_labels`), the playback position as a white dot."""
        pad = max(6, self.fs // 2)
        y = self.height - pad - self.fs // 2
        a, b = x + 2 * pad, x + self.panel_w - 2 * pad
        span = max(self.t1 - self.t0, 1e-9)

        def at(tt):
            return a + (b - a) * (min(max(tt, self.t0), self.t1) - self.t0) / span

        draw.line([(a, y), (b, y)], fill=(200, 200, 200), width=2)
        h = max(4, self.fs // 3)
        shown = [k for k, tk in enumerate(self.kf_t) if self.t0 - 1e-9 <= tk <= self.t1 + 1e-9]
        for k in shown:
            xk = at(self.kf_t[k])
            color = _CURRENT_TEXT if k == current else _GHOST_TEXT
            draw.line([(xk, y - h), (xk, y + h)], fill=color, width=3 if k == current else 2)
        if self.labels and shown:
            widths = [draw.textlength(str(k), font=self.small) + 4 for k in shown]  # + the outline
            centres = [at(self.kf_t[k]) for k in shown]
            first = shown.index(current) if current in shown else None
            for i in timeline_labels(centres, widths, first, gap=max(2.0, self.fs / 4)):
                k = shown[i]
                color = _CURRENT_TEXT if k == current else _GHOST_TEXT
                self.draw_text(im, (centres[i], y - h - 2), str(k), self.small, color, anchor="md")
        xt = at(t)
        draw.ellipse([(xt - h, y - h), (xt + h, y + h)], fill=WHITE, outline=(0, 0, 0))


def timeline_labels(centres, widths, first=None, gap: float = 2.0) -> list[int]:
    """Which tick labels of a timeline to draw so that no two overlap.

    Args:
        centres: (m,) [px] the labels' horizontal centres, increasing. widths: (m,) [px] their widths.
        first: index of a label that is always drawn (the current keyframe's), or None.
        gap: [px] free space kept between two labels.
    Returns:
        the indices drawn, increasing: `first`, then greedily from left to right every label that keeps
        `gap` from those already drawn (close keyframes keep their ticks, their numbers are thinned out).
    """
    kept = [] if first is None else [first]

    def fits(i):
        return all(abs(centres[i] - centres[j]) >= (widths[i] + widths[j]) / 2 + gap for j in kept)

    for i in range(len(centres)):
        if i != first and fits(i):
            kept.append(i)
    return sorted(kept)
