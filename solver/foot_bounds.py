"""The bounds on the feet in contact: planted and slide (`solver.constraint_set` poses them with the rest).

    planted   over each foot contact, its support site's mean height              mean h <= FLOAT_LIMIT   2 mm
              with a capture, over each site contact, the site's mean height       mean h <= the known paths' own
    slide     over each site contact, the slide beyond what the keyframes force    <= allowance            2 mm

A foot contact is a foot's sites' contacts merged; at each point of one the support site is the foot's
site that the schedule has in contact there and the reference motion holds lowest: a walking foot
rolls from its heel onto its toe, and the toe carries it while the heel rises (the float metric of the
field is the foot's lowest point, ../shared/METRICS.md). Its planted pair holds that site down.

Where the keyframes came from a capture (and in a clean), each site the schedule has in contact also has a
planted pair of its own over its own contact: no higher above its surface on average than the known paths
through the keyframes hold it, the higher of the two: the reference motion (the plain spline, or a clean's
capture itself) and the capture (FLOAT_LIMIT where both hold it lower). Both meet the pair, so the keyframes
never force it. Without it the cheapest way down for a support site that rests too high is to pitch the foot
about the ankle: a light joint, little change, and the foot's other site, in contact by the schedule, rises
several times as far. The clean of 05_09 lowered its heels 3-4 mm by lifting both toes 2.4-4.6 cm off the
floor and a box for the whole clip; keyed every 0.25 s, 127_33 lifted a heel 5 cm above both paths over a
0.1 s contact. Against the plain spline alone, a keyed path whose capture holds a site higher between the
keys would be held nearer the floor than the motion it came from. Without a capture nothing witnesses where
a site other than the support rests (the plain spline only interpolates the keys), and the plain spline's
own heights as the limit doubled the solve of the shipped standing jump without converging it: a
keyframe-only problem keeps the foot's pair alone.

Planted and slide are integrals over a contact (its mean height, the distance it slides): a contact
detected on a capture begins and ends with the site still moving (entry below 0.5 m/s and 3 cm, exit above
1 m/s or 5 cm: solver.contacts), so a bound at every point would have the site held still to the contact's
end and then thrown off it. What the keyframes force, and how the limits follow from it, is in
`solver.constraint_set`'s docstring.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solver.constraints.sites import SupportHeight, SupportSlide, huber, site_heights
from solver.contacts import foot_contacts, site_positions

__all__ = ["CAPTURE_RESOLUTION", "CLEAN_SKATE", "FLOAT_LIMIT", "SLIDE_SHARE", "SLIDE_SMOOTHING", "Relaxation", "foot_bounds",
           "frame_weights", "full_keyframes"]

#: [1] the share of a known path's slide beyond what the keyframes force (the plain spline's, the capture's)
#: that the path may keep: half, the product's skate requirement (docs/corpus.md, `skate_excess`)
SLIDE_SHARE = 0.5
#: [m] a planted foot's mean height over its contact: 2 mm (with the 2 mm tolerance, under the 5 mm float
#: of PhysDiff's metric, ../shared/METRICS.md; a sole resting on a floor sits about that high in a capture)
FLOAT_LIMIT = 2e-3
#: [m/s] the width of the Huber function that smooths a sliding speed at 0 (`SupportSlide`): 1 cm/s,
#: where a site's slide is within the capture's marker noise (about 1 mm per frame at 120 fps)
SLIDE_SMOOTHING = 1e-2
#: [m/frame] a clean's skate in contact, mean over its contacts' frames (docs/corpus.md "Cleaning the corpus"), what
#: its slides are measured to (`figure_constraints`' `frames`): the Huber width at most this a frame (the keyed
#: 1 cm/s where narrower, at 50 fps and above) and each contact's tolerance half of it a frame step (the keyed
#: 2 mm where less). By Jensen's inequality a slide met within that tolerance moves on average at most
#: huber_b^-1(tol / T) a frame, tol / T + b / 2 = this with both at their largest: within the bound at any
#: frame rate, as the planted limit and its tolerance are within the float bound (the keyed 2 mm over a
#: 3-frame contact at 30 fps is 0.55 mm a frame)
CLEAN_SKATE = 2e-4
#: [m] a capture file's position resolution (0.01 cm): the width that smooths a clean's planted heights'
#: positive part (`SupportHeight`'s `above`: within half of it of max(0, h))
CAPTURE_RESOLUTION = 1e-4


@dataclass(frozen=True)
class Relaxation:
    """Where the keyframes decide a constraint (`solver.constraint_set`'s docstring).

    Attributes:
        constraint: its name. label: the site or joint. keyframe: index of the keyframe (-1: several).
        start, end: [s] the span relaxed. amount: [SI] the largest amount the limit was raised by.
    """
    constraint: str
    label: str
    keyframe: int
    start: float
    end: float
    amount: float


def frame_weights(t: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """(q,) [s] quadrature weights at the points `t` (q,) that sum over the capture `frames` (n,) [s], n >= 2:
    the frame step at the point of each frame, 0 elsewhere (a mean over a contact is then its frames' own
    mean, as the float figure takes it: ../shared/METRICS.md).

    Raises:
        ValueError: a frame more than a microsecond from every point (a clean's frames are its points:
            `solver.quadrature.simpson_points`).
    """
    t, frames = np.asarray(t, float), np.asarray(frames, float)
    i = np.clip(np.searchsorted(t, frames), 1, len(t) - 1)
    i = np.where(np.abs(t[i - 1] - frames) < np.abs(t[i] - frames), i - 1, i)
    if np.any(np.abs(t[i] - frames) > 1e-6):  # [s] a microsecond: the points are sums of float steps
        raise ValueError("a capture frame is not a quadrature point")
    w = np.zeros(len(t))
    w[i] = float(np.median(np.diff(frames)))
    return w


def _pairs_in(t: np.ndarray, a: float, b: float) -> np.ndarray:
    """Indices of quadrature points in the closed interval [a, b]."""
    return np.flatnonzero((t >= a) & (t <= b))


def full_keyframes(plain):
    """(indices, times, values) of the keyframes that fix every component (they pin every site)."""
    full = np.flatnonzero(plain.is_keyframe & plain.fixed.all(axis=1))
    return full, plain.times[full], plain.values[full]


def _run_around(values: np.ndarray, j: int) -> slice:
    """The run of consecutive positive entries of `values` around index j (empty if values[j] <= 0)."""
    if values[j] <= 0:
        return slice(j, j)
    lo, hi = j, j
    while lo > 0 and values[lo - 1] > 0:
        lo -= 1
    while hi < len(values) - 1 and values[hi + 1] > 0:
        hi += 1
    return slice(lo, hi + 1)


def foot_bounds(model, figure, reference, plain, contacts, state, support, radii, witness, tolerances: dict,
                planted_tolerance: float, frames=None) -> tuple | None:
    """The planted and slide constraints of the feet in contact (module docstring), or None without a contact.

    Args:
        model: MjModel of the scene. figure: `solver.figure.Figure`. reference: `ReferenceMotion` (the points).
        plain: the plain spline's FrameSet. contacts: `solver.contacts.Contact`s. state: the reference's
            PathState at the points. support: SupportSurfaces. radii: (k,) [m] the contact sites'. witness: the
            capture's PathState, or None. tolerances: {"slide": [m], ...} (`solver.constraint_set.TOLERANCES`).
        planted_tolerance: [m] the planted pairs'. frames: (n,) [s] a clean's capture frames, or None
            (`solver.constraint_set.figure_constraints`).
    Returns:
        (SupportHeight "planted", SupportSlide "slide"), their relaxations in the first's `reports`; or None.
    """
    feet = _foot_support(model, figure, reference, plain, contacts, state, support, radii, witness, planted_tolerance,
                         frames)
    if feet is None:
        return None
    args, limit_h, reports = feet
    own = 0
    if witness is not None:  # a capture witnesses where each site rests in contact (module docstring)
        args, own = _with_site_pairs(args, reference, contacts, figure.contact_sites, support, frames)
    height = SupportHeight(*args, limit=np.r_[limit_h, np.zeros(own)], tolerance=planted_tolerance,
                           above=0.0 if frames is None else CAPTURE_RESOLUTION)
    if own:  # each site in contact no higher than the known paths hold it, the higher of the two
        height.limit[-own:] = np.maximum(FLOAT_LIMIT, np.maximum(height.measure(state), height.measure(witness))[-own:])
    rate = None if frames is None else 1.0 / float(np.median(np.diff(frames)))
    slide, slide_reports = _site_slides(model, reference, plain, contacts, support, radii, tuple(figure.contact_sites),
                                        state, tolerances["slide"], witness, rate)
    height.reports = reports + slide_reports
    return height, slide


def _with_site_pairs(args, reference, contacts, sites, support, frames):
    """The foot support's args (`_FootSupport`) with a pair per site contact appended (`_site_contact_pairs`, its
    points as the foot pairs': the capture's frames in a clean): (args, how many appended)."""
    w = reference.weights if frames is None else frame_weights(reference.t, frames)
    sup, radii, *cols = args
    kept, own = _site_contact_pairs(contacts, sites, support, reference.t, w, frames is not None, first=len(cols[5]))
    if not kept:
        return args, 0
    return (sup, radii, *(np.concatenate([a, b]) for a, b in zip(cols, own))), len(kept)


def _site_contact_pairs(contacts, sites, support, t: np.ndarray, w: np.ndarray, frames_only: bool, first: int = 0):
    """A pair per site contact over its quadrature points (with `frames_only`, those of weight w > 0: the capture's
    frames), at its own site and surface, numbered from `first`: (the contacts that have points, the
    `_FootSupport` arrays points, cols, surfaces, pair, w, span, rows, labels, or None without a pair)."""
    kept, parts = [], [[] for _ in range(8)]
    for c in contacts:
        on = _pairs_in(t, c.start, c.end)
        on = on[w[on] > 0] if frames_only else on
        if not on.size:
            continue
        k, si = first + len(kept), -1 if not c.surface else support.index(c.surface)
        kept.append(c)
        for lst, val in zip(parts, (on, np.full(len(on), sites.index(c.site)), np.full(len(on), si), np.full(len(on), k),
                                    w[on], [float(w[on].sum())], [int(on[len(on) // 2])], np.array([c.site], object))):
            lst.append(np.asarray(val))
    return kept, (tuple(np.concatenate(p) for p in parts) if kept else None)


def _site_slides(model, reference, plain, contacts, support, radii, sites, state, tolerance: float, witness=None,
                 frame_rate=None):
    """The slide constraint (`SupportSlide`), a pair per site contact (the site's own contact), its limit the
    slide the keyframes force in its own measure (Jensen's inequality: module docstring) plus an allowance:
    SLIDE_SHARE of what the plain spline (`state`, the reference) or the `witness` slides beyond that,
    whichever is less; and the relaxations worth reporting (the keyframes force more than the `tolerance` [m]).
    With a `frame_rate` [Hz] (a clean) the Huber width and each pair's tolerance are per frame (`CLEAN_SKATE`)."""
    b = SLIDE_SMOOTHING if frame_rate is None else min(SLIDE_SMOOTHING, CLEAN_SKATE * float(frame_rate))
    index, times, values = full_keyframes(plain)
    keyed_xy = site_positions(model, values, sites)[..., :2] if len(times) else np.zeros((0, len(sites), 2))
    kept, arrays = _site_contact_pairs(contacts, sites, support, reference.t, reference.weights, False)
    keyed, reports = [], []
    for c in kept:
        col = sites.index(c.site)
        inside = np.flatnonzero((times >= c.start - 1e-6) & (times <= c.end + 1e-6))
        d = np.linalg.norm(np.diff(keyed_xy[inside, col], axis=0), axis=-1)  # [m] between consecutive keys
        dt = np.diff(times[inside])
        forced = float(dt @ huber(d / dt, b)) if len(d) else 0.0  # Jensen: the slide's own measure
        keyed.append(forced)
        if forced > tolerance:  # worth saying: the keyframes force more than the tolerance
            reports.append(Relaxation("slide", c.site, int(index[inside[-1]]), float(times[inside[0]]),
                                      float(times[inside[-1]]), forced))
    forced, span = np.array(keyed), arrays[5]
    tol = (tolerance if frame_rate is None  # a clean: half CLEAN_SKATE a frame step
           else np.minimum(tolerance, 0.5 * CLEAN_SKATE * float(frame_rate) * span))
    slide = SupportSlide(support, radii, *arrays, limit=forced, tolerance=tol, width=b, forced=forced)
    allowance = np.full(len(forced), np.inf)
    for path in (state, witness):  # a known path through the keyframes: the path halves its excess
        if path is not None:
            allowance = np.minimum(allowance, SLIDE_SHARE * np.maximum(0.0, slide.measure(path) - forced))
    slide.limit = forced + allowance
    return slide, reports


def _foot_support(model, figure, reference, plain, contacts, state, support, radii, witness, tolerance: float,
                  frames=None):
    """The foot contacts' support points (`solver.constraints.sites._FootSupport`) and their limits
    relaxed where the keyframes force (module docstring), or None without contacts. Where a keyframe holds
    a foot up, the limit is what a known path through the keyframes does over the contact: `witness` (the
    capture they came from, a PathState at the quadrature points), else the plain spline (`state`).
    `tolerance` [m]: the planted limits'. `frames` (n,) [s]: the means are over these frames (`frame_weights`);
    None: the midpoint rule's.

    Returns:
        (args of `_FootSupport`, planted limits (p,) [m], relaxation reports).
    """
    sites = tuple(figure.contact_sites)
    t = reference.t
    w = reference.weights if frames is None else frame_weights(t, frames)
    index, times, values = full_keyframes(plain)
    keyed_pts = site_positions(model, values, sites) if len(times) else np.zeros((0, len(sites), 3))
    keyed_low = keyed_pts.copy()
    keyed_low[..., 2] -= radii  # the contact points (lowest points of the sites' spheres)
    args = tuple([] for _ in range(8))
    limits_h, reports = [], []
    feet = {s: name for name, pair in figure.feet.items() for s in pair}
    for F in foot_contacts(list(contacts), dict(figure.feet)):
        mine = [c for c in contacts if feet.get(c.site) == F.site and c.end >= F.start and c.start <= F.end]
        on = _pairs_in(t, F.start, F.end)
        if frames is not None:
            on = on[w[on] > 0]  # the contact's frames: the points of the mean
        if not on.size:
            continue
        cand = np.full((len(on), len(sites)), np.inf)  # reference height of each site in contact there
        surf = np.full((len(on), len(sites)), -1, int)
        for c in mine:
            col = sites.index(c.site)
            inside = (t[on] >= c.start) & (t[on] <= c.end)
            si = -1 if not c.surface else support.index(c.surface)
            h, _ = site_heights(state, support, radii, on[inside], np.full(inside.sum(), col),
                                np.full(inside.sum(), si), None)
            better = h < cand[inside, col]
            cand[np.flatnonzero(inside)[better], col] = h[better]
            surf[np.flatnonzero(inside)[better], col] = si
        cols = np.argmin(cand, axis=1)
        ok = np.isfinite(cand[np.arange(len(on)), cols])
        on, cols = on[ok], cols[ok]
        if not on.size:
            continue
        surfaces = surf[np.flatnonzero(ok), cols]
        href = cand[np.flatnonzero(ok), cols]
        if witness is not None:
            href = site_heights(witness, support, radii, on, cols, surfaces, None)[0]
        p, held_up = len(limits_h), len(reports)
        span = float(w[on].sum())
        for j, (k, tk) in enumerate(zip(index, times)):  # keyframes inside the foot contact
            if not (F.start - 1e-6 <= tk <= F.end + 1e-6):
                continue
            i = int(np.argmin(np.abs(t[on] - tk)))
            keyed, _ = support.height(keyed_low[j, cols[i]][None], None if surfaces[i] < 0 else int(surfaces[i]))
            if keyed[0] - FLOAT_LIMIT <= tolerance:
                continue  # the keyframe meets the bound
            run = _run_around(href - FLOAT_LIMIT, i)
            run = run if run.stop > run.start else slice(i, i + 1)
            reports.append(Relaxation("planted", F.site, int(k), float(t[on[run.start]]), float(t[on[run.stop - 1]]),
                                      float(keyed[0])))
        limit_h = FLOAT_LIMIT
        if len(reports) > held_up:  # a keyframe holds the foot up: met where it floats no more than the witness
            limit_h = max(FLOAT_LIMIT, float(w[on] @ href) / span - tolerance)
        for lst, val in zip(args, (on, cols, surfaces, np.full(len(on), p), w[on], [span], [int(on[len(on) // 2])], [F.site])):
            lst.append(np.asarray(val))
        limits_h.append(limit_h)
    if not limits_h:
        return None
    support_args = (support, radii, *(np.concatenate(a) for a in args))
    return support_args, np.array(limits_h), reports
