"""The figure's constraints for one problem, each a function with its unit and tolerance (docs/design.md).

    penetration  every contact site's lowest point outside every plane and box, at every instant  d >= 0     0.9 mm (below)
    sole         in a clean, the soles' edges likewise, no deeper than the capture holds them  -d <= capture's  0.9 mm
    planted      over each foot contact, the support site's mean height                 mean h <= FLOAT_LIMIT 2 mm
                 with a capture, over each site contact, that site's (solver.foot_bounds) <= the known paths'
    slide        over each site contact, the slide beyond what the keyframes force    <= allowance (below)  2 mm
    flight       in a flight, every site clear (the field's flight height)             h >= 3.1 cm      1 mm
    ground       outside flights, the site the reference holds lowest is down          h <= 2.9 cm      1 mm
                 (with a capture, neither between the two frames about a flight's end: below)
    hinge        knees and elbows turn about their flexion axis                         phi <= limit     1 deg
    hyperextension  knees and elbows do not bend backwards                               -theta <= limit  0.4 deg (below)
    rom          every joint motion inside its published range (AAOS 1965)              lo <= x <= hi    1 deg
    acceleration no jolts: pelvis and ball joints no harder than the capture's (6 Hz) or the plain spline's peak  5 %
    effort       with a capture: RMS joint torque no more than the capture's (6 Hz) or the plain spline's     5 %
    tracking     with a capture: the contact sites' mean distance from the capture's, the plain spline's at most  5 %
    unit         quaternions near unit norm between the frames                          ||q| - 1| <= 0.03  0.01

With `--terms all` the force bounds join them (`solver.constraints.forces`, added by
`solver.least_change.build_least_change`): no external wrench in flight, the friction cone and the peak
ground force on the ground.

A capture's flights are found on its frames (`solver.contacts.airborne_intervals`): a flight starts midway
between the last frame with a site down and the first with every site up (and ends likewise). Between those
two frames the capture does not say when the foot crossed the flight height, so neither flight nor ground
is posed between them: a bound there asks for a crossing time no data gave, and beside a keyframe only the
velocity at the key could meet it. The two frames themselves are quadrature points (`flight_edge_frames`),
where ground and flight hold as the capture observed them.

The feet's bounds in contact, planted and slide, are `solver.foot_bounds`'s.

What the keyframes force. Keyframes are met exactly, so a constraint a keyframe breaks cannot be met
there; the problem is made well posed instead of excused:

* Where a full keyframe breaks a height bound (a keyed toe below the floor, a keyed heel 2 cm up on
  its support), the plain spline through the keyframes breaks it on an interval around the keyframe
  (its excursion: the quadrature points of that site around the keyframe where it breaks it). There the
  limit becomes the plain spline's own value, but no more than the keyframe's own (a path through the
  keyframe can leave it at the keyed value; the plain spline often dips deeper beside it): the path may
  do better, never worse than the keyframe forces. Where a keyframe holds a foot up inside a contact, the planted limit (a mean over
  the contact) becomes the mean height of a known path through the keyframes over the contact: the
  capture they came from, else the plain spline (its witness: a path that meets it).
* Two full keyframes dt apart in one foot contact that hold its support site a distance d apart along
  the surface make it slide at least d between them (the triangle inequality; the skate the keyframes
  force, `runner.motion_metrics.forced_skate_mm`, is that bound). The slide constraint measures the
  integral of huber_b(|v|) (`SupportSlide`), convex and nondecreasing in the speed, so in its own measure
  the keyframes force at least dt huber_b(d / dt) (Jensen's inequality; a constant speed meets it). The
  slide limit is the sum of those plus an allowance: SLIDE_SHARE (half) of what a known path through the
  keyframes slides beyond that sum, the plain spline or, when the keyframes came from one, the capture,
  whichever slides less: the path halves the slide the keyframes leave to it (the product's skate
  requirement). No fixed distance caps it: a capture's feet leave the ground moving (a contact ends at
  1 m/s or 5 cm), and a cap of 1 cm, under the 4-5 cm a capture's toe moves as it lifts off, held the toe
  still to the contact's end and flung it off at twice the capture's speed. The distance d itself is no bound on
  the measure, which is below it at speeds under b: a standing clip's keys, a capture's marker noise
  apart, summed 1.8-2.9 mm of "forced" slide, and a solve used it as a slow drift.
* The anatomical limits are widened (docs/anatomy.md): off the hinge to a known path through the keyframes
  (the capture, not the plain spline's overshoot between keys, else the plain spline); the others to the
  reference's own worst.
* No jolts is a bound only with a capture (keyframes made from motion capture): then A is the larger of
  the capture's filtered peak and the plain spline's (`solver.capture_bounds`). The plain spline's peak
  alone is no bound: sparse keyframes give a spline smoother than any motion that meets its contacts
  (run-and-step without its capture cannot land on the step within it), and the measure of change
  already prices every change of acceleration.
* The effort bound (`solver.constraints.effort`) is, for the same reason, a bound only with a capture: the
  larger of the capture's filtered RMS joint torque and the plain spline's. It needs the inverse
  dynamics (`solver.inverse_dynamics.InverseDynamics`), which a capture's problem then uses as its engine.
* The tracking bound (`solver.constraints.tracking`) is a bound only with a capture, and only on a keyed
  path: the contact sites no further from the capture's on average than the plain spline's. The contact
  constraints move the feet, and the measure of change prices a change against the plain spline, not
  against where the capture stood.

Penetration's tolerance is its 1 mm bound less a capture's 0.1 mm position resolution
(`PENETRATION_TOLERANCE`), so that a path met within it is inside the bound as measured at 1000 Hz: the
constraint takes each site's height between two quadrature points as a cubic, whose deepest point differs from
the path's by micrometres, and paths the solve left at the edge of a 1 mm tolerance measured 0.989-1.0008 mm.
Hyperextension's is likewise its 0.5 degree bound less a capture's 0.1 degree rotation resolution
(`HYPEREXTENSION_TOLERANCE`): the constraint holds at the quadrature points and the bound is measured at 1000 Hz,
where a keyed walk the solve left at the edge of a 0.5 degree tolerance measured 0.0007 degree beyond it.

Each relaxation is reported (`solver.foot_bounds.Relaxation`: which constraint, site or joint, keyframe, where, how much),
so a user sees where the keyframes, not the optimizer, decide.
"""
from __future__ import annotations

