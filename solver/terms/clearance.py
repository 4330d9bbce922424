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

from solver.errors import InputError
from solver.layout import CONTACT_SITES
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
        sites: the sites the term looks after (default the four contact sites).
        t_span: see `Planted`.
    Raises:
        InputError: bad contact, no surfaces, bad parameters.
    """

    name = "clearance"
    units = "m^2"
    needs = (0,)

    def __init__(self, model, contacts, clearance: float = 0.02, core: float = 0.5, flight: bool = True,
                 sites=CONTACT_SITES, t_span=None, engine=None, flight_clearance: float | None = None):
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
        self.clearance, self.core, self.flight, self.t_span = c, core, bool(flight), t_span
        self.kin = SiteMotion(model, tuple(sites))
        self.swings = [swings(self.contacts, s) for s in self.kin.names]
        self.flights = flights(self.contacts) if self.flight else []
        #: c_f of each flight [m]
        self.flight_bands = np.array([min(c, GRAVITY * (b - a) ** 2 / 8.0) if flight_clearance is None
                                      else float(flight_clearance) for a, b in self.flights])
        self.excused: list[tuple[int, float, float]] = []  # (site column, a, b): `violation` skips these
        self.lowered: dict[tuple[int, float, float], float] = {}  # (site column, a, b): swing band [m]
        self.engine = engine
        if engine is not None:  # site positions of all points from the shared engine's forward pass
            self._eidx = _engine_index(engine, model, self.kin.names)
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
        np.add.at(g_sites, (slice(None), self._eidx), gp)
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

        Returns:
            [(keyframe index, site, distance short of the clearance [m]), ...].
        """
        times = np.asarray(times, float)
        d = self._band_depths(np.asarray(qpos, float), times)
        U = self.windows(times)
        Us, Uf, Bf, Bs = self.split_windows(times)
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

    def split_windows(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(Us (n, k), Uf (n,), Bf (n,), Bs (n, k)): each site's swing window, the flight window, the
        flight's band c_f [m] and each site's swing band [m] (c, or lower where `conflicts` lowered it)
        at times t (read-only; the last times' are kept: the quadrature points are the same at every
        evaluation)."""
        return last_for_times(self, "_split_cache", t, self._split_windows)

    def _split_windows(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        fl = np.zeros(t.shape)
        band = np.full(t.shape, self.clearance)
        for (a, b), cf in zip(self.flights, self.flight_bands, strict=True):
            fl = np.maximum(fl, gap_window(t, a, b, self.core))
            band[(t > a) & (t < b)] = cf
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

    def _band_depths(self, Y: np.ndarray, t: np.ndarray) -> np.ndarray:
        """(m, k) how far each site is inside the band of the window that weighs it most at times t [m]."""
        Us, Uf, Bf, Bs = self.split_windows(t)
        h, _ = self.below.height(self.kin.positions(Y))
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
        d = self._band_depths(Y[rows], t[rows])
        return float(np.max(np.where(U[rows] >= FULL, d, 0.0)))
