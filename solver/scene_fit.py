"""Fit the static scene (floor height, raised boxes) to where the feet of a reference motion rest.

Motion capture records where the feet stood, not the props. `fit_scene` turns the contact-site
positions during contacts into a floor height and axis-aligned boxes, `scene_mjcf` writes them as a
MuJoCo scene around the figure.

Method:
1. Stances: a foot's site contacts that overlap in time form one stance (`contacts.foot_contacts`).
   Its rest height is the lowest of its sites' median heights over their contacts (the sole rests on
   its lowest site; a forefoot runner's heel hovers above). Its footprint is the x-y bounding box of
   all its sites during their contacts.
2. Floor: the median rest height of the stances within RAISED (0.05 m) of the lowest one.
3. Raised stances (rest height > floor + RAISED) are clustered by single linkage: two stances join
   when their rest heights differ by at most HEIGHT_TOL (0.08 m) and their footprints are at most
   LINK (1.0 m) apart in x-y. 0.08 m: on 127_33 retargeted onto a floor-only scene the two stances on
   the box rest at 0.227 and 0.271 m (the retargeting's root-height correction cannot see the box, so
   it interpolates across it), one box. 1.0 m: the two stances on the box are 0.5 m apart; a gap of
   a metre or more between stances at one height is more likely two props.
4. Box per cluster: top = the mean rest height of its stances (each stance counts once, however
   long); bottom = the floor; x-y extent = the cluster's footprint padded by MARGIN (0.2 m) on every
   side: the sites mark only heel and toe, the sole reaches a few cm past them, and an optimized
   path moves planted feet by a few cm; 0.2 m is also the spare the hand-made scene
   models/run_and_step.xml gives its step. Where the padding would put a floor-level contact
   point under the box, that side is pulled back to halfway between the footprint and the point.

Limits: the floor is horizontal (no slopes), boxes are axis-aligned (no rotation about z) and stand
on the floor, one box per cluster (an L-shaped platform becomes one bounding box), and an edge no
foot came near is set by the margin, not by data (only the contacts bound it: an edge lies between
the last contact on the box and the first on the floor). A surface nobody stood on is not found.
"""
from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from solver.contacts import FEET, SITES, Contact, contact_mask, detect_contacts, foot_contacts
from solver.errors import InputError

#: a stance resting more than this above the floor is on a raised surface [m].
RAISED = 0.05
#: stances on one box differ in rest height by at most this [m].
HEIGHT_TOL = 0.08
#: stances on one box have footprints at most this far apart in x-y [m].
LINK = 1.0
#: padding of a box's footprint on every side [m].
MARGIN = 0.2
#: `fit_contacts`: a "rest" whose site falls faster than this [m/s^2] (half of gravity) is the top of
#: a hop or jump, not a rest on a surface
BALLISTIC = 0.5 * 9.81


@dataclass(frozen=True)
class FittedScene:
    """A floor plane z = floor_z and axis-aligned boxes standing on it.

    Attributes:
        floor_z: [m] height of the floor.
        boxes: ((center (3,), half (3,)), ...) [m]: box i spans center - half .. center + half; its
            top center[2] + half[2] is where the feet rested.
    """

    floor_z: float
    boxes: tuple[tuple[np.ndarray, np.ndarray], ...] = ()

    def box_tops(self) -> list[float]:
        """[m] top height of each box."""
        return [float(c[2] + h[2]) for c, h in self.boxes]


@dataclass(frozen=True)
class _Stance:
    rest: float          # [m]
    lo: np.ndarray       # (2,) footprint min x, y
    hi: np.ndarray       # (2,) footprint max x, y


def _stances(times, site_pos, contacts, sites):
    mask = contact_mask(contacts, sites, times)
    feet = {f: tuple(s for s in members if s in sites) for f, members in FEET.items()}
    out = []
    for st in foot_contacts(contacts, feet):
        rests, pts = [], []
        for c in contacts:
            if c.site in feet[st.site] and c.start >= st.start - 1e-9 and c.end <= st.end + 1e-9:
                k = list(sites).index(c.site)
                rows = mask[:, k] & (times >= c.start - 1e-9) & (times <= c.end + 1e-9)
                if rows.any():
                    rests.append(float(np.median(site_pos[rows, k, 2])))
                    pts.append(site_pos[rows, k, :2])
        if rests:
            p = np.concatenate(pts)
            out.append(_Stance(min(rests), p.min(axis=0), p.max(axis=0)))
    return out


def _rect_gap(a: _Stance, b: _Stance) -> float:
    d = np.maximum(0.0, np.maximum(a.lo - b.hi, b.lo - a.hi))
    return float(np.linalg.norm(d))


