"""Swing feet that clear the ground: the clearance term of a contact schedule (docs/contacts.md "The contact
terms").

`Clearance` (name "clearance", m^2): a site that is not in contact keeps a clearance c (default 2 cm)
from every surface in the middle of its swing, and every site keeps c_f in the middle of a flight,

    f(t) = sum over sites k of  u_k(t) max(0, c - h_k(t))^2 + u_f(t) max(0, c_f - h_k(t))^2,
    h_k = height of site k above the surface under it (a box's top face over its footprint, else the
          floor; `SupportSurfaces` with no footprint margin): clearance above the ground under the
          foot, so a toe passing a step's wall on its way up is not pushed sideways (the penetration
          term keeps it out of the box); beside a box's footprint, the distance to its top face where
          that is nearer (`rounded_edges`: the band wraps round the top's edge as a quarter cylinder
          of radius c, so the height, and the term, are continuous across the edge; a height that
          jumped there by the box's height left the optimizer a penalty its gradient could not see
          the end of, and rounds ended where they began, docs/contacts.md "The contact terms"),
    c_f = min(c, g T^2 / 8) for a flight of duration T (default): the height a ballistic body rises in
          a flight that long (g = 9.81 m/s^2), so a short hop's feet are not lifted more than the body
          is (a 0.08 s flight: 8 mm; 0.13 s and longer: c); or a fixed `flight_clearance`,
    the flight's band, with the default c_f, is lifted: max(c_f, `flight_lift`(t)) over the flight
          (a, b), a lift that rises linearly to H = `flight_lift` (FLIGHT_LIFT = 3.5 cm: the contact
          entry height 3 cm, which is also the flight metric's height, and 5 mm for the penalty's give)
          in TAKEOFF_RISE = 35 ms after take-off and falls back to 0 over the LANDING_DESCENT = 50 ms
          before landing. The captured feet of a schedule's flight are above the 3 cm flight height
          from 25-42 ms after its lift-off to 33-67 ms before its touch-down, in short flights as in
          long ones (a run's 0.10 s flights reach 3.5-5 cm), so the lifted band keeps a flight of T
          seconds in the air for T - 73 ms whatever T (docs/contacts.md "The contact terms"). The
          ballistic body's g/2 (t - a)(b - t) it replaces never reached 3 cm in a flight under 0.156 s
          (a short hop lost its flight). Without the lift c_f <= 2 cm is under the 3 cm that makes a
          flight in the metric (`solver.motion_metrics.FLIGHT_HEIGHT`). The lift is a target, not a
          bound for `conflicts`; keyframes where it is at its ceiling lower the ceiling to the lowest
          site they hold (`lower_lifts`). The band's corners are knots of the solve (`knot_times`): the
          feet rise to the flight height in TAKEOFF_RISE, a bend a spline follows only with a knot there,
    u_k = the swing window of site k, u_f = the flight window:
      swing: each gap [a, b] between consecutive contacts of site k (not before its first or after its
             last contact: there the schedule says nothing). u rises by a smoothstep from 0 at a to 1 at
             a + f L and falls back to 0 from b - f L to b, L = b - a, f = (1 - core) / 2, core =
             `core` (default 0.5: the central half of the swing is fully weighted).
      flight: the same shape on each interval inside the schedule where no site is in contact; it
             applies to all contact sites, so the flight of a run stays a flight (a walk has none).
             With the capture's own flights (`airborne`: the intervals where the motion the keyframes
             came from has every site above the 3 cm flight height) only the parts of a gap the capture
             flies through are flights (`flight_windows`: a ballistic one widened so that the lifted band
             crosses 3 cm where the capture does); the rest of the gap is plain swing. A gap where the
             captured feet glide in low (a landing foot below 3 cm before its contact, a heel sliding
             onto a step) is no flight, and the band does not hold the foot up there.

  So scuffing along the floor through the swing does not pay, while lift-off and touchdown (the ends
  of the gap) are free.

Keyframes that hold a swinging site lower than c (the capture's toe scuffs the floor in mid-swing on a
walk) lower that swing's band to the lowest height they hold it at (`Clearance.conflicts` finds them;
the term built with what it found, `conflicts=`, uses the lowered band): a path that must pass through
the keyframe and stay above c around it shoots the foot up between keyframes (16_23 keyed every 0.2 s:
35 cm, site error 52 cm).
"""
from __future__ import annotations

