"""Fit the static scene (a floor plane, raised boxes) to where the feet of a reference motion rest.

Motion capture records where the feet stood, not the props. `fit_scene` turns the contact-site
positions during contacts into a floor plane and boxes standing on it, `scene_mjcf` writes them as a
MuJoCo scene around the figure (docs/contacts.md "Fitted scenes").

Method:
1. Stances: a foot's site contacts that overlap in time form one stance (`contacts.foot_contacts`).
   Its rest height is the lowest of its sites' median heights over their contacts (the sole rests on
   its lowest site; a forefoot runner's heel hovers above), at that site's median x, y. Its footprint
   is the x-y bounding box of all its sites during their contacts.
2. Floor: a plane z = a + b x + c y through the rest points of the floor stances, fitted by least
   squares with a soft-L1 loss (scale PLANE_SCALE, 5 mm: a stance resting a few cm off, a foot not
   quite down, pulls the plane by its sign, not its size). The floor stances start as those within
   RAISED (0.05 m) of the lowest one and are then those within RAISED above the plane fitted to them,
   until they no longer change (a floor rising 5 cm along the clip keeps its far end).
   - The slope is fitted only along the principal directions of the floor stances' x, y in which they
     extend over MIN_SPAN (1 m) or more, and only with MIN_STANCES (4) of them or more: across a
     straight walk the stances spread 0.2-0.3 m, where a left-right difference of the sole heights
     (13 mm on 16_23's source feet) would pass for a 5 % cross slope; with fewer than 4 rests a plane
     follows their scatter.
   - A slope steeper than MAX_SLOPE (0.05, about 3 degrees) is not a capture floor's tilt (the shared
     clips that tilt, three of six, by 0.6-1.1 degrees): the floor is fitted level instead.
   - A tilt that moves the floor by less than LEVEL_TOL (5 mm) across the floor stances is written
     level: the stances' rest heights scatter about the fitted floor by 2-7 mm (standard deviation,
     the source feet of the shared clips), so such a tilt is not told from level.
   A floor that rises along the clip is modelled as tilted in space, not drifting in time: on 07_04
   (a walk whose floor rises 2 cm per metre) a foot flat and still on the floor rises at 0-4 mm/s
   (frame-weighted mean 3.6 mm/s, like the standing feet of the level clips 75_03 and 83_02, 1-4 mm/s),
   where a drift in time would raise it at 19 mm/s; a tilted plane fits its six stances to 2 mm
   (standard deviation), a level one to 23 mm.
3. Levels and boxes, in the floor's frame (`FittedScene.rotation`; heights above the floor plane): the
   raised stances (rest > RAISED) are sorted by rest height and split into levels wherever two
   consecutive rests differ by more than HEIGHT_TOL (5 cm; a 1-D single-linkage clustering): the rests
   of one surface scatter by up to 3 cm (on 127_33 the two stances on the box rest 1-4 cm apart; two
   feet of one capture disagree by up to 3 cm, docs/mocap.md), and a rise of more than RAISED is
   another surface, as it is from the floor. Within a level, stances join when their footprints are at
   most LINK (1.0 m) apart: a gap of a metre or more between stances at one height is more likely two
   props. Each cluster is one box.
4. Box per cluster: top = the mean rest height of its stances above the floor (each stance counts
   once, however long); bottom = the floor; extent = the cluster's footprint padded by MARGIN (0.2 m)
   on every side (the sites mark only heel and toe, the sole reaches a few cm past them, and an
   optimized path moves planted feet by a few cm; 0.2 m is also the spare the hand-made scene
   models/run_and_step.xml gives its step), except that no box covers a footprint of another height
   or prop: where the padded box would cover a floor stance's footprint, or overlap another box
   padded likewise, its side facing that footprint is pulled back to halfway between the two
   footprints (on the axis along which they lie furthest apart; two boxes stop at the same line), and
   likewise where a contact site of any frame passed more than RAISED below its top beside the rests (a
   swinging foot under the padding). A cluster whose footprint overlaps a floor stance's or another
   cluster's gets no box: no prop stood where a foot rested at another height (docs/contacts.md). So the
   boxes of a stair are side by side, none inside another, each under the rests it was fitted to, and a
   contact is on the surface under its site. A box on a tilted floor is tilted with it.

5. Levelling (`FittedScene.levelling`, `FittedScene.levelled`; solver/capture_frame.py): a tilted
   capture floor is a calibration error of the capture volume, so `runner.capture.scene.clip_scene`
   writes the scene in the frame where the fitted floor is z = 0 (the shortest rotation taking its
   normal to +z, then a vertical shift), the boxes square to the world axes, and records that rigid
   transform in the scene for the clip's import (and its inverse for the export onto the source).

Limits (docs/contacts.md "Fitted scenes"): one floor plane, no drift in time, boxes square to the floor
and standing on it, one box per cluster, an edge no foot came near set by the margin, rises of 5 cm or
less not told apart; a surface nobody stood on is not found.
"""
from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from runner.capture.contact_detection import detect_contacts
from solver.capture_frame import CaptureFrame
from solver.contacts import Contact, contact_mask, foot_contacts
from solver.errors import InputError
from solver.figure import foot_sites