def fit_scene(
    times: np.ndarray,
    site_pos: np.ndarray,
    contacts: Sequence[Contact],
    sites: Sequence[str] = SITES,
    raised: float = RAISED,
    height_tol: float = HEIGHT_TOL,
    link: float = LINK,
    margin: float = MARGIN,
) -> FittedScene:
    """Floor height and raised boxes from the contact-site positions during contacts (module doc).

    Args:
        times: (n,) [s]. site_pos: (n, s, 3) [m] site positions (world, z up). contacts: site
            contacts (e.g. `fit_contacts`, or hand-written). sites: the s site names.
        raised, height_tol, link, margin: [m], see the module constants.
    Returns:
        FittedScene; boxes sorted by their center x.
    Raises:
        InputError: no contact at all (nothing to fit), or shapes disagree.
    """
    times = np.asarray(times, float)
    site_pos = np.asarray(site_pos, float)
    if site_pos.shape != (len(times), len(sites), 3):
        raise InputError(f"site_pos must have shape ({len(times)}, {len(sites)}, 3); got {site_pos.shape}")
    stances = _stances(times, site_pos, contacts, sites)
    if not stances:
        raise InputError("no contacts: a scene is fitted to where the feet rest, and they never do")
    rest = np.array([s.rest for s in stances])
    floor_z = float(np.median(rest[rest <= rest.min() + raised]))
    low = [s for s in stances if s.rest <= floor_z + raised]
    high = [s for s in stances if s.rest > floor_z + raised]
    # single-linkage clusters of the raised stances
    label = list(range(len(high)))

    def root(i):
        while label[i] != i:
            i = label[i]
        return i

    for i in range(len(high)):
        for j in range(i + 1, len(high)):
            if abs(high[i].rest - high[j].rest) <= height_tol and _rect_gap(high[i], high[j]) <= link:
                label[root(j)] = root(i)
    floor_pts = [(s.lo + s.hi) / 2 for s in low] + [s.lo for s in low] + [s.hi for s in low]
    boxes = []
    for r in sorted({root(i) for i in range(len(high))}):
        members = [high[i] for i in range(len(high)) if root(i) == r]
        top = float(np.mean([m.rest for m in members]))
        flo = np.min([m.lo for m in members], axis=0)
        fhi = np.max([m.hi for m in members], axis=0)
        lo, hi = flo - margin, fhi + margin
        for p in floor_pts:
            if np.all(p >= lo) and np.all(p <= hi):
                out_lo, out_hi = flo - p, p - fhi  # > 0: p beyond the footprint on that side
                side = int(np.argmax(np.concatenate([out_lo, out_hi])))
                if side < 2 and out_lo[side] > 0:
                    lo[side] = (flo[side] + p[side]) / 2
                elif side >= 2 and out_hi[side - 2] > 0:
                    hi[side - 2] = (fhi[side - 2] + p[side - 2]) / 2
        center = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (floor_z + top) / 2])
        half = np.array([(hi[0] - lo[0]) / 2, (hi[1] - lo[1]) / 2, (top - floor_z) / 2])
        boxes.append((center, half))
    boxes.sort(key=lambda b: b[0][0])
    return FittedScene(floor_z, tuple(boxes))


def fit_contacts(times: np.ndarray, site_pos: np.ndarray, sites: Sequence[str] = SITES,
                 ballistic: float = BALLISTIC, **thresholds) -> list[Contact]:
    """Contacts for fitting a scene that is not known yet: heights relative to the foot's lowest site.

    `detect_contacts` needs each site's height above the surface under it, which is what is being
    fitted. Here a site's height is taken above the lowest site of the same foot in that frame, so
    the speed thresholds do the work: a foot's lowest site counts when it is still, its other site
    when it is also within the height thresholds of it (a flat foot).

    A foot is also slow at the top of a hop or a jump, where its upward speed passes through zero;
    it falls with the body there. A contact whose site height, fitted by a parabola over the contact's
    frames (least squares), accelerates downward faster than `ballistic` is such a top, not a rest,
    and is dropped, with any contact of the same foot's other site that overlaps it in time: a box
    under it would stand where the feet took off (a 15 cm hop made a 14 cm box; a 12 cm hop of the run
    35_17 a 12 cm box under the heel, which rose as the toe fell).
    Resting contacts of the shipped clips accelerate between -1.2 and +15 m/s^2 (heel strikes and
    push-offs curve upward), the tops of synthetic hops -6.5 to -10 (docs/contacts.md). A foot held
    still in the air (not falling) still counts as resting on something; the clips have none.

    Args:
        times: (n,) [s]. site_pos: (n, s, 3) [m]. sites: names. ballistic: [m/s^2] > 0.
        thresholds: of `detect_contacts`.
    """
    site_pos = np.asarray(site_pos, float)
    times = np.asarray(times, float)
    h = np.empty(site_pos.shape[:2])
    for members in FEET.values():
        ks = [list(sites).index(s) for s in members if s in sites]
        if ks:
            h[:, ks] = site_pos[:, ks, 2] - site_pos[:, ks, 2].min(axis=1, keepdims=True)
    found = detect_contacts(times, site_pos, h, sites, **thresholds)
    falling = []
    for c in found:
        rows = (times >= c.start - 1e-9) & (times <= c.end + 1e-9)
        if rows.sum() >= 3:
            t = times[rows] - times[rows].mean()
            if 2.0 * np.polyfit(t, site_pos[rows, list(sites).index(c.site), 2], 2)[0] < -ballistic:
                falling.append(c)
    # a foot whose one site falls is in the air: its other site's "rest" at the same time is no rest
    # either (its own motion can hide the fall: a push-off lifts the heel while the toe falls)
    foot = {s: f for f, members in FEET.items() for s in members}
    return [c for c in found if not any(foot.get(c.site) == foot.get(b.site) and c.start < b.end and b.start < c.end
                                        for b in falling)]