from types import MappingProxyType

import numpy as np

from solver.contact_thresholds import DETECT_HEIGHT_ON as HEIGHT_ON
from solver.contacts import checked_intervals, contact_radii
from solver.errors import InputError
from solver.layout import CONTACT_SITES, index_run
from solver.path_context import EngineGradient, site_engine
from solver.schedule_conflicts import ScheduleConflicts
from solver.surfaces import StaticSurfaces
from solver.terms.base import Residual, SiteRows, Term, TermEval
from solver.terms.contact_schedule import (
    FULL,
    SiteMotion,
    SupportSurfaces,
    _engine_index,
    _sample_times,
    check_contacts,
    gap_window,
    last_for_times,
)

GRAVITY = 9.81  # [m/s^2], for the ballistic flight clearance c_f
#: ceiling of the lift of a flight's band [m]: the contact entry height (3 cm, also the flight height of
#: `solver.motion_metrics.FLIGHT_HEIGHT`) and 5 mm for the penalty's give (docs/contacts.md "The contact terms")
FLIGHT_LIFT = HEIGHT_ON + 0.005
#: the lift's rise after a flight's take-off [s]: the captured feet cross the 3 cm flight height 25-42 ms
#: (mean 30 ms) after the schedule's lift-off (tuning clips 127_33 and 35_17 on the shipped figure and
#: floor, feet planted 2 mm up: 7 flights), so the lift reaches 3 cm 30 ms after take-off.
TAKEOFF_RISE = 0.035
#: the lift's descent before a flight's landing [s]: a landing foot comes down below the flight height
#: 33-67 ms (mean 44 ms) before its contact begins, gliding in at more than 0.5 m/s (the same flights).
LANDING_DESCENT = 0.05


def airborne_intervals(times: np.ndarray, heights: np.ndarray, height: float = HEIGHT_ON) -> tuple[tuple[float, float], ...]:
    """The intervals where a motion is airborne: every site higher than `height` (the flight metric's
    3 cm, `solver.motion_metrics.FLIGHT_HEIGHT`), a run of such frames i..j as (t_i - dt/2, t_j + dt/2)
    with dt the median frame spacing, so an interval lasts as long as the metric counts its frames.

    Args:
        times: (n,) increasing frame times [s], n >= 2. heights: (n, k) height of each site above the
            surface under it [m] (`solver.contacts.site_heights` of `contact_points`). height: [m].
    Returns:
        ((start, end), ...) [s], sorted and disjoint; () when no frame is airborne.
    Raises:
        InputError: shapes that disagree, fewer than two frames, times not increasing.
    """
    t, h = np.asarray(times, float), np.asarray(heights, float)
    if t.ndim != 1 or len(t) < 2 or h.ndim != 2 or len(h) != len(t):
        raise InputError(f"airborne_intervals: times {t.shape} and heights {h.shape} must be (n,) and (n, k), n >= 2")
    if not np.all(np.diff(t) > 0):
        raise InputError("airborne_intervals: frame times must increase")
    half = 0.5 * float(np.median(np.diff(t)))
    up = np.concatenate([[False], (h > height).all(axis=1), [False]]).astype(np.int8)
    starts, ends = np.flatnonzero(np.diff(up) == 1), np.flatnonzero(np.diff(up) == -1) - 1
    return tuple((float(t[i] - half), float(t[j] + half)) for i, j in zip(starts, ends, strict=True))


