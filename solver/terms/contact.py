"""Feet that plant (issue 11): a contact schedule turned into objective terms.

A contact is any object with attributes `site` (a contact site name, e.g. l_heel), `start`, `end` [s]
and `surface` (a `StaticSurfaces` name, "" = whichever surface is under the site; `solver.contacts.Contact`
has that shape). Two terms here, one in `solver.terms.contact_wrench` (friction cone):

`Planted` (name "planted", m^2): during a contact the site is on its surface and does not slide,

    f(t) = sum over contacts c of  w_c(t) [ (h_c(t) - h0)^2 + tau^2 |v_t,c(t)|^2 ],

    h   = signed height of the site above its support surface [m] (floating > 0, inside < 0),
    h0  = `rest_height` = the penetration term's margin (the figure: 2 mm), so the two terms agree on
          where a planted site rests (with h0 = 0 they fight: run-and-step's site ended 0.65 mm inside),
    v_t = v - (n.v) n, the site's velocity along the surface (n its unit normal) [m/s],
    tau = `velocity_time` [s] (default 0.1 s: 1 cm of height weighs like 10 cm/s of sliding),
    w_c = the contact's window: 1 inside [start + r, end - r], 0 outside [start, end], a smoothstep
          ramp of length r = `ramp` (default 0.02 s, at most half the contact) at each end.

  The plant point is left to the optimizer: the height is pulled to the surface under the site and the
  tangential velocity to zero, so the site stays wherever the path puts it (no keyframe pins it). The
  ramp tolerates contact times that are a frame or two off (touchdown and lift-off are not instant in
  the keyframes) and keeps the integrand continuous in t.

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

Velocities. The site velocity is v = P(Y) Y' with P = dp/dY = J(q) B(Y) (J the site Jacobian of
`mj_jacSite`, B the tangent map of `solver.kinematics`). Its gradient with respect to Y needs the
second derivatives of p: because d^2 p / dY_i dY_j is symmetric,

    d (g.v) / dY = (dP/dt)^T g = B^T Jdot^T g + Bdot^T J^T g,   d (g.v) / dY' = B^T J^T g,

with Jdot = dJ/dt along qvel = B Y' (MuJoCo's `mj_jacDot`, exact, no finite differences) and Bdot the
time derivative of B (on each quaternion block B = 2 G(q)/s, s = q.q:
Bdot = 2 G(q')/s - 4 (q.q') G(q)/s^2). `SiteMotion` does this.

Support surfaces. A plane supports on its free side; a box on its top face (the face whose outward
normal points most upward), over its footprint. With `surface=""` the support is chosen per point:
among the planes and the boxes whose top-face footprint (grown by `footprint_margin`) contains the
site, the one nearest in |height|. `SupportSurfaces` does this.
"""
from __future__ import annotations

import numpy as np

from solver.errors import InputError
from solver.layout import CONTACT_SITES
from solver.surfaces import StaticSurfaces
from solver.terms.base import Term, TermEval
from solver.terms.contact_schedule import (  # noqa: F401  (the schedule helpers, re-exported)
    FULL,
    SiteMotion,
    SupportSurfaces,
    _engine_index,
    _engine_motion,
    _sample_times,
    check_contacts,
    contact_window,
    flights,
    gap_window,
    last_for_times,
    smoothstep,
    swings,
)

GRAVITY = 9.81  # [m/s^2], for the ballistic flight clearance

__all__ = ["CONTACT_SITES", "Clearance", "Planted", "SiteMotion", "SupportSurfaces", "check_contacts",
           "contact_window", "flights", "gap_window", "smoothstep", "swings"]