#: a stance resting more than this above the floor is on a raised surface [m].
RAISED = 0.05
#: [m] rest heights closer than this (sorted, consecutive) are one level: the rests of one surface scatter
#: by up to 3 cm, and a rise of more than RAISED is another surface, as it is from the floor (module doc, 3).
HEIGHT_TOL = RAISED
#: stances on one box have footprints at most this far apart in x-y [m].
LINK = 1.0
#: padding of a box's footprint on every side [m].
MARGIN = 0.2
#: the floor's slope is fitted only along directions in which its stances spread over this much [m].
MIN_SPAN = 1.0
#: a fitted tilt that moves the floor by less than this across its stances is written level [m].
LEVEL_TOL = 0.005
#: a fitted slope steeper than this [m/m] (about 3 degrees) is not a tilted capture floor.
MAX_SLOPE = 0.05
#: the floor's slope is fitted only through at least this many floor stances.
MIN_STANCES = 4
#: scale of the soft-L1 loss of the floor plane fit [m]: residuals beyond it count linearly.
PLANE_SCALE = 0.005
#: `fit_contacts`: a "rest" whose site falls faster than this [m/s^2] (half of gravity) is the top of
#: a hop or jump, not a rest on a surface
BALLISTIC = 0.5 * 9.81


@dataclass(frozen=True)
class FittedScene:
    """A floor plane z = floor_z + slope . (x, y) and boxes standing on it, square to it.

    Attributes:
        floor_z: [m] height of the floor at x = y = 0.
        boxes: ((center (3,), half (3,)), ...) [m]: box i spans center +- half along the floor's axes
            (`rotation`: the world axes when the floor is level); its top face, parallel to the floor
            at the distance 2 half[2] above it, is where the feet rested.
        floor_slope: (dz/dx, dz/dy) of the floor [m/m]; (0, 0): level.
    """

    floor_z: float
    boxes: tuple[tuple[np.ndarray, np.ndarray], ...] = ()
    floor_slope: tuple[float, float] = (0.0, 0.0)

    @property
    def level(self) -> bool:
        """True when the floor is horizontal (floor_slope == (0, 0))."""
        return not any(self.floor_slope)

    def floor_height(self, x, y) -> np.ndarray:
        """[m] height of the floor plane at world x, y [m] (arrays broadcast)."""
        b, c = self.floor_slope
        return self.floor_z + b * np.asarray(x, float) + c * np.asarray(y, float)

    def rotation(self) -> np.ndarray:
        """(3, 3) the floor's frame: columns x', y', n (n the floor's upward unit normal); the shortest
        rotation taking world z to n (Rodrigues' formula), the identity when the floor is level."""
        return _tilt_rotation(*self.floor_slope)

    def tilt_deg(self) -> float:
        """[deg] angle between the floor's normal and world z."""
        return float(np.degrees(np.arctan(np.hypot(*self.floor_slope))))

    def describe_floor(self) -> str:
        """One line for the user: the floor's height at the origin and, if tilted, by how much and which way."""
        if self.level:
            return f"floor level at {100 * self.floor_z:.1f} cm"
        b, c = self.floor_slope
        return (f"floor tilted {self.tilt_deg():.2f} deg ({100 * b:+.2f} cm per m along x, {100 * c:+.2f} along y), "
                f"{100 * self.floor_z:.1f} cm at x = y = 0")

    def box_tops(self) -> list[float]:
        """[m] world height of the centre of each box's top face."""
        n = self.rotation()[:, 2]
        return [float(c[2] + h[2] * n[2]) for c, h in self.boxes]

    def box_heights(self) -> list[float]:
        """[m] height of each box's top above the floor, along the floor's normal (2 half[2])."""
        return [float(2 * h[2]) for _, h in self.boxes]

    def surfaces(self):
        """The floor and boxes as `solver.surfaces.StaticSurfaces` (names "floor", "box0", ...), for
        heights above them (`StaticSurfaces.height_above`) without writing a scene file."""
        from solver.surfaces import StaticSurfaces

        rot = self.rotation()
        return StaticSurfaces(np.array([[0.0, 0.0, self.floor_z]]), rot[:, 2][None].copy(),
                              np.array([c for c, _ in self.boxes], float).reshape(-1, 3),
                              np.repeat(rot[None], len(self.boxes), axis=0),
                              np.array([h for _, h in self.boxes], float).reshape(-1, 3),
                              ("floor",) + tuple(f"box{i}" for i in range(len(self.boxes))))

    def levelling(self) -> CaptureFrame:
        """The rigid transform taking this floor to the plane z = 0 by the shortest rotation
        (`solver.capture_frame`); a level floor at 0 gives the identity."""
        return CaptureFrame.levelling(self.floor_z, self.floor_slope)

    def levelled(self) -> FittedScene:
        """This scene in its levelled frame (`levelling`): the floor level at z = 0, each box's centre
        moved by the transform, its half sizes kept (a box square to the floor becomes square to the
        world axes)."""
        t = self.levelling()
        return FittedScene(0.0, tuple((t.points(c), h.copy()) for c, h in self.boxes))