_SCENE = """<mujoco model="{model}">
  <include file="{figure}"/>

  <option timestep="0.002" gravity="0 0 -9.81"/>

  <visual>
    <headlight ambient="0.35 0.35 0.35" diffuse="0.4 0.4 0.4" specular="0.1 0.1 0.1"/>
    <map znear="0.01" zfar="50" shadowclip="0.4"/>
  </visual>

  <asset>
    <texture name="sky" type="skybox" builtin="gradient" rgb1="0.55 0.70 0.90" rgb2="0.10 0.15 0.25"
             width="512" height="512"/>
    <texture name="grid" type="2d" builtin="checker" rgb1="0.30 0.33 0.36" rgb2="0.22 0.25 0.28"
             mark="edge" markrgb="0.5 0.5 0.5" width="512" height="512"/>
    <material name="floor" texture="grid" texrepeat="1 1" texuniform="true" reflectance="0.1"/>
    <texture name="wood" type="cube" builtin="flat" rgb1="0.62 0.48 0.32" rgb2="0.55 0.40 0.25"
             mark="random" random="0.05" markrgb="0.45 0.33 0.20" width="256" height="256"/>
    <material name="step" texture="wood" rgba="1 1 1 1" specular="0.1"/>
  </asset>

  <worldbody>
    <light name="sun" mode="trackcom" pos="0 -2 6" dir="0.1 0.25 -1" directional="true" castshadow="true"
           diffuse="0.7 0.7 0.7" specular="0.2 0.2 0.2"/>
    <light name="fill" pos="4 4 4" dir="-1 -1 -1" directional="true" castshadow="false"
           diffuse="0.25 0.25 0.25"/>
    <geom name="floor" type="plane" pos="0 0 {floor_z:.6f}" size="0 0 0.05" material="floor"
          contype="1" conaffinity="1"/>
{boxes}    <camera name="side" mode="trackcom" pos="0 -5 1.2" xyaxes="1 0 0 0 0.25 1"/>
  </worldbody>
</mujoco>
"""


def scene_mjcf(fitted: FittedScene, figure_path: str | os.PathLike, relative_to: str | os.PathLike | None = None,
               model: str = "fitted_scene") -> str:
    """MJCF text of the fitted scene: the figure included, a floor plane "floor", boxes "box0", ...

    Materials, lights and camera as models/run_and_step.xml. The include path is absolute unless
    `relative_to` (the directory the scene will be saved in) is given, then relative to it; either way
    the scene loads from where it is saved (MuJoCo resolves includes against the main file's folder).

    Args:
        fitted: the scene. figure_path: the figure's MJCF (models/humanoid39.xml).
        relative_to: optional folder of the saved scene. model: the model name.
    Raises:
        InputError: figure_path does not exist.
    """
    fig = Path(figure_path).resolve()
    if not fig.is_file():
        raise InputError(f"figure_path {str(figure_path)!r} is not a file; give e.g. models/humanoid39.xml")
    inc = os.path.relpath(fig, Path(relative_to).resolve()) if relative_to is not None else str(fig)
    boxes = "".join(
        f'    <geom name="box{i}" type="box" pos="{c[0]:.6f} {c[1]:.6f} {c[2]:.6f}" '
        f'size="{h[0]:.6f} {h[1]:.6f} {h[2]:.6f}" material="step" contype="1" conaffinity="1"/>\n'
        for i, (c, h) in enumerate(fitted.boxes)
    )
    return _SCENE.format(model=model, figure=inc, floor_z=fitted.floor_z, boxes=boxes)