class Planted(Term):
    """f = sum over contacts of w(t) ((h - h0)^2 + tau^2 |v_t|^2) [m^2]: feet on their surface, not sliding.

    See the module docstring for the equations. The gradient with respect to Y' is B^T J^T g_v, with
    respect to Y the site Jacobian for the height plus the second-derivative terms of the velocity
    (`SiteMotion.pullback`); exact, no finite differences. Only quadrature points inside a contact are
    computed.

    Args:
        model: MjModel of the scene (figure + static planes/boxes).
        contacts: objects with site, start, end, surface (see module docstring).
        velocity_time: tau [s] > 0, weighs sliding speed against height.
        ramp: r [s] >= 0, length of the smoothstep ramp at each end of a contact.
        rest_height: h0 [m], the height a planted site is pulled to (set it to the penetration term's
            margin).
        footprint_margin: [m] see `SupportSurfaces`.
        t_span: (t0, t1) [s] of the keyframes: `violation(Y)` without times assumes Y sampled evenly on
            it (how `solve` checks limits).
    Raises:
        InputError: a bad contact (unknown site or surface, start >= end), no surfaces, bad parameters.
    """

    name = "planted"
    units = "m^2"
    needs = (0, 1)

    def __init__(self, model, contacts, velocity_time: float = 0.1, ramp: float = 0.02,
                 rest_height: float = 0.005, footprint_margin: float = 0.03, t_span=None, engine=None):
        surfaces = StaticSurfaces.from_model(model)
        if surfaces.count == 0:
            raise InputError("the scene has no static floor plane or box for the planted term")
        self.support = SupportSurfaces(surfaces, footprint_margin)
        self.contacts = check_contacts(contacts, CONTACT_SITES, surfaces.names)
        tau, ramp = float(velocity_time), float(ramp)
        if not np.isfinite(tau) or tau <= 0:
            raise InputError(f"velocity_time is {velocity_time}; it must be a time > 0 [s]")
        if not np.isfinite(ramp) or ramp < 0:
            raise InputError(f"ramp is {ramp}; it must be a time >= 0 [s]")
        if not np.isfinite(float(rest_height)):
            raise InputError(f"rest_height is {rest_height}; it must be a finite height [m]")
        self.tau, self.ramp, self.rest_height, self.t_span = tau, ramp, float(rest_height), t_span
        used = sorted({c.site for c in self.contacts}, key=CONTACT_SITES.index)
        self.kin = SiteMotion(model, used or CONTACT_SITES[:1])
        self._col = np.array([self.kin.names.index(c.site) for c in self.contacts], int)
        self._surf = [self.support.index(c.surface) for c in self.contacts]
        self.excused: set[int] = set()  # contacts a keyframe contradicts: `violation` skips them
        self.engine = engine if engine is not None and hasattr(engine, "site_velocities") else None
        if self.engine is not None:
            # site positions and velocities at all points from the engine's vectorized forward pass
            # (shared with penetration/torque/root/cone), gradients through its single reverse pass
            self._eidx = _engine_index(self.engine, model, self.kin.names)
            self.needs = tuple(self.engine.needs)  # what the engine's forward pass reads

    def knot_times(self) -> np.ndarray:
        """(2C,) every contact's start and end [s]: at touch-down and lift-off a site goes from
        moving to still and back, a change of its acceleration a spline can only follow with a knot
        there (`Term.knot_times`)."""
        return np.array([x for c in self.contacts for x in (c.start, c.end)], float)

    def windows(self, t: np.ndarray) -> np.ndarray:
        """(n, C) window of each contact at times t (read-only; the last times' are kept)."""
        return last_for_times(self, "_window_cache", t, self._windows)

    def _windows(self, t: np.ndarray) -> np.ndarray:
        return np.stack([contact_window(t, float(c.start), float(c.end), self.ramp) for c in self.contacts], 1) \
            if self.contacts else np.zeros((len(t), 0))

    def _parts(self, p, v, W, rows):
        """Heights (m, C), tangential velocities (m, C, 3), normals (m, C, 3) of the contacts' sites,
        each contact's only where its window W (m, C) is on (zero elsewhere: W h^2 and W |v_t|^2 are
        zero there anyway)."""
        m, C = len(rows), len(self.contacts)
        h = np.zeros((m, C))
        vt = np.zeros((m, C, 3))
        nrm = np.zeros((m, C, 3))
        for c in range(C):
            on = np.flatnonzero(W[:, c] > 0)
            pc = p[on, self._col[c]]
            hc, nc = self.support.height(pc, self._surf[c])
            h[on, c] = hc - self.rest_height
            nrm[on, c] = nc
            if v is not None:
                vc = v[on, self._col[c]]
                vt[on, c] = vc - np.einsum("mi,mi->m", vc, nc)[:, None] * nc
        return h, vt, nrm

    def evaluate_deferred(self, t, Y, Y1, Y2, grad=True) -> TermEval:
        """With an engine: `evaluate` at all points at once, the gradient left to the engine's reverse
        pass (`solver.terms.dynamics.EngineGradient`); without one, `evaluate`."""
        if self.engine is None:
            return self.evaluate(t, Y, Y1, Y2, grad)
        from solver.terms.dynamics import EngineGradient

        mo, res = _engine_motion(self, Y, Y1, Y2)
        W = self.windows(t)
        rows = np.flatnonzero((W > 0).any(axis=1))
        f = np.zeros(len(Y))
        Wr = W[rows]
        p = res.sites[rows][:, self._eidx]
        v = self.engine.site_velocities(res)[rows][:, self._eidx]
        f[rows], g_p, g_v = self._integrand(p, v, Wr, rows, grad)
        if not grad:
            return TermEval(f)
        g_sites = np.zeros(res.sites.shape)
        g_vel = np.zeros(res.sites.shape)
        g_sites[np.ix_(rows, self._eidx)] = g_p
        g_vel[np.ix_(rows, self._eidx)] = g_v
        return TermEval(f, deferred=EngineGradient(self.engine, res, mo, None, g_sites, g_vel))

    def _integrand(self, p, v, Wr, rows, grad):
        """f at the contact rows (r,) from site positions p and velocities v (r, s, 3), and its gradients
        with respect to p and v (None without grad). d|v_t|^2/dv = 2 v_t (v_t is a projection of v)."""
        h, vt, nrm = self._parts(p, v, Wr, rows)
        t2 = self.tau * self.tau
        f = (Wr * (h * h + t2 * (vt * vt).sum(-1))).sum(1)
        if not grad:
            return f, None, None
        g_p = np.zeros(p.shape)
        g_v = np.zeros(v.shape)
        for c in range(len(self.contacts)):
            k = self._col[c]
            g_p[:, k] += (2.0 * Wr[:, c] * h[:, c])[:, None] * nrm[:, c]
            g_v[:, k] += (2.0 * t2 * Wr[:, c])[:, None] * vt[:, c]
        return f, g_p, g_v

    def evaluate(self, t, Y, Y1, Y2, grad=True) -> TermEval:
        if self.engine is not None:
            ev = self.evaluate_deferred(t, Y, Y1, Y2, grad)
            return ev if ev.deferred is None else TermEval(ev.f, *ev.deferred.pullback())
        n, nq = Y.shape
        W = self.windows(t)
        rows = np.flatnonzero((W > 0).any(axis=1))
        f = np.zeros(n)
        dY, dY1 = (np.zeros((n, nq)), np.zeros((n, nq))) if grad else (None, None)
        if rows.size == 0:
            return TermEval(f, dY, dY1)
        Yr, Y1r = Y[rows], Y1[rows]
        Wr = W[rows]
        mask = np.zeros((rows.size, len(self.kin.names)), bool)
        for c in range(len(self.contacts)):
            mask[:, self._col[c]] |= Wr[:, c] > 0
        p, v, J, Jd = self.kin.motion(Yr, Y1r, mask, grad)
        f[rows], g_p, g_v = self._integrand(p, v, Wr, rows, grad)
        if not grad:
            return TermEval(f)
        dYr, dY1r = self.kin.pullback(Yr, Y1r, J, Jd, g_p, g_v)
        dY[rows], dY1[rows] = dYr, dY1r
        return TermEval(f, dY, dY1)

    def residuals(self, t, Y, Y1=None):
        """Per sample and contact: window, height [m] and tangential speed [m/s] (velocity from Y1 if
        given, else by finite differences of the site positions along t).

        Returns:
            W (n, C), h - h0 (n, C), speed (n, C) (zero where the window is 0).
        """
        t = np.asarray(t, float)
        W = self.windows(t)
        n, C = W.shape
        h = np.zeros((n, C))
        speed = np.zeros((n, C))
        rows = np.flatnonzero((W > 0).any(axis=1))
        if rows.size == 0:
            return W, h, speed
        if Y1 is not None:
            p, v, _, _ = self.kin.motion(Y[rows], Y1[rows], grad=False)
        else:
            P = self.kin.positions(Y)
            v = np.gradient(P, t, axis=0)[rows]
            p = P[rows]
        hh, vt, _ = self._parts(p, v, W[rows], rows)
        h[rows], speed[rows] = hh, np.linalg.norm(vt, axis=-1)
        return W, h, speed

    def violation(self, Y: np.ndarray, t: np.ndarray | None = None) -> float | None:
        """Largest max(|h - h0|, tau |v_t|) [m] where a contact's window is full (velocities by finite
        differences of the samples). Times: `t`, else Y is taken as sampled evenly on `t_span`; None if
        neither is known or no sample is fully in contact."""
        t = _sample_times(Y, t, self.t_span)
        if t is None or not self.contacts:
            return None
        W, h, speed = self.residuals(t, Y)
        full = W >= FULL
        full[:, sorted(self.excused)] = False
        if not full.any():
            return None
        return float(np.max(np.where(full, np.maximum(np.abs(h), self.tau * speed), 0.0)))

    def _at_keyframes(self, times, qpos):
        """(W (k, C) contact windows at the keyframe times, p (k, sites, 3) site positions or None)."""
        W = self.windows(np.asarray(times, float))
        return W, (self.kin.positions(np.asarray(qpos, float)) if W.size else None)

    def conflicts(self, times, qpos, tolerance: float = 0.01, excuse: bool = False) -> list[tuple[int, str, float]]:
        """Keyframes that contradict the schedule: a keyframe at time t inside a contact's full window
        whose site is more than `tolerance` [m] from the plant height (keyframes are met exactly, so
        the term cannot pull that site down). excuse: also leave those contacts out of `violation`
        (else penalty continuation would raise the weight against a bound it cannot reach).

        Returns:
            [(keyframe index, site, height - h0 [m]), ...].
        """
        W, p = self._at_keyframes(times, qpos)
        out = []
        if not W.size:
            return out
        for c, contact in enumerate(self.contacts):
            h, _ = self.support.height(p[:, self._col[c]], self._surf[c])
            for i in np.flatnonzero((W[:, c] >= FULL) & (np.abs(h - self.rest_height) > tolerance)):
                out.append((int(i), contact.site, float(h[i] - self.rest_height)))
                if excuse:
                    self.excused.add(c)
        return out

    def slides(self, times, qpos, tolerance: float = 0.01, excuse: bool = False) -> list[tuple[int, str, float]]:
        """Keyframes that make a planted site slide: two keyframes in one contact (window > 0) that hold
        the site more than `tolerance` [m] apart horizontally (capture's feet roll and pivot: 2-4 cm on
        the walk; no path can then keep the site still, README "Feet that plant"). excuse: leave those
        contacts out of `violation` (the term still pulls toward no sliding).

        Returns: [(index of the later keyframe, site, largest horizontal distance [m]), ...].
        """
        W, p = self._at_keyframes(times, qpos)
        out = []
        if not W.size:
            return out
        for c, contact in enumerate(self.contacts):
            inside = np.flatnonzero(W[:, c] > 0)
            if len(inside) < 2:
                continue
            xy = p[inside, self._col[c], :2]
            spread = float(np.max(np.linalg.norm(xy[:, None] - xy[None], axis=-1)))
            if spread > tolerance:
                out.append((int(inside[-1]), contact.site, spread))
                if excuse:
                    self.excused.add(c)
        return out


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

    def _integrand(self, p, Us, Uf, Bf, grad=True):
        """f (m,) and df/dp (m, k, 3) at site positions p (m, k, 3) with swing weights Us (m, k),
        flight weights Uf (m,) and flight bands Bf (m,) [m]."""
        h, n = self.below.height(p)  # (m, k) height above the surface under each site, (m, k, 3) its normal
        f = np.zeros(len(p))
        gp = np.zeros(p.shape) if grad else None
        for U, band in ((Us, self.clearance), (np.broadcast_to(Uf[:, None], Us.shape), Bf[:, None])):
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
        excuse: also leave that site's swing (or flight) out of `violation`.

        Returns:
            [(keyframe index, site, distance short of the clearance [m]), ...].
        """
        times = np.asarray(times, float)
        d = self._band_depths(np.asarray(qpos, float), times)
        U = self.windows(times)
        out = [(int(i), self.kin.names[k], float(d[i, k]))
               for i, k in zip(*np.nonzero((U >= FULL) & (d > tolerance)), strict=True)]
        if excuse:
            for i, k, _ in ((i, self.kin.names.index(site), dd) for i, site, dd in out):
                for a, b in [*self.swings[k], *self.flights]:
                    if a < times[i] < b:
                        self.excused.append((k, a, b))
        return out

    def split_windows(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(Us (n, k), Uf (n,), Bf (n,)): each site's swing window, the flight window and the flight's
        band c_f [m] (the clearance outside flights) at times t (read-only; the last times' are kept:
        the quadrature points are the same at every evaluation)."""
        return last_for_times(self, "_split_cache", t, self._split_windows)

    def _split_windows(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        fl = np.zeros(t.shape)
        band = np.full(t.shape, self.clearance)
        for (a, b), cf in zip(self.flights, self.flight_bands, strict=True):
            fl = np.maximum(fl, gap_window(t, a, b, self.core))
            band[(t > a) & (t < b)] = cf
        cols = []
        for gaps in self.swings:
            u = np.zeros(t.shape)
            for a, b in gaps:
                u = np.maximum(u, gap_window(t, a, b, self.core))
            cols.append(u)
        return np.stack(cols, 1), fl, band

    def windows(self, t: np.ndarray) -> np.ndarray:
        """(n, k) weight of each site at times t: the larger of its swing and the flight window."""
        Us, Uf, _ = self.split_windows(t)
        return np.maximum(Us, Uf[:, None])

    def _band_depths(self, Y: np.ndarray, t: np.ndarray) -> np.ndarray:
        """(m, k) how far each site is inside the band of the window that weighs it most at times t [m]."""
        Us, Uf, Bf = self.split_windows(t)
        h, _ = self.below.height(self.kin.positions(Y))
        return np.maximum(0.0, np.where(Us >= Uf[:, None], self.clearance, Bf[:, None]) - h)

    def evaluate(self, t, Y, Y1, Y2, grad=True) -> TermEval:
        if self.engine is not None:
            ev = self.evaluate_deferred(t, Y, Y1, Y2, grad)
            return ev if ev.deferred is None else TermEval(ev.f, *ev.deferred.pullback())
        n, nq = Y.shape
        Us, Uf, Bf = self.split_windows(t)
        rows = np.flatnonzero((Us > 0).any(axis=1) | (Uf > 0))
        f = np.zeros(n)
        dY = np.zeros((n, nq)) if grad else None
        if rows.size == 0:
            return TermEval(f, dY)
        p = self.kin.positions(Y[rows])
        f[rows], gp = self._integrand(p, Us[rows], Uf[rows], Bf[rows], grad)
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