import numpy as np

from solver.capture_bounds import capture_accelerations, capture_effort, capture_state, filtered_capture, reference_state
from solver.constraints.anatomy import anatomy_constraints
from solver.constraints.penetration import Penetration, SoleEdges
from solver.constraints.sites import HeightBound, SupportHeight, site_heights
from solver.constraints.tracking import SiteTracking, mean_site_distance
from solver.constraints.unit import UnitNorm
from solver.contact_thresholds import FLIGHT_HEIGHT
from solver.contacts import contact_radii, site_positions
from solver.foot_bounds import CAPTURE_RESOLUTION, Relaxation, foot_bounds, full_keyframes
from solver.layout import StateLayout
from solver.path_state import PathState
from solver.support import SupportSurfaces
from solver.surfaces import StaticSurfaces

__all__ = ["ANGLE_RESOLUTION", "HYPEREXTENSION_TOLERANCE", "PENETRATION_TOLERANCE", "TOLERANCES", "figure_constraints", "flight_edge_frames"]

#: each constraint's tolerance [SI]: a pair is met when c <= tolerance (the acceptance bounds' units:
#: penetration 1 mm; float 2 mm, under the 5 mm of PhysDiff's float; slide 2 mm; flight 1 mm above the
#: field's 3 cm flight height; angles 1 deg, hyperextension 0.5 deg as the acceptance list; unit norm 0.01,
#: a third of its limit)
TOLERANCES = {"penetration": 1e-3, "planted": 2e-3, "slide": 2e-3, "flight": 1e-3,
              "hinge": float(np.radians(1.0)), "hyperextension": float(np.radians(0.5)), "rom": float(np.radians(1.0)), "unit": 0.01}

