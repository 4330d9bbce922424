"""Swing feet that clear the ground (issue 11): the clearance term of a contact schedule.

`Clearance` (name "clearance", m^2): a site that is not in contact keeps a clearance c (default 2 cm)
from every surface in the middle of its swing, and every site keeps c_f in the middle of a flight,

    f(t) = sum over sites k of  u_k(t) max(0, c - h_k(t))^2 + u_f(t) max(0, c_f - h_k(t))^2,
    h_k = height of site k above the surface under it (a box's top face over its footprint, else the
          floor; `SupportSurfaces` with no footprint margin): clearance above the ground under the
          foot, so a toe passing a step's edge on its way up is not pushed sideways (the penetration
          term keeps it out of the box),
    c_f = min(c, g T^2 / 8) for a flight of duration T (default): the height a ballistic body rises in
          a flight that long (g = 9.81 m/s^2), so a short hop's feet are not lifted more than the body
          is (a 0.08 s flight: 8 mm; 0.13 s and longer: c); or a fixed `flight_clearance`,
    the flight's band, with the default c_f, is lifted ballistically: max(c_f, min(H, g/2 (t - a)(b - t)))
          over the flight (a, b), g/2 (t - a)(b - t) the height of a body that leaves the floor at a and
          lands at b (its feet with it, as in a hop), H = `flight_lift` (FLIGHT_LIFT = 3.5 cm: the
          contact entry height 3 cm, which is also the flight metric's height, and 5 mm for the
          penalty's give). Without the lift c_f = 2 cm is under the 3 cm that makes a flight in the
          metric (`solver.motion_metrics.FLIGHT_HEIGHT`), and the feet sank to it long before the
          landing: a 15 cm, 0.35 s hop of 16_23 flew 58 ms less than the capture (0.258 / 0.317 s), now
          0.317 s (docs/contacts.md "Hops and jumps"). Flights shorter than 0.13 s are not lifted
          (g T^2 / 8 <= c); a run's (0.16-0.18 s) only in their middle. The lift is a target, not a
          bound for `conflicts`; keyframes where it is at its ceiling lower the ceiling to the lowest
          site they hold (`lower_lifts`),
    u_k = the swing window of site k, u_f = the flight window:
      swing: each gap [a, b] between consecutive contacts of site k (not before its first or after its
             last contact: there the schedule says nothing). u rises by a smoothstep from 0 at a to 1 at
             a + f L and falls back to 0 from b - f L to b, L = b - a, f = (1 - core) / 2, core =
             `core` (default 0.5: the central half of the swing is fully weighted).
      flight: the same shape on each interval inside the schedule where no site is in contact; it
             applies to all contact sites, so the flight of a run stays a flight (a walk has none).

  So scuffing along the floor through the swing does not pay, while lift-off and touchdown (the ends
  of the gap) are free.

Keyframes that hold a swinging site lower than c (the capture's toe scuffs the floor in mid-swing on a
walk) lower that swing's band to the lowest height they hold it at (`Clearance.conflicts` with
excuse=True): a path that must pass through the keyframe and stay above c around it shoots the foot
up between keyframes (16_23 keyed every 0.2 s: 35 cm, site error 52 cm).
"""
from __future__ import annotations

import numpy as np

from solver.contact_thresholds import DETECT_HEIGHT_ON as HEIGHT_ON
from solver.errors import InputError
from solver.layout import CONTACT_SITES, index_run
from solver.surfaces import StaticSurfaces
from solver.terms.base import Term, TermEval
from solver.terms.contact_schedule import (
    FULL,
    SiteMotion,
    SupportSurfaces,
    _engine_index,
    _engine_motion,
    _sample_times,
    check_contacts,
    flights,
    gap_window,
    last_for_times,
    swings,
)

GRAVITY = 9.81  # [m/s^2], for the ballistic flight clearance
#: ceiling of the ballistic lift of a flight's band [m]: the contact entry height (3 cm, also the flight
#: height of `solver.motion_metrics.FLIGHT_HEIGHT`) and 5 mm for the penalty's give (docs/contacts.md)
FLIGHT_LIFT = HEIGHT_ON + 0.005