def _tilt_rotation(b: float, c: float) -> np.ndarray:
    """(3, 3) shortest rotation taking z to the unit normal of the plane z = b x + c y (Rodrigues)."""
    n = np.array([-b, -c, 1.0]) / np.sqrt(1.0 + b * b + c * c)
    k = np.array([[0.0, 0.0, n[0]], [0.0, 0.0, n[1]], [-n[0], -n[1], 0.0]])  # cross-product matrix of z x n
    return np.eye(3) + k + k @ k / (1.0 + n[2])


@dataclass(frozen=True)
class _Stance:
    rest: float          # [m]
    lo: np.ndarray       # (2,) footprint min x, y
    hi: np.ndarray       # (2,) footprint max x, y
    at: np.ndarray       # (2,) x, y of the rest: the resting (lowest) site's median position [m]


def _stances(times, site_pos, contacts, feet):
    sites = foot_sites(feet)
    mask = contact_mask(contacts, sites, times)
    out = []
    for st in foot_contacts(contacts, feet):
        rests, ats, pts = [], [], []
        for c in contacts:
            if c.site in feet[st.site] and c.start >= st.start - 1e-9 and c.end <= st.end + 1e-9:
                k = list(sites).index(c.site)
                rows = mask[:, k] & (times >= c.start - 1e-9) & (times <= c.end + 1e-9)
                if rows.any():
                    rests.append(float(np.median(site_pos[rows, k, 2])))
                    ats.append(np.median(site_pos[rows, k, :2], axis=0))
                    pts.append(site_pos[rows, k, :2])
        if rests:
            p = np.concatenate(pts)
            k = int(np.argmin(rests))
            out.append(_Stance(rests[k], p.min(axis=0), p.max(axis=0), ats[k]))
    return out


def _rect_gap(a: _Stance, b: _Stance) -> float:
    d = np.maximum(0.0, np.maximum(a.lo - b.hi, b.lo - a.hi))
    return float(np.linalg.norm(d))


def _plane(at: np.ndarray, rest: np.ndarray, min_span: float, scale: float) -> tuple[float, np.ndarray]:
    """Robust plane z = a + g . (x, y) through rest points (soft-L1 least squares, scale `scale` [m]).

    The slope is fitted only along the principal directions of the points' x, y in which they extend
    over at least `min_span` [m] (0 across a straight walk). Returns (a, g (2,))."""
    from scipy.optimize import least_squares

    mid = at.mean(axis=0)
    free = np.zeros((2, 0))
    if len(at) >= MIN_STANCES:
        _, _, vt = np.linalg.svd(at - mid, full_matrices=False)
        spans = np.ptp((at - mid) @ vt.T, axis=0)
        free = vt[spans >= min_span].T  # (2, f) directions with a slope
    d = (at - mid) @ free  # (m, f)

    def resid(p):
        return p[0] + d @ p[1:] - rest

    start = np.r_[np.median(rest), np.zeros(free.shape[1])]
    p = least_squares(resid, start, loss="soft_l1", f_scale=scale, xtol=1e-12, ftol=1e-12, gtol=1e-12).x
    g = free @ p[1:]
    return float(p[0] - mid @ g), g