#: [m] the penetration constraint's tolerance: its 1 mm bound (TOLERANCES) less a capture's position resolution
#: (`solver.foot_bounds.CAPTURE_RESOLUTION`, 0.1 mm), the margin for the cubic between quadrature points (module docstring)
PENETRATION_TOLERANCE = TOLERANCES["penetration"] - CAPTURE_RESOLUTION
#: [rad] a capture's rotation resolution, as the corpus bounds take a BVH's (runner.corpus_bounds.PLAIN_FLOORS,
#: 0.1 deg); with `solver.foot_bounds.CAPTURE_RESOLUTION` for positions, the floor of a still joint's no-jolt limit
ANGLE_RESOLUTION = float(np.radians(0.1))
#: [rad] the hyperextension constraint's tolerance: its 0.5 deg bound (TOLERANCES) less `ANGLE_RESOLUTION`, the
#: margin for the path between quadrature points, where the bound is measured at 1000 Hz (module docstring)
HYPEREXTENSION_TOLERANCE = TOLERANCES["hyperextension"] - ANGLE_RESOLUTION


def figure_constraints(model, figure, reference, plain, contacts=(), flights=(), engine=None, capture=None,
                       planted_tolerance: float = TOLERANCES["planted"], track: bool = False,
                       frames: np.ndarray | None = None, no_jolt=None):
    """The constraints of a figure's problem (module docstring).

    Args:
        model: MjModel of the scene. figure: its `solver.figure.Figure`. reference: `ReferenceMotion` (the
            quadrature points). plain: the plain spline's FrameSet (keyframes: the full ones pin sites).
        contacts: `solver.contacts.Contact`s. flights: ((start, end), ...) [s]. engine: the contact
            sites' `SiteKinematics` (figure.contact_sites, in that order; a clean's, `figure.surface_sites`: the
            soles' edges follow them and are held by the sole constraint). planted_tolerance: [m] the planted
            limits' tolerance, also where a keyframe that holds a foot up relaxes them (a clean's is 0.9 mm:
            `solver.displacement`). track: a keyed path: with a capture, hold the contact sites as near it
            as the plain spline keeps them (`solver.constraints.tracking`; not a clean, whose plain spline is
            the capture). frames: (n,) [s] a clean's capture frame times, each a quadrature point: a clean is
            written and judged at its frames, so its planted means are of the heights' positive part over a
            contact's frames (`solver.foot_bounds.frame_weights`, to `CAPTURE_RESOLUTION`), its slides per frame (`CLEAN_SKATE`);
            None: a keyed path's (signed heights by the midpoint rule; `SLIDE_SMOOTHING`, 2 mm a contact).
            no_jolt: with a capture, the no-jolt bound (a `Constraint`) in place of `capture_accelerations`'s
            (a clean's bounds the change's accelerations, `solver.displacement.ChangeAcceleration`).
    Returns:
        (constraints, relaxations): a list of `Constraint`s and a list of `Relaxation`s.
    """
    t = reference.t
    sites = tuple(figure.contact_sites)
    surfaces = StaticSurfaces.from_model(model)
    support = SupportSurfaces(surfaces, rounded_edges=True)
    radii = contact_radii(model, sites)
    out = []
    state = None if engine is None else reference_state(model, reference, plain, engine)  # the plain spline's
    if engine is not None and surfaces.count:
        out.append(Penetration(surfaces, radii, t, sites, PENETRATION_TOLERANCE))
        witness = None if capture is None else capture_state(model, reference, capture, engine)
        if frames is not None and figure.sole_sites and witness is not None:  # a clean's engine: contact sites, soles' edges
            out.append(SoleEdges(surfaces, t, figure.sole_sites, PENETRATION_TOLERANCE,
                                 len(sites) + np.arange(len(figure.sole_sites)), witness))
        feet = foot_bounds(model, figure, reference, plain, contacts, state, support, radii, witness, TOLERANCES,
                           planted_tolerance, frames)
        out += list(feet or ())
        if track and witness is not None:
            out += _tracking(reference, state, witness)
        if len(contacts) or len(flights):  # nothing known of the contacts: no ground or flight height to hold
            out += _flight_and_ground(model, reference, plain, engine, support, radii, flights, sites, t, capture)
    layout = StateLayout.from_model(model)
    out += anatomy_constraints(figure, layout, reference, plain, capture, TOLERANCES | {"hyperextension": HYPEREXTENSION_TOLERANCE})
    quats = [j for j in layout.joints if j.quat_index is not None]
    out.append(UnitNorm(len(t), np.array([j.quat_index for j in quats]), [j.name for j in quats], TOLERANCES["unit"]))
    if capture is not None:  # no jolts: bounded by what the captured motion does (module docstring)
        filtered = filtered_capture(model, reference, capture)
        out.append(capture_accelerations(model, reference, filtered) if no_jolt is None else no_jolt)
        if engine is not None and getattr(engine, "forces", False):
            out += capture_effort(model, reference, plain, filtered, engine)
    relaxations = []
    if engine is not None:
        relaxations = _relax_heights(out, state, plain, model)
        relaxations += [r for c in out if isinstance(c, SupportHeight) for r in c.reports]
    return out, relaxations