def flight_windows(gaps, airborne, rise: float = TAKEOFF_RISE, descent: float = LANDING_DESCENT,
                   ceiling: float = FLIGHT_LIFT, height: float = HEIGHT_ON) -> list[tuple[float, float]]:
    """The flights of a schedule that follow the capture's own: in each gap (a, b) of the schedule, each
    airborne interval (s, e) of the capture that overlaps it, clipped to the gap, touching ones merged.

    An interval at least as long as the lift's ramps (e - s >= rise + descent: 85 ms) is a ballistic
    flight: it is widened so that the lift (`flight_lift`) crosses `height` at s and e, (s - rise h /
    ceiling, e + descent h / ceiling), 30 ms and 43 ms with the defaults, so that a hop keeps its whole
    flight (a lift kept inside it would put the feet over 3 cm only after its ramps). A shorter one is
    the feet grazing the flight height between a glide and a landing: the lift stays inside it, since
    the site that ends it is the landing one, already low, and a lift widened past its end would hold
    that foot up while the capture's lands (docs/contacts.md "Flights where the capture flies"). A gap
    the capture does not fly through has no window: its sites keep their swing bands.

    Args:
        gaps: ((a, b), ...) [s] the schedule's flights (`ContactSchedule.flights`).
        airborne: ((s, e), ...) [s] the capture's airborne intervals (`airborne_intervals`).
        rise, descent: [s] > 0. ceiling: [m] > 0. height: [m] in [0, ceiling].
    Returns:
        [(start, end), ...] [s] sorted, each inside one gap.
    """
    lead, lag = rise * height / ceiling, descent * height / ceiling

    def widened(s, e):
        return (s - lead, e + lag) if e - s >= rise + descent else (s, e)

    out: list[tuple[float, float]] = []
    for a, b in gaps:
        inside = sorted((max(a, s), min(b, e)) for s, e in (widened(*se) for se in airborne) if s < b and e > a)
        for s, e in inside:
            if out and s <= out[-1][1]:
                out[-1] = (out[-1][0], max(out[-1][1], e))
            elif e > s:
                out.append((s, e))
    return out


def _checked_airborne(airborne) -> tuple[tuple[float, float], ...] | None:
    """`airborne` as ((start, end), ...) [s], checked (`checked_intervals`); None stays None."""
    return None if airborne is None else checked_intervals(airborne, "airborne")


def flight_lift(t: np.ndarray, a: float, b: float, ceiling: float, rise: float = TAKEOFF_RISE,
                descent: float = LANDING_DESCENT) -> np.ndarray:
    """The lifted flight band over a flight (a, b): ceiling * min(1, (t - a) / rise, (b - t) / descent),
    clipped at 0 outside (a, b) [m].

    Linear ramps: the band is above h (< ceiling) from a + rise h / ceiling to b - descent h / ceiling,
    so with the default ramps and ceiling (FLIGHT_LIFT) a flight of T seconds keeps the feet above the
    3 cm flight height for T - 73 ms, as the captured feet are (tuning clips: T - 58 to T - 92 ms in
    flights of 0.10-0.175 s; none in a 0.067 s one). A ballistic body's g/2 (t - a)(b - t) stays under
    the flight height in every flight under 0.156 s, where the captured feet of a run rise 3.5-5.8 cm.

    Args:
        t: (n,) times [s]. a < b: the flight [s]. ceiling: [m] >= 0. rise, descent: [s] > 0.
    Returns:
        (n,) band heights [m].
    """
    t = np.asarray(t, float)
    ramp = np.minimum(np.minimum((t - a) / rise, (b - t) / descent), 1.0)
    return float(ceiling) * np.clip(ramp, 0.0, None)