def _fit_floor(stances, raised, min_span, level_tol, max_slope, scale):
    """The floor plane z = a + g . (x, y) through the floor stances: (a [m], g (2,) [m/m]) (module doc, step 2)."""
    rest = np.array([s.rest for s in stances])
    at = np.array([s.at for s in stances])
    on = rest <= rest.min() + raised
    for _ in range(10):  # the floor stances: within `raised` above the plane fitted to them
        a, g = _plane(at[on], rest[on], min_span, scale)
        if np.hypot(*g) > max_slope:
            a, g = _plane(at[on], rest[on], np.inf, scale)
        new = rest - (a + at @ g) <= raised
        if (new == on).all():
            break
        on = new | (rest == rest.min())
    across = float(np.ptp(at[on] @ g)) if on.any() else 0.0
    if across < level_tol:
        a, g = _plane(at[on], rest[on], np.inf, scale)
    return a, g


def _levels(rests: np.ndarray, tol: float) -> np.ndarray:
    """(m,) level label of each rest height [m]: sorted, a gap of more than `tol` starts a new level
    (1-D single linkage), labels counted from the lowest."""
    order = np.argsort(rests)
    label = np.empty(len(rests), int)
    label[order] = np.concatenate([[0], np.cumsum(np.diff(rests[order]) > tol)]) if len(rests) else []
    return label


def _cut(lo: np.ndarray, hi: np.ndarray, own: tuple, other: tuple, reach: float) -> None:
    """Pull the rectangle [lo, hi] (around the footprint `own` = (lo, hi)) back from the footprint
    `other` where it overlaps that footprint padded by `reach` [m]: on the axis along which the two
    footprints lie furthest apart, the facing side moves to halfway between them. Two boxes cut against
    each other stop at the same line. In place."""
    olo, ohi = other[0] - reach, other[1] + reach
    if np.any(lo > ohi) or np.any(hi < olo):
        return  # apart (a footprint on the edge counts as covered)
    olo, ohi = other
    flo, fhi = own
    gaps = np.concatenate([olo - fhi, flo - ohi])  # > 0: other beyond own on that side (+x, +y, -x, -y)
    k = int(np.argmax(gaps))
    if k < 2:
        hi[k] = min(hi[k], (fhi[k] + olo[k]) / 2)
    else:
        lo[k - 2] = max(lo[k - 2], (flo[k - 2] + ohi[k - 2]) / 2)


def _overlap(a: tuple, b: tuple) -> bool:
    """Whether the footprints a = (lo, hi) and b (x, y rectangles [m]) share a point (edges included)."""
    return bool(np.all(a[0] <= b[1]) and np.all(b[0] <= a[1]))


def _within(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(p,) bool: the points' x, y inside the rectangle [lo, hi]."""
    return ((points[:, :2] >= lo) & (points[:, :2] <= hi)).all(axis=1)


def _fit_boxes(stances, raised, height_tol, link, margin, passing):
    """Boxes (center, half) in the floor's frame (floor at z = 0) from the stances (module doc, 3-4);
    `passing` (p, 3): the contact sites at every frame, which no box may hold more than `raised` inside it.
    """
    low = [s for s in stances if s.rest <= raised]
    high = [s for s in stances if s.rest > raised]
    level = _levels(np.array([s.rest for s in high]), height_tol)
    label = list(range(len(high)))  # single-linkage clusters of the raised stances, within a level

    def root(i):
        while label[i] != i:
            i = label[i]
        return i

    for i in range(len(high)):
        for j in range(i + 1, len(high)):
            if level[i] == level[j] and _rect_gap(high[i], high[j]) <= link:
                label[root(j)] = root(i)
    clusters = [[high[i] for i in range(len(high)) if root(i) == r] for r in sorted({root(i) for i in range(len(high))})]
    prints = [(np.min([m.lo for m in c], axis=0), np.max([m.hi for m in c], axis=0)) for c in clusters]
    boxes = []
    for i, members in enumerate(clusters):
        if any(_overlap(prints[i], f) for f in [(s.lo, s.hi) for s in low] + prints[:i] + prints[i + 1:]):
            continue  # a foot rested at another height within the footprint: feet held still in the air (module doc, 4)
        top = float(np.mean([m.rest for m in members]))
        lo, hi = prints[i][0] - margin, prints[i][1] + margin
        # no surface covers where a foot rested at another height or on another prop: each side facing
        # such a footprint stops halfway to it (both boxes of a pair stop at the same line)
        for other, reach in [((s.lo, s.hi), 0.0) for s in low] + [(f, margin) for j, f in enumerate(prints) if j != i]:
            _cut(lo, hi, prints[i], other, reach)
        # nor where a foot passed more than `raised` below its top beside the rests (a swinging foot
        # under the padding): the side facing such a point stops halfway to it
        below = passing[passing[:, 2] < top - raised]
        for p in below[_within(below, lo, hi) & ~_within(below, *prints[i])]:
            _cut(lo, hi, prints[i], (p[:2], p[:2]), 0.0)
        center = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, top / 2])
        half = np.array([(hi[0] - lo[0]) / 2, (hi[1] - lo[1]) / 2, top / 2])
        boxes.append((center, half))
    return boxes