def _tracking(reference, plain: PathState, capture: PathState) -> list:
    """[the tracking bound] (`solver.constraints.tracking`): the contact sites of the capture (`capture`, the
    witness) as the target and the plain spline's (`plain`) mean distance from them as the bound; [] where the
    plain spline is on the capture at every point (nothing to keep it nearer)."""
    bound = mean_site_distance(plain.sites, capture.sites, reference.weights)
    return [SiteTracking(reference.weights, capture.sites, bound)] if bound > 0 else []


def _relax_heights(constraints, state, plain, model) -> list[Relaxation]:
    """Raise the pointwise limits (penetration, flight, ground) a full keyframe breaks by more than the
    tolerance to the plain spline's own values on its excursion, at most the keyframe's own (module
    docstring); the reports. The
    keyframe's value is the plain spline's at the pair nearest it (`Penetration`'s pairs stand for the
    intervals between quadrature points, at their midpoints); every time series of the
    same site (and surface) is relaxed on its own run of broken pairs around the keyframe."""
    index, times, values = full_keyframes(plain)
    t = state.t
    half = 0.5 * float(np.max(np.diff(t))) + 1e-9  # [s] half the quadrature spacing (+ round-off)
    out = []
    for c in constraints:
        if c.name not in ("penetration", "flight", "ground"):
            continue
        v = c.values(state)
        ptimes = c.pair_times(t) if hasattr(c, "pair_times") else t[c.rows]
        groups = getattr(c, "group", c.series)
        # penetration at the keyframes themselves (a `Penetration` pair stands for an interval, not a point)
        depth = _keyed_depths(model, values, c) if isinstance(c, Penetration) else None  # (k, K, S)
        for g in np.unique(groups):
            in_g = np.flatnonzero(groups == g)
            for j, (k, tk) in enumerate(zip(index, times)):
                near = in_g[int(np.argmin(np.abs(ptimes[in_g] - tk)))]
                at_key = v[near] if depth is None else depth[j].ravel()[g] - c.limit[near]
                if abs(ptimes[near] - tk) > half or at_key <= c.tolerance:
                    continue  # no pair at the keyframe, or the keyframe meets the bound
                amount = float(at_key)
                spans = [_relax_run(c, v, ptimes, in_g[c.series[in_g] == key], tk, amount)
                         for key in np.unique(c.series[in_g])]
                spans = [sp for sp in spans if sp is not None]
                out.append(Relaxation(c.name, str(c.labels[near]), int(k), min(a for a, _ in spans),
                                      max(b for _, b in spans), amount))
    return out


def _keyed_depths(model, values: np.ndarray, c: Penetration) -> np.ndarray:
    """(k, K, S) [m] the depth of each of a `Penetration`'s K sites' contact points (the sites less their radii, as it
    samples them) in each of its S surfaces at the full keyframes' poses `values` (k, nq)."""
    keyed = site_positions(model, values, c.sites) if len(values) else np.zeros((0, len(c.sites), 3))
    keyed[..., 2] -= c.radii
    return -c.surfaces.signed_distances(keyed)[0]