class Clearance(Term):
    """f = sum over sites of u(t) max(0, c - h)^2 (+ the flight band) [m^2]: swing feet clear.

    See the module docstring for u (swing cores and flights) and h. Gradient: -n (the normal of the
    surface under the site) through the site Jacobian, only where a weighted site is lower than its band.

    Args:
        model: MjModel of the scene. contacts: the schedule (objects with site, start, end, surface).
        clearance: c [m] > 0 (default 2 cm).
        core: fraction in [0, 1] of each swing / flight that is fully weighted (default 0.5).
        flight: also apply to all contact sites during flights (default True).
        flight_clearance: c_f [m] > 0, the clearance during flights; default None: min(c, g T^2 / 8)
            per flight of duration T (module docstring, docs/contacts.md).
        flight_lift: ceiling [m] of the ballistic lift of the flight band (default FLIGHT_LIFT, 3.5 cm;
            None: no lift, the band is c_f). Only with the default c_f (flight_clearance None).
        sites: the sites the term looks after (default the four contact sites).
        t_span: see `Planted`.
    Raises:
        InputError: bad contact, no surfaces, bad parameters.
    """

    name = "clearance"
    units = "m^2"
    needs = (0,)

    def __init__(self, model, contacts, clearance: float = 0.02, core: float = 0.5, flight: bool = True,
                 sites=CONTACT_SITES, t_span=None, engine=None, flight_clearance: float | None = None,
                 flight_lift: float | None = FLIGHT_LIFT):
        surfaces = StaticSurfaces.from_model(model)
        if surfaces.count == 0:
            raise InputError("the scene has no static floor plane or box for the clearance term")
        #: the surface under a site: the boxes' top faces over their footprints exactly, else the floor
        self.below = SupportSurfaces(surfaces, footprint_margin=0.0)
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
        self.swings = [swings(self.contacts, s) for s in self.kin.names]
        self.flights = flights(self.contacts) if self.flight else []
        #: c_f of each flight [m]
        self.flight_bands = np.array([min(c, GRAVITY * (b - a) ** 2 / 8.0) if flight_clearance is None
                                      else float(flight_clearance) for a, b in self.flights])
        #: ceiling of each flight's ballistic lift [m] (lowered by keyframes in `conflicts`); None: no lift
        self.flight_lifts = (None if flight_lift is None or flight_clearance is not None
                             else np.full(len(self.flights), float(flight_lift)))
        self.excused: list[tuple[int, float, float]] = []  # (site column, a, b): `violation` skips these
        self.lowered: dict[tuple[int, float, float], float] = {}  # (site column, a, b): swing band [m]
        self.engine = engine
        if engine is not None:  # site positions of all points from the shared engine's forward pass
            self._eidx = index_run(_engine_index(engine, model, self.kin.names))  # the figure's: a slice
            self.needs = tuple(engine.needs)

    def evaluate_deferred(self, t, Y, Y1, Y2, grad=True) -> TermEval:
        """With an engine: `evaluate` with the gradient left to the engine's reverse pass."""
        if self.engine is None:
            return self.evaluate(t, Y, Y1, Y2, grad)
        from solver.terms.dynamics import EngineGradient

        mo, res = _engine_motion(self, Y, Y1, Y2)
        f, gp = self._integrand(res.sites[:, self._eidx], *self.split_windows(t), grad=grad)
        if not grad:
            return TermEval(f)
        g_sites = np.zeros(res.sites.shape)
        g_sites[:, self._eidx] += gp  # distinct sites: distinct engine indices (as np.add.at, faster)
        return TermEval(f, deferred=EngineGradient(self.engine, res, mo, None, g_sites))

    def _integrand(self, p, Us, Uf, Bf, Bs, grad=True):
        """f (m,) and df/dp (m, k, 3) at site positions p (m, k, 3) with swing weights Us (m, k),
        flight weights Uf (m,) and flight bands Bf (m,) [m]."""
        h, n = self.below.height(p)  # (m, k) height above the surface under each site, (m, k, 3) its normal
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

    def conflicts(self, times, qpos, excuse: bool = False, tolerance: float = 1e-4) -> list[tuple[int, str, float]]:
        """Keyframes that contradict the schedule: a keyframe inside a fully weighted swing or flight
        window that holds a site more than `tolerance` [m] inside its band (keyframes are met exactly).
        excuse: also leave that site's swing (or flight) out of `violation`, and lower the band of that
            swing, in the objective too, to the lowest height a keyframe holds the site at in it.
        Flights' depths are against c_f: their ballistic lift is a target, not a conflict (`lower_lifts`).

        Returns:
            [(keyframe index, site, distance short of the clearance [m]), ...].
        """
        times, qpos = np.asarray(times, float), np.asarray(qpos, float)
        Us, Uf, Bf, Bs = self._split_windows(times, lift=False)  # the lift is a target, not a bound
        U = np.maximum(Us, Uf[:, None])
        d = self._band_depths(qpos, times, lift=False)
        height = np.where(Us >= Uf[:, None], Bs, Bf[:, None]) - d  # where d > 0: the site's height [m]
        out = [(int(i), self.kin.names[k], float(d[i, k]))
               for i, k in zip(*np.nonzero((U >= FULL) & (d > tolerance)), strict=True)]
        if excuse:
            for i, k in ((i, self.kin.names.index(site)) for i, site, _ in out):
                for a, b in self.swings[k]:
                    if a < times[i] < b:  # the swing's band down to the keyframe's height, for good
                        low = min(self.lowered.get((k, a, b), self.clearance), float(height[i, k]))
                        self.lowered[(k, a, b)] = max(0.0, low)
                for a, b in [*self.swings[k], *self.flights]:
                    if a < times[i] < b:
                        self.excused.append((k, a, b))
            self.__dict__.pop("_split_cache", None)  # the windows' bands changed
        return out

    def lower_lifts(self, times, qpos) -> None:
        """Keyframes (times (k,) [s], poses qpos (k, nq)) lower each flight's lift ceiling, for good, to
        the lowest site height they hold where the lift is at its ceiling (g/2 (t - a)(b - t) >=
        ceiling; not just after take-off or before landing, where every flight is low): a path that must
        pass through the keyframe and stay above the ceiling around it would bulge up between keyframes
        (a synthetic hop into a run, whose schedule missed a touch-down: 23 cm, site error 7.2 -> 10.9 cm).
        Call it with the keyframes only (`solver.problem.keyframe_conflicts`)."""
        if self.flight_lifts is None:
            return
        times, qpos = np.asarray(times, float), np.asarray(qpos, float)
        low = self.below.height(self.kin.positions(qpos))[0].min(axis=1)  # (k,) lowest site [m]
        for j, (a, b) in enumerate(self.flights):
            top = 0.5 * GRAVITY * (times - a) * (b - times) >= self.flight_lifts[j]
            if top.any():
                self.flight_lifts[j] = min(self.flight_lifts[j], max(0.0, float(low[top].min())))
        self.__dict__.pop("_split_cache", None)

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
            if lift and self.flight_lifts is not None:  # max(c_f, min(ceiling, g/2 (t - a)(b - t)))
                ti = t[inside]
                band[inside] = np.maximum(cf, np.minimum(self.flight_lifts[j], 0.5 * GRAVITY * (ti - a) * (b - ti)))
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
        h, _ = self.below.height(self.kin.dense_positions(Y) if dense else self.kin.positions(Y))
        return np.maximum(0.0, np.where(Us >= Uf[:, None], Bs, Bf[:, None]) - h)

    def evaluate(self, t, Y, Y1, Y2, grad=True) -> TermEval:
        if self.engine is not None:
            ev = self.evaluate_deferred(t, Y, Y1, Y2, grad)
            return ev if ev.deferred is None else TermEval(ev.f, *ev.deferred.pullback())
        n, nq = Y.shape
        Us, Uf, Bf, Bs = self.split_windows(t)
        rows = np.flatnonzero((Us > 0).any(axis=1) | (Uf > 0))
        f = np.zeros(n)
        dY = np.zeros((n, nq)) if grad else None
        if rows.size == 0:
            return TermEval(f, dY)
        p = self.kin.positions(Y[rows])
        f[rows], gp = self._integrand(p, Us[rows], Uf[rows], Bf[rows], Bs[rows], grad)
        if not grad:
            return TermEval(f)
        hit = np.flatnonzero(np.abs(gp).sum(axis=(1, 2)) > 0)
        if hit.size:
            Yh = Y[rows[hit]]
            _, J = self.kin.jacobians(Yh)
            gv = np.einsum("mkij,mki->mj", J, gp[hit])
            dY[rows[hit]] = self.kin.tmap.pullback(Yh, gv)
        return TermEval(f, dY)

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