def fit_scene(
    times: np.ndarray,
    site_pos: np.ndarray,
    contacts: Sequence[Contact],
    feet: Mapping[str, Sequence[str]],
    raised: float = RAISED,
    height_tol: float = HEIGHT_TOL,
    link: float = LINK,
    margin: float = MARGIN,
    min_span: float = MIN_SPAN,
    level_tol: float = LEVEL_TOL,
    max_slope: float = MAX_SLOPE,
) -> FittedScene:
    """Floor plane and raised boxes from the contact-site positions during contacts (module doc).

    Args:
        times: (n,) [s]. site_pos: (n, s, 3) [m] site positions (world, z up). contacts: site
            contacts (e.g. `fit_contacts`, or hand-written). feet: {foot: its sites}, the figure's
            (`Figure.feet`); the s columns of `site_pos` are their sites, foot by foot.
        raised, height_tol, link, margin, min_span, level_tol: [m]; max_slope: [m/m]; see the
            module constants.
    Returns:
        FittedScene; boxes sorted by their center x.
    Raises:
        InputError: no contact at all (nothing to fit), or shapes disagree.
    """
    times, site_pos, sites = np.asarray(times, float), np.asarray(site_pos, float), foot_sites(feet)
    if site_pos.shape != (len(times), len(sites), 3):
        raise InputError(f"site_pos must have shape ({len(times)}, {len(sites)}, 3); got {site_pos.shape}")
    stances = _stances(times, site_pos, contacts, feet)
    if not stances:
        raise InputError("no contacts: a scene is fitted to where the feet rest, and they never do")
    a, g = _fit_floor(stances, raised, min_span, level_tol, max_slope, PLANE_SCALE)
    floor = FittedScene(a, (), (float(g[0]), float(g[1])))
    rot, origin = floor.rotation(), np.array([0.0, 0.0, a])
    in_floor = (site_pos - origin) @ rot  # the floor's frame: floor at z = 0
    local = _stances(times, in_floor, contacts, feet)
    boxes = [(origin + rot @ c, h) for c, h in _fit_boxes(local, raised, height_tol, link, margin,
                                                          in_floor.reshape(-1, 3))]
    boxes.sort(key=lambda b: b[0][0])
    return FittedScene(a, tuple(boxes), floor.floor_slope)