def _relax_run(c, v: np.ndarray, ptimes: np.ndarray, pairs: np.ndarray, tk: float, forced: float):
    """Raise the limit of one time series' run of broken pairs around time tk by the values there, at most
    `forced` [SI] (what the keyframe itself breaks the bound by: a path through it need break it by no more
    around it, leaving it at the keyed value; v set to 0 on the run); returns the run's (start, end) [s],
    or None when the pair nearest tk is not broken."""
    pairs = pairs[np.argsort(c.rows[pairs], kind="stable")]
    rows, tp = c.rows[pairs], ptimes[pairs]
    i = int(np.argmin(np.abs(tp - tk)))
    if v[pairs[i]] <= 0:
        return None
    lo = hi = i
    while lo > 0 and rows[lo - 1] == rows[lo] - 1 and v[pairs[lo - 1]] > 0:
        lo -= 1
    while hi < len(rows) - 1 and rows[hi + 1] == rows[hi] + 1 and v[pairs[hi + 1]] > 0:
        hi += 1
    at = pairs[lo:hi + 1]
    c.limit[at] = c.limit[at] + np.minimum(v[at], forced)
    v[at] = 0.0
    return float(tp[lo]), float(tp[hi])


def _half_frame(frame_times) -> float:
    """[s] half the median interval of a capture's frames: how far from a flight's end (midway between two
    frames, `solver.contacts.airborne_intervals`) the capture leaves the crossing of the flight height unknown."""
    return 0.5 * float(np.median(np.diff(np.asarray(frame_times, float))))


def flight_edge_frames(flights, frame_times, keytimes=()) -> np.ndarray:
    """The capture's frames either side of each flight's start and end, where the ground and the flight
    bounds resume (module docstring): a -+ h and b -+ h for each flight (a, b), h half the median frame
    interval (`solver.contacts.airborne_intervals` puts a flight's ends midway between frames), each once
    (a one-frame flight's a + h and b - h are one frame) and none within a microsecond of a `keytimes` entry.
    A problem makes them quadrature points, so the bounds hold at the frames the capture observed.

    Args:
        flights: ((start, end), ...) [s]. frame_times: (n,) the capture's increasing frame times [s], n >= 2.
        keytimes: (k,) [s] times that are points already (the keyframes).
    Returns:
        (m,) increasing times [s], m <= 4 len(flights).
    """
    near = 1e-6  # [s] a microsecond: a key time's resolution (the keyframe file's 6 digits), far below any frame interval
    h = _half_frame(frame_times)
    edges = np.sort([x for a, b in flights for x in (a - h, a + h, b - h, b + h)])
    edges = edges[np.r_[True, np.diff(edges) >= near]] if edges.size else edges
    keys = np.asarray(keytimes, float).ravel()
    if keys.size and edges.size:
        edges = edges[np.abs(edges[:, None] - keys[None, :]).min(axis=1) >= near]
    return edges


def _flight_and_ground(model, reference, plain, engine, support, radii, flights, sites, t, capture=None) -> list:
    """flight: every site at least FLIGHT_HEIGHT + tol up in the flights; ground: elsewhere, the site the
    reference holds lowest at most FLIGHT_HEIGHT - tol up; with a `capture` (times, qpos), neither at points
    within half its median frame interval of a flight's start or end (module docstring)."""
    n, K = len(t), len(sites)
    flying, edge = np.zeros(n, bool), np.zeros(n, bool)
    half = 0.0 if capture is None else _half_frame(capture[0]) - 1e-9  # [s] (less round-off: the frames are points)
    for a, b in flights:
        flying |= (t > a) & (t < b)
        edge |= (np.abs(t - a) < half) | (np.abs(t - b) < half)
    flying &= ~edge
    out = []
    tol = TOLERANCES["flight"]
    if flying.any():
        on = np.flatnonzero(flying)
        rows, cols = np.repeat(on, K), np.tile(np.arange(K), len(on))
        out.append(HeightBound("flight", support, radii, rows, cols, -np.ones(len(rows), int),
                               np.full(len(rows), FLIGHT_HEIGHT + tol), False, tol, np.array(sites, object)[cols]))
    on = np.flatnonzero(~flying & ~edge)
    if on.size:
        state = reference_state(model, reference, plain, engine) if capture is None else capture_state(model, reference, capture, engine)
        h, _ = site_heights(state, support, radii, np.repeat(on, K), np.tile(np.arange(K), len(on)),
                            -np.ones(len(on) * K, int))
        cols = np.argmin(h.reshape(len(on), K), axis=1)
        out.append(HeightBound("ground", support, radii, on, cols, -np.ones(len(on), int),
                               np.full(len(on), FLIGHT_HEIGHT - tol), True, tol, np.array(sites, object)[cols]))
    return out