class Clearance(Term):
    """f = sum over sites of u(t) max(0, c - h)^2 (+ the flight band) [m^2]: swing feet clear.

    See the module docstring for u (swing cores and flights) and h. Gradient: -n (the normal of the
    surface under the site) through the site Jacobian, only where a weighted site is lower than its band.

    Args:
        model: MjModel of the scene. contacts: the schedule (a `solver.ContactSchedule`, or objects with
            site, start, end, surface; checked against the scene's surfaces).
        clearance: c [m] > 0 (default 2 cm).
        core: fraction in [0, 1] of each swing / flight that is fully weighted (default 0.5).
        flight: also apply to all contact sites during flights (default True).
        flight_clearance: c_f [m] > 0, the clearance during flights; default None: min(c, g T^2 / 8)
            per flight of duration T (module docstring, docs/contacts.md "The contact terms").
        flight_lift: ceiling [m] of the ballistic lift of the flight band (default FLIGHT_LIFT, 3.5 cm;
            None: no lift, the band is c_f). Only with the default c_f (flight_clearance None).
        sites: the sites the term looks after (default the four contact sites).
        t_span: see `Planted`.
        engine: the engine shared with the other terms (tracking `sites`); None: one of its own
            (`solver.path_context.site_engine`, positions only).
        airborne: ((start, end), ...) [s], the intervals where the capture the keyframes came from has
            every site above the flight height (`airborne_intervals`; `solver.problem.capture_airborne`):
            the flights are then only where the capture flies (`flight_windows`); None (default): every
            gap of the schedule is a flight.
        conflicts: `ScheduleConflicts` from `solver.problem.keyframe_conflicts`: its swings are left out
            of `violation`, its lowered bands and lift ceilings used (default: none).
    Raises:
        InputError: bad contact, no surfaces, bad parameters.
    """

    name = "clearance"
    units = "m^2"
    needs = (0,)
    fixed_points = True  # windows cached for the quadrature points

    def __init__(self, model, contacts, clearance: float = 0.02, core: float = 0.5, flight: bool = True,
                 sites=CONTACT_SITES, t_span=None, engine=None, flight_clearance: float | None = None,
                 flight_lift: float | None = FLIGHT_LIFT, conflicts: ScheduleConflicts | None = None,
                 airborne=None):
        surfaces = StaticSurfaces.from_model(model)
        if surfaces.count == 0:
            raise InputError("the scene has no static floor plane or box for the clearance term")
        #: the surface under a site: the boxes' top faces over their footprints exactly, else the floor
        self.below = SupportSurfaces(surfaces, footprint_margin=0.0, rounded_edges=True)
        self.contacts = check_contacts(contacts, CONTACT_SITES, surfaces.names)
        c, core = float(clearance), float(core)
        if not np.isfinite(c) or c <= 0:
            raise InputError(f"clearance is {clearance}; it must be a distance > 0 [m]")
        if not (0.0 <= core <= 1.0):
            raise InputError(f"core is {core}; it must be a fraction in [0, 1]")
        if flight_clearance is not None and not (np.isfinite(float(flight_clearance)) and float(flight_clearance) > 0):
            raise InputError(f"flight_clearance is {flight_clearance}; it must be a distance > 0 [m]")
        if flight_lift is not None and not (np.isfinite(float(flight_lift)) and float(flight_lift) >= 0):
            raise InputError(f"flight_lift is {flight_lift}; it must be a height >= 0 [m] (or None)")
        self.clearance, self.core, self.flight, self.t_span = c, core, bool(flight), t_span
        self.kin = SiteMotion(model, tuple(sites))
        self.radii = contact_radii(model, self.kin.names)  # (k,) [m]: 0 unless the figure rounds a site
        self.swings = [self.contacts.swings(s) for s in self.kin.names]
        #: the capture's airborne intervals [s], or None (unknown: every gap of the schedule is a flight)
        self.airborne = _checked_airborne(airborne)
        gaps = self.contacts.flights() if self.flight else []
        self.flights = gaps if self.airborne is None else flight_windows(gaps, self.airborne)
        #: c_f of each flight [m]
        self.flight_bands = np.array([min(c, GRAVITY * (b - a) ** 2 / 8.0) if flight_clearance is None
                                      else float(flight_clearance) for a, b in self.flights])
        #: what keyframes contradict (`solver.problem.keyframe_conflicts`); fixed at construction
        self.excusals = conflicts if conflicts is not None else ScheduleConflicts()
        #: ceiling of each flight's ballistic lift [m] (lowered by keyframes: `conflicts.lifts`); None: no lift
        self.flight_lifts = None
        if flight_lift is not None and flight_clearance is None:
            self.flight_lifts = np.array([min(float(flight_lift), self.excusals.lifts.get(ab, np.inf))
                                          for ab in self.flights], float).reshape(-1)
            self.flight_lifts.flags.writeable = False
        col = {s: k for k, s in enumerate(self.kin.names)}
        #: (site column, a, b) of the swings and flights `violation` skips (`conflicts.swings`)
        self.excused = tuple(sorted((col[s], a, b) for s, a, b in self.excusals.swings if s in col))
        #: (site column, a, b) -> the swing's lowered band [m] (`conflicts.lowered`)
        self.lowered = MappingProxyType({(col[s], a, b): v for (s, a, b), v in self.excusals.lowered.items()
                                         if s in col})
        # site positions of all points from the engine's forward pass (shared through the `PathContext`)
        self.engine = engine if engine is not None else site_engine(model, tuple(sites), velocities=False)
        self._eidx = index_run(_engine_index(self.engine, model, self.kin.names))  # the figure's: a slice
        self.needs = tuple(sorted({0, *self.engine.required}))

    def _heights(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Heights (..., k) [m] of the sites' contact points (a rounded site's sphere bottom, its centre
        minus its radius: `solver.contacts.lowest_points`) above the surface under them, and that
        surface's normals (..., k, 3) (`SupportSurfaces.height`), for site positions p (..., k, 3)."""
        h, nrm = self.below.height(p)
        return h - self.radii, nrm

    def knot_times(self) -> np.ndarray:
        """(r,) the corners of each lifted flight's band [s] (`Term.knot_times`): TAKEOFF_RISE after
        its take-off and LANDING_DESCENT before its landing, where the lift (`flight_lift`) reaches and
        leaves its ceiling; in a flight too short for both (T < TAKEOFF_RISE + LANDING_DESCENT) the top
        of its ramps. The feet go from the ground to above the flight height in those 35 ms, a bend a
        spline can only follow with a knot there: a hop keyed on its take-off, next frame 0.1 s later,
        left the optimized feet 7-10 mm under the ramp, the flight two frames short at its start.
        Flights whose lift is off or lowered to c_f (`lower_lifts`) have none.

        Returns:
            (r,) times [s], r <= 2 x the number of flights.
        """
        if self.flight_lifts is None:
            return np.zeros(0)
        knots = []
        for (a, b), top, cf in zip(self.flights, self.flight_lifts, self.flight_bands, strict=True):
            if top > cf:
                up, down = a + TAKEOFF_RISE, b - LANDING_DESCENT
                knots += [up, down] if up < down else [a + (b - a) * TAKEOFF_RISE / (TAKEOFF_RISE + LANDING_DESCENT)]
        return np.array(knots, float)

    def evaluate_in(self, ctx, grad=True) -> TermEval:
        """`Term.evaluate_in`: the gradient left to the engine's reverse pass (`EngineGradient`)."""
        mo, res = ctx.forward(self.engine, self.kin.tmap)
        f, gp = self._integrand(res.sites[:, self._eidx], *self.split_windows(ctx.t), grad=grad)
        if not grad:
            return TermEval(f)
        g_sites = np.zeros(res.sites.shape)
        g_sites[:, self._eidx] += gp  # distinct sites: distinct engine indices
        return TermEval(f, deferred=EngineGradient(self.engine, res, mo, None, g_sites))

    def residual(self, ctx) -> Residual:
        """r (n, 2 k) [m]: per site, sqrt(U_s) max(0, c_s - h) (swing) and sqrt(U_f) max(0, c_f - h)
        (flight) (f = |r|^2). Jacobian-vector products through the engine's reverse pass: d h / d p = n,
        the normal of the surface under the site (piecewise constant)."""
        mo, res = ctx.forward(self.engine, self.kin.tmap)
        Us, Uf, Bf, Bs = self.split_windows(ctx.t)
        h, nrm = self._heights(res.sites[:, self._eidx])  # (n, k), (n, k, 3)
        Uf = np.broadcast_to(Uf[:, None], Us.shape)
        su, sf = np.sqrt(Us), np.sqrt(Uf)
        ds, df = np.maximum(0.0, Bs - h), np.maximum(0.0, Bf[:, None] - h)
        r = np.concatenate([su * ds, sf * df], axis=1)
        k = Us.shape[1]

        def pull(g):
            gh = -(g[:, :k] * su * (ds > 0) + g[:, k:] * sf * (df > 0))  # d (g.r) / d h
            g_sites = np.zeros(res.sites.shape)
            g_sites[:, self._eidx] += gh[..., None] * nrm
            return EngineGradient(self.engine, res, mo, None, g_sites).pullback()

        site = np.tile(np.arange(len(self.engine.site_ids))[self._eidx], 2)
        dp = -np.concatenate([(su * (ds > 0))[..., None] * nrm, (sf * (df > 0))[..., None] * nrm], axis=1)
        signed = np.concatenate([su * (Bs - h), sf * (Bf[:, None] - h)], axis=1)
        signed[~np.isfinite(signed) | (np.concatenate([su, sf], axis=1) == 0)] = -np.inf  # nothing below / unweighted
        dsigned = -np.concatenate([su[..., None] * nrm, sf[..., None] * nrm], axis=1)
        return Residual(r, pull=pull, sites=SiteRows(ctx, self.engine, res, site, dp=dp, signed=signed,
                                                     dsigned=dsigned))

    def _integrand(self, p, Us, Uf, Bf, Bs, grad=True):
        """f (m,) and df/dp (m, k, 3) at site positions p (m, k, 3) with swing weights Us (m, k),
        flight weights Uf (m,) and flight bands Bf (m,) [m]."""
        h, n = self._heights(p)  # (m, k) height above the surface under each site, (m, k, 3) its normal
        f = np.zeros(len(p))
        gp = np.zeros(p.shape) if grad else None
        for U, band in ((Us, Bs), (np.broadcast_to(Uf[:, None], Us.shape), Bf[:, None])):
            if not U.any():
                continue
            depth = np.maximum(0.0, band - h)  # (m, k)
            f += (U * depth * depth).sum(1)
            if grad:
                gp -= (2.0 * U * depth)[..., None] * n
        return f, gp

    def conflicts(self, times, qpos, tolerance: float = 1e-4,
                  given: ScheduleConflicts | None = None) -> ScheduleConflicts:
        """Keyframes that contradict the schedule: a keyframe inside a fully weighted swing or flight
        window that holds a site more than `tolerance` [m] inside its band (keyframes are met exactly).
        Flights' depths are against c_f: their ballistic lift is a target, not a conflict
        (`lower_lifts`). A query: the term is not changed.

        Args:
            times: (k,) [s] times. qpos: (k, nq) poses there. tolerance: [m].
            given: conflicts found before (their lowered bands are the bands checked against).
        Returns:
            ScheduleConflicts: found = (("clearance", index into times, site, distance short of the
            clearance [m]), ...); those sites' swings (and flights) in `swings` (left out of `violation`
            when the term is built with it) and each such swing's band in `lowered`, down to the lowest
            height a keyframe holds the site at in it (used in the objective too).
        """
        times, qpos = np.asarray(times, float), np.asarray(qpos, float)
        given = given if given is not None else ScheduleConflicts()
        Us, Uf, Bf, Bs = self._split_windows(times, lift=False)  # the lift is a target, not a bound
        lowered = {}
        for (site, a, b), low in given.lowered.items():
            if site in self.kin.names:
                k, inside = self.kin.names.index(site), (times > a) & (times < b)
                Bs[inside, k] = np.minimum(Bs[inside, k], low)
                lowered[(site, a, b)] = low
        U = np.maximum(Us, Uf[:, None])
        band = np.where(Us >= Uf[:, None], Bs, Bf[:, None])
        d = np.maximum(0.0, band - self._heights(self.kin.positions(qpos))[0])
        height = band - d  # where d > 0: the site's height [m]
        hits = [(int(i), int(k)) for i, k in zip(*np.nonzero((U >= FULL) & (d > tolerance)), strict=True)]
        excused, new = set(), {}
        for i, k in hits:
            site = self.kin.names[k]
            for a, b in self.swings[k]:
                if a < times[i] < b:  # the swing's band down to the keyframe's height
                    low = min(new.get((site, a, b), lowered.get((site, a, b), self.clearance)), float(height[i, k]))
                    new[(site, a, b)] = max(0.0, low)
            excused |= {(site, a, b) for a, b in [*self.swings[k], *self.flights] if a < times[i] < b}
        found = [("clearance", i, self.kin.names[k], float(d[i, k])) for i, k in hits]
        return ScheduleConflicts(found, swings=excused, lowered=new)

    def lower_lifts(self, times, qpos) -> ScheduleConflicts:
        """Keyframes (times (k,) [s], poses qpos (k, nq)) lower each flight's lift ceiling to the lowest
        site height they hold where the lift is at its ceiling (`flight_lift` at full height: from
        TAKEOFF_RISE after take-off to LANDING_DESCENT before landing): a path that must pass through the
        keyframe and stay above the ceiling around it would bulge up between keyframes (a synthetic hop
        into a run, whose schedule missed a touch-down: 23 cm, site error 7.2 -> 10.9 cm). Call it with
        the keyframes only (`solver.problem.keyframe_conflicts`). A query: the term is not changed.

        Returns:
            ScheduleConflicts with `lifts` {(a, b): the lowered ceiling [m]} for the flights lowered.
        """
        if self.flight_lifts is None:
            return ScheduleConflicts()
        times, qpos = np.asarray(times, float), np.asarray(qpos, float)
        low = self._heights(self.kin.positions(qpos))[0].min(axis=1)  # (k,) lowest site [m]
        lifts = {}
        for j, (a, b) in enumerate(self.flights):
            top = flight_lift(times, a, b, 1.0) >= 1.0  # the lift at its ceiling
            if top.any():
                lifts[(a, b)] = min(float(self.flight_lifts[j]), max(0.0, float(low[top].min())))
        return ScheduleConflicts(lifts=lifts)

    def split_windows(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(Us (n, k), Uf (n,), Bf (n,), Bs (n, k)): each site's swing window, the flight window, the
        flight's band c_f [m] and each site's swing band [m] (c, or lower where `conflicts` lowered it)
        at times t (read-only; the last times' are kept: the quadrature points are the same at every
        evaluation)."""
        return last_for_times(self, "_split_cache", t, self._split_windows)

    def _split_windows(self, t: np.ndarray, lift: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        fl = np.zeros(t.shape)
        band = np.full(t.shape, self.clearance)
        for j, ((a, b), cf) in enumerate(zip(self.flights, self.flight_bands, strict=True)):
            fl = np.maximum(fl, gap_window(t, a, b, self.core))
            inside = (t > a) & (t < b)
            band[inside] = cf
            if lift and self.flight_lifts is not None:  # max(c_f, the lift up to its ceiling)
                band[inside] = np.maximum(cf, flight_lift(t[inside], a, b, self.flight_lifts[j]))
        cols = []
        bands = np.full((len(t), len(self.swings)), self.clearance)
        for k, gaps in enumerate(self.swings):
            u = np.zeros(t.shape)
            for a, b in gaps:
                u = np.maximum(u, gap_window(t, a, b, self.core))
                low = self.lowered.get((k, a, b))
                if low is not None:
                    bands[(t > a) & (t < b), k] = low
            cols.append(u)
        return np.stack(cols, 1), fl, band, bands

    def windows(self, t: np.ndarray) -> np.ndarray:
        """(n, k) weight of each site at times t: the larger of its swing and the flight window."""
        Us, Uf, _, _ = self.split_windows(t)
        return np.maximum(Us, Uf[:, None])

    def _band_depths(self, Y: np.ndarray, t: np.ndarray, lift: bool = True, dense: bool = False) -> np.ndarray:
        """(m, k) how far each site is inside the band of the window that weighs it most at times t [m]
        (lift False: flights' bands without the ballistic lift; dense: many samples, site positions by
        `SiteMotion.dense_positions`)."""
        Us, Uf, Bf, Bs = self.split_windows(t) if lift else self._split_windows(t, lift=False)
        h, _ = self._heights(self.kin.dense_positions(Y) if dense else self.kin.positions(Y))
        return np.maximum(0.0, np.where(Us >= Uf[:, None], Bs, Bf[:, None]) - h)

    def violation(self, Y: np.ndarray, t: np.ndarray | None = None) -> float | None:
        """Deepest intrusion into the clearance band, max(c - distance, 0) [m], where a site's window is
        full (times as in `Planted.violation`); None if unknown or nothing is fully weighted."""
        t = _sample_times(Y, t, self.t_span)
        if t is None:
            return None
        U = self.windows(t)
        for k, a, b in self.excused:
            U[(t > a) & (t < b), k] = 0.0
        rows = np.flatnonzero((U >= FULL).any(axis=1))
        if rows.size == 0:
            return None
        d = self._band_depths(Y[rows], t[rows], dense=True)
        return float(np.max(np.where(U[rows] >= FULL, d, 0.0)))