def fit_contacts(times: np.ndarray, site_pos: np.ndarray, feet: Mapping[str, Sequence[str]],
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
        times, site_pos, feet: as `fit_scene`. ballistic: [m/s^2] > 0.
        thresholds: of `detect_contacts`.
    """
    times, site_pos, sites = np.asarray(times, float), np.asarray(site_pos, float), foot_sites(feet)
    h = np.empty(site_pos.shape[:2])
    for members in feet.values():
        ks = [sites.index(s) for s in members]
        h[:, ks] = site_pos[:, ks, 2] - site_pos[:, ks, 2].min(axis=1, keepdims=True)
    # per site (feet=None): heights here are above the foot's lowest site, which is always at 0, so a
    # still site is a rest by itself; the lowest site's own speed says nothing about where it rests
    thresholds.setdefault("feet", None)
    found = detect_contacts(times, site_pos, h, sites, **thresholds)
    falling = []
    for c in found:
        rows = (times >= c.start - 1e-9) & (times <= c.end + 1e-9)
        if rows.sum() >= 3:
            t = times[rows] - times[rows].mean()
            if 2.0 * np.polyfit(t, site_pos[rows, sites.index(c.site), 2], 2)[0] < -ballistic:
                falling.append(c)
    # a foot whose one site falls is in the air: its other site's "rest" at the same time is no rest
    # either (its own motion can hide the fall: a push-off lifts the heel while the toe falls)
    foot = {s: f for f, members in feet.items() for s in members}
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
    <texture name="sky" type="skybox" builtin="gradient" rgb1="0.55 0.70 0.90" rgb2="0.10 0.15 0.25" width="512" height="512"/>
    <texture name="grid" type="2d" builtin="checker" rgb1="0.30 0.33 0.36" rgb2="0.22 0.25 0.28" mark="edge" markrgb="0.5 0.5 0.5" width="512" height="512"/>
    <material name="floor" texture="grid" texrepeat="1 1" texuniform="true" reflectance="0.1"/>
    <texture name="wood" type="cube" builtin="flat" rgb1="0.62 0.48 0.32" rgb2="0.55 0.40 0.25"
             mark="random" random="0.05" markrgb="0.45 0.33 0.20" width="256" height="256"/>
    <material name="step" texture="wood" rgba="1 1 1 1" specular="0.1"/>
  </asset>

  <worldbody>
    <light name="sun" mode="trackcom" pos="0 -2 6" dir="0.1 0.25 -1" directional="true" castshadow="true"
           diffuse="0.7 0.7 0.7" specular="0.2 0.2 0.2"/>
    <light name="fill" pos="4 4 4" dir="-1 -1 -1" directional="true" castshadow="false" diffuse="0.25 0.25 0.25"/>
    <geom name="floor" type="plane" pos="0 0 {floor_z:.6f}"{quat} size="0 0 0.05" material="floor"
          contype="1" conaffinity="1"/>
{boxes}    <camera name="side" mode="trackcom" pos="0 -5 1.2" xyaxes="1 0 0 0 0.25 1"/>
  </worldbody>
</mujoco>
"""


def scene_mjcf(fitted: FittedScene, figure_path: str | os.PathLike, relative_to: str | os.PathLike | None = None,
               model: str = "fitted_scene", capture: CaptureFrame | None = None) -> str:
    """MJCF text of the fitted scene: the figure included, a floor plane "floor", boxes "box0", ...

    Materials, lights and camera as models/run_and_step.xml. `capture` (the transform from the
    capture's coordinates to the scene's, `FittedScene.levelling`), when given, is recorded as the
    scene's `<custom><numeric name="capture:frame">` (`solver.capture_frame`). The include path is absolute unless
    `relative_to` (the directory the scene will be saved in) is given, then relative to it; either way
    the scene loads from where it is saved (MuJoCo resolves includes against the main file's folder).

    Args:
        fitted: the scene. figure_path: the figure's MJCF (models/humanoid39.xml).
        relative_to: optional folder of the saved scene. model: the model name. capture: see above.
    Raises:
        InputError: figure_path does not exist.
    """
    fig = Path(figure_path).resolve()
    if not fig.is_file():
        raise InputError(f"figure_path {str(figure_path)!r} is not a file; give e.g. models/humanoid39.xml")
    inc = os.path.relpath(fig, Path(relative_to).resolve()) if relative_to is not None else str(fig)
    quat = "" if fitted.level else ' quat="{:.9f} {:.9f} {:.9f} {:.9f}"'.format(*_quat(fitted.rotation()))
    boxes = "".join(
        f'    <geom name="box{i}" type="box" pos="{c[0]:.6f} {c[1]:.6f} {c[2]:.6f}"{quat} '
        f'size="{h[0]:.6f} {h[1]:.6f} {h[2]:.6f}" material="step" contype="1" conaffinity="1"/>\n'
        for i, (c, h) in enumerate(fitted.boxes)
    )
    text = _SCENE.format(model=model, figure=inc, floor_z=fitted.floor_z, quat=quat, boxes=boxes)
    return text if capture is None else text.replace("</mujoco>", capture.mjcf() + "</mujoco>")


def _quat(rot: np.ndarray) -> np.ndarray:
    """(4,) unit quaternion w x y z of a rotation matrix (MuJoCo's mju_mat2Quat)."""
    import mujoco

    q = np.empty(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(rot, float).ravel())
    return q
