"""Feet that plant: a contact schedule turned into objective terms (docs/contacts.md "The contact terms").

A contact is any object with attributes `site` (a contact site name, e.g. l_heel), `start`, `end` [s]
and `surface` (a `StaticSurfaces` name, "" = whichever surface is under the site; `solver.contacts.Contact`
has that shape). One term here, one in `solver.terms.clearance` and one in
`solver.terms.contact_wrench` (friction cone):

`Planted` (name "planted", m^2): during a contact the site is on its surface and does not slide,

    f(t) = sum over contacts c of  s_c(t) (h_c(t) - h0)^2 + w_c(t) tau^2 |v_t,c(t)|^2,

    h   = signed height of the site above its support surface [m] (floating > 0, inside < 0),
    h0  = `rest_height` = the penetration term's margin (the figure: 2 mm), so the two terms agree on
          where a planted site rests (with h0 = 0 they fight: run-and-step's site ended 0.65 mm inside),
    v_t = v - (n.v) n, the site's velocity along the surface (n its unit normal) [m/s],
    tau = `velocity_time` [s] (default 0.1 s: 1 cm of height weighs like 10 cm/s of sliding),
    w_c = the contact's sliding window: 1 inside [start + r, end - r], 0 outside [start, end], a
          smoothstep ramp of length r = `ramp` (default 0.02 s, at most half the contact) at each end,
    s_c = the contact's height window: 1 on the closed contact [start, end], 0 outside (no ramp).

  The plant point is left to the optimizer: the height is pulled to the surface under the site and the
  tangential velocity to zero, so the site stays wherever the path puts it (no keyframe pins it). The
  sliding ramps tolerate contact times a frame or two off: the capture's sites still move at touch-down
  and lift-off (contacts start below 0.5 m/s and end above 1 m/s, `solver.contacts`). Height has no ramp:
  a site in contact is on its surface from touch-down to lift-off (the capture's sites are 2-13 mm up at
  a contact's first and last frames), and the float metric (`solver.motion_metrics`, docs/contacts.md
  "Motion metrics": mean float in reference contact) counts every frame of the contact. With the height
  ramped as well, the optimized feet come down 2-3 frames late and leave 2-4 frames early, 1-3 cm up
  at the contact's ends, and the frames inside the ramps make about half the mean float
  (docs/contacts.md "The contact terms"). A ramp outside the contact (pulling a foot that is still in the air) cut more float but
  shortened flights by up to 0.11 s. The step in s_c is harmless to the quadrature: the solve puts a
  frame at every touch-down and lift-off (`knot_times`; not within 30 ms of another frame), and the
  quadrature points are fixed, so the objective stays a smooth function of the frames.

`Clearance` (name "clearance", `solver.terms.clearance`): swing feet keep clear of the surfaces.

Velocities. The site velocity is v = P(Y) Y' with P = dp/dY = J(q) B(Y) (J the site Jacobian of
`mj_jacSite`, B the tangent map of `solver.kinematics`). Its gradient with respect to Y needs the
second derivatives of p: because d^2 p / dY_i dY_j is symmetric,

    d (g.v) / dY = (dP/dt)^T g = B^T Jdot^T g + Bdot^T J^T g,   d (g.v) / dY' = B^T J^T g,

with Jdot = dJ/dt along qvel = B Y' (MuJoCo's `mj_jacDot`, exact, no finite differences) and Bdot the
time derivative of B (on each quaternion block B = 2 G(q)/s, s = q.q:
Bdot = 2 G(q')/s - 4 (q.q') G(q)/s^2). The term reads v and pulls its gradient back through the
shared engine's vectorized forward and reverse passes (`solver.path_context`: the velocity of the
site's point of its body, appendix A eq. 19); `SiteMotion` computes the same with MuJoCo point by
point, the tests' reference.

Support surfaces. A plane supports on its free side; a box on its top face (the face whose outward
normal points most upward), over its footprint. With `surface=""` the support is chosen per point:
among the planes and the boxes whose top-face footprint (grown by `footprint_margin`) contains the
site, the one nearest in |height|. `SupportSurfaces` does this.
"""
from __future__ import annotations

import copy

import numpy as np

from solver.contact_thresholds import KEYFRAME_TOLERANCE
from solver.contacts import contact_radii
from solver.errors import InputError
from solver.layout import CONTACT_SITES
from solver.path_context import EngineGradient, site_engine
from solver.schedule_conflicts import ScheduleConflicts
from solver.surfaces import StaticSurfaces
from solver.terms.base import Residual, SiteRows, Term, TermEval
from solver.terms.contact_schedule import (
    FULL,
    KEYFRAME_AT_END,
    SiteMotion,
    SupportSurfaces,
    _engine_index,
    _sample_times,
    check_contacts,
    contact_window,
    flights,
    gap_window,
    last_for_times,
    smoothstep,
    swings,
)

__all__ = ["CONTACT_SITES", "Planted", "SiteMotion", "SupportSurfaces", "check_contacts",
           "contact_window", "flights", "gap_window", "smoothstep", "swings"]


class Planted(Term):
    """f = sum over contacts of w(t) ((h - h0)^2 + tau^2 |v_t|^2) [m^2]: feet on their surface, not sliding.

    See the module docstring for the equations. Site positions and velocities come from the engine's
    forward pass on the evaluation's `PathContext`; the gradient (with respect to Y: the height's site
    Jacobian plus the velocity's second-derivative terms; with respect to Y': B^T J^T g_v) from its
    reverse pass, exact, no finite differences. Only the (point, contact) pairs inside a contact are
    computed. `residual` gives r with f = |r|^2.

    Args:
        model: MjModel of the scene (figure + static planes/boxes).
        contacts: a `solver.ContactSchedule`, or objects with site, start, end, surface (see module
            docstring), checked against the scene's surfaces (`ContactSchedule.for_scene`).
        velocity_time: tau [s] > 0, weighs sliding speed against height.
        ramp: r [s] >= 0, length of the smoothstep ramp at each end of a contact's sliding window (height has none).
        rest_height: h0 [m], the height a planted site is pulled to (set it to the penetration term's
            margin).
        footprint_margin: [m] see `SupportSurfaces`.
        t_span: (t0, t1) [s] of the keyframes: `violation(Y)` without times assumes Y sampled evenly on
            it (how `solve` checks limits).
        engine: the engine shared with the other terms (`SiteKinematics` or `InverseDynamics`, tracking
            the contact sites); one without site velocities (MuJoCo's), or None: one of its own
            (`solver.path_context.site_engine`).
        conflicts: `ScheduleConflicts` from `solver.problem.keyframe_conflicts`: its `planted` contacts
            are left out of `violation` (default: none).
    Raises:
        InputError: a bad contact (unknown site or surface, start >= end), no surfaces, bad parameters,
            or (with no usable engine given) a figure the vectorized kinematics does not model.
    """

    name = "planted"
    units = "m^2"
    needs = (0, 1)
    fixed_points = True  # windows and (point, contact) pairs cached for the quadrature points

    def __init__(self, model, contacts, velocity_time: float = 0.1, ramp: float = 0.02,
                 rest_height: float = 0.005, footprint_margin: float = 0.03, t_span=None, engine=None,
                 conflicts: ScheduleConflicts | None = None):
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
        #: (C,) each contact's plant height of its site [m]: `rest_height` for the site's contact point, so
        #: the site's own height plus its radius if the figure rounds it (`solver.contacts.contact_radii`)
        self._h0 = self.rest_height + contact_radii(model, self.kin.names)[self._col]
        #: what keyframes contradict (`solver.problem.keyframe_conflicts`); fixed at construction
        self.excusals = conflicts if conflicts is not None else ScheduleConflicts()
        #: indices of the contacts a keyframe contradicts: `violation` skips them
        self.excused = frozenset(c for c, x in enumerate(self.contacts) if x in self.excusals.planted)
        #: (C,) factor on each contact's integrand: 1, and for the excused contacts 1 / (the product of the
        #: boosts the term's weight was given: `for_boost`), so that their effective weight stays put
        self.gain = np.ones(len(self.contacts))
        # site positions and velocities at all points from the engine's vectorized forward pass (shared
        # with penetration/torque/root/cone through the `PathContext`), gradients through its reverse
        # pass; an engine without site velocities (MuJoCo's inverse dynamics) is not shared
        self.engine = engine if engine is not None and engine.has_site_velocities else site_engine(model, CONTACT_SITES)
        self._eidx = _engine_index(self.engine, model, self.kin.names)
        self.needs = tuple(sorted({0, 1, *self.engine.required}))

    def for_boost(self, factor: float) -> Planted:
        """The term to use once penalty continuation multiplies its weight by `factor` (> 0): a shallow copy
        whose excused contacts' integrands are divided by `factor` (`gain`), so that only the contacts
        `violation` measures are stiffened (`solver.continuation`, module docstring). The keyframes hold an
        excused contact's site off its surface; a stiffer pull toward the surface there cannot reach the
        bound, and bends the leg between the keyframes to bring the site down (a knee straightened past
        its limit). The same term (`self`) when nothing is excused. Does not change `self`.
        """
        if not self.excused:
            return self
        new = copy.copy(self)
        new.gain = self.gain.copy()
        new.gain[sorted(self.excused)] /= float(factor)
        return new

    def knot_times(self) -> np.ndarray:
        """(2C,) every contact's start and end [s]: at touch-down and lift-off a site goes from
        moving to still and back, a change of its acceleration a spline can only follow with a knot
        there (`Term.knot_times`)."""
        return np.array([x for c in self.contacts for x in (c.start, c.end)], float)

    def windows(self, t: np.ndarray) -> np.ndarray:
        """(n, C) sliding window w of each contact at times t (read-only; the last times' are kept)."""
        return self._both(t)[1]

    def height_windows(self, t: np.ndarray) -> np.ndarray:
        """(n, C) height window s of each contact at times t: the closed contact (>= `windows`; read-only)."""
        return self._both(t)[0]

    def _both(self, t: np.ndarray):
        return last_for_times(self, "_window_cache", t, self._windows)

    def _span(self, c) -> tuple[float, float]:
        """[s] the part of contact c the term pulls: the contact, or the part a keyframe leaves to it
        (`held`; empty when lo >= hi)."""
        return self.excusals.held.get(c, (float(c.start), float(c.end)))

    def _windows(self, t: np.ndarray):
        if not self.contacts:
            return np.zeros((len(t), 0)), np.zeros((len(t), 0))
        # heights: the closed contact [start, end] (ramp 0); sliding: smoothstep ramps inside it
        spans = [self._span(c) for c in self.contacts]
        zero = np.zeros(len(t))
        S = np.stack([contact_window(t, a, b, 0.0) if b > a else zero for a, b in spans], 1)
        W = np.stack([contact_window(t, a, b, self.ramp) if b > a else zero for a, b in spans], 1)
        return S, W

    def _parts(self, p, v, S, rows):
        """Heights (m, C), tangential velocities (m, C, 3), normals (m, C, 3) of the contacts' sites,
        each contact's only where its height window S (m, C) is on (zero elsewhere: S h^2 and
        W |v_t|^2 are zero there anyway, as W <= S)."""
        m, C = len(rows), len(self.contacts)
        h = np.zeros((m, C))
        vt = np.zeros((m, C, 3))
        nrm = np.zeros((m, C, 3))
        for c in range(C):
            on = np.flatnonzero(S[:, c] > 0)
            pc = p[on, self._col[c]]
            hc, nc = self.support.height(pc, self._surf[c])
            h[on, c] = hc - self._h0[c]
            nrm[on, c] = nc
            if v is not None:
                vc = v[on, self._col[c]]
                vt[on, c] = vc - np.einsum("mi,mi->m", vc, nc)[:, None] * nc
        return h, vt, nrm

    def _pairs(self, t: np.ndarray):
        """The (point, contact) pairs where a contact's height window is on, at times t (read-only, kept
        for the last t): rows (r,) the points with any contact on; for each pair (P,), contact by
        contact and rows ascending within one: its row in rows (local), point (glob), contact (con),
        engine site index (site) and height and sliding windows (s, w); starts (C+1,) (contact c's
        pairs are [starts[c], starts[c+1])); unique: 1 if no two pairs share a point and site."""
        return last_for_times(self, "_pair_cache", t, self._make_pairs)

    def _make_pairs(self, t: np.ndarray):
        S, W = self._windows(t)
        rows = np.flatnonzero((S > 0).any(axis=1))
        on = [np.flatnonzero(S[rows, c] > 0) for c in range(len(self.contacts))]
        starts = np.cumsum([0] + [len(x) for x in on])
        local = np.concatenate(on).astype(int) if on else np.zeros(0, int)
        con = np.repeat(np.arange(len(on)), [len(x) for x in on]).astype(int)
        site = self._eidx[self._col[con]] if len(con) else np.zeros(0, int)
        glob = rows[local]
        unique = np.array([len(np.unique(glob * (site.max(initial=0) + 1) + site)) == len(glob)], int)
        return rows, local, glob, con, site, S[glob, con], W[glob, con], starts, unique

    def _pair_motion(self, ctx):
        """The engine's pass and, at the (point, contact) pairs of `_pairs`: the pairs, site velocities
        v (P, 3), heights above the rest height h (P,) [m] and surface normals nc (P, 3)."""
        mo, res = ctx.forward(self.engine, self.kin.tmap)
        pairs = self._pairs(np.asarray(ctx.t, float))
        rows, local, glob, con, site, s, w, starts, unique = pairs
        p, vc = res.sites[glob, site], self.engine.site_velocities(res)[glob, site]  # (P, 3)
        h, nc = np.empty(len(glob)), np.empty((len(glob), 3))
        for c in range(len(self.contacts)):
            a, b = starts[c], starts[c + 1]
            if a < b:
                h[a:b], nc[a:b] = self.support.height(p[a:b].copy(), self._surf[c])
        h -= self._h0[con]
        return mo, res, pairs, vc, h, nc

    def evaluate_in(self, ctx, grad=True) -> TermEval:
        """`Term.evaluate_in`: at all points at once, the gradient left to the engine's reverse pass
        (`EngineGradient`). Only at the (point, contact) pairs where a contact's height window is on
        (`_pairs`)."""
        mo, res, pairs, vc, h, nc = self._pair_motion(ctx)
        rows, local, glob, con, site, s, w, starts, unique = pairs
        vt = vc - np.einsum("mi,mi->m", vc, nc)[:, None] * nc
        t2 = self.tau * self.tau
        s, w = s * self.gain[con], w * self.gain[con]  # the excused contacts' gain (`for_boost`)
        T = np.zeros((len(rows), len(self.contacts)))  # each contact's integrand, zero where it is off
        T[local, con] = s * h * h + w * t2 * (vt * vt).sum(-1)
        f = np.zeros(len(ctx.Y))
        f[rows] = T.sum(1)
        if not grad:
            return TermEval(f)
        g_sites, g_vel = np.zeros(res.sites.shape), np.zeros(res.sites.shape)
        gp, gv = (2.0 * s * h)[:, None] * nc, (2.0 * t2 * w)[:, None] * vt
        if unique[0]:  # one pair per point and site
            g_sites[glob, site] += gp
            g_vel[glob, site] += gv
        else:  # contacts of one site overlapping: added in contact order
            np.add.at(g_sites, (glob, site), gp)
            np.add.at(g_vel, (glob, site), gv)
        return TermEval(f, deferred=EngineGradient(self.engine, res, mo, None, g_sites, g_vel))

    def residual(self, ctx) -> Residual:
        """r (n, 4 C) [m]: per contact c, sqrt(s_c) (h - h0) and sqrt(w_c) tau v_t (3 components),
        zero where the contact's height window is off (f = |r|^2). Jacobian-vector products through
        the engine's reverse pass: d h / d p = n, d v_t / d v = I - n n^T (n piecewise constant)."""
        mo, res, pairs, vc, h, nc = self._pair_motion(ctx)
        rows, local, glob, con, site, s, w, starts, unique = pairs
        vt = vc - np.einsum("mi,mi->m", vc, nc)[:, None] * nc
        gain = self.gain[con]  # the excused contacts' gain (`for_boost`)
        ss, sw = np.sqrt(s * gain), np.sqrt(w * gain) * self.tau
        n, C = len(ctx.Y), len(self.contacts)
        r = np.zeros((n, C, 4))
        r[glob, con, 0] = ss * h
        r[glob, con, 1:] = sw[:, None] * vt

        def pull(g):
            g = g.reshape(n, C, 4)
            gh, gv = g[glob, con, 0], sw[:, None] * g[glob, con, 1:]
            g_sites, g_vel = np.zeros(res.sites.shape), np.zeros(res.sites.shape)
            np.add.at(g_sites, (glob, site), (ss * gh)[:, None] * nc)
            np.add.at(g_vel, (glob, site), gv - np.einsum("mi,mi->m", gv, nc)[:, None] * nc)
            return EngineGradient(self.engine, res, mo, None, g_sites, g_vel).pullback()

        dp, dv = np.zeros((n, C, 4, 3)), np.zeros((n, C, 4, 3))
        dp[glob, con, 0] = ss[:, None] * nc
        dv[glob, con, 1:] = sw[:, None, None] * (np.eye(3) - nc[:, :, None] * nc[:, None, :])
        sites = np.zeros(C, int)
        sites[con] = site  # each contact's engine site
        rows = SiteRows(ctx, self.engine, res, np.repeat(sites, 4), dp=dp.reshape(n, 4 * C, 3),
                        dv=dv.reshape(n, 4 * C, 3))
        return Residual(r.reshape(n, 4 * C), pull=pull, sites=rows)

    def residuals(self, t, Y, Y1=None):
        """Per sample and contact: height and sliding windows, height [m] and tangential speed [m/s]
        (velocity from Y1 if given, else by finite differences of the site positions along t).

        Returns:
            S (n, C), W (n, C), h - h0 (n, C), speed (n, C) (zero where the height window S is 0).
        """
        t = np.asarray(t, float)
        S, W = self._both(t)
        n, C = W.shape
        h = np.zeros((n, C))
        speed = np.zeros((n, C))
        rows = np.flatnonzero((S > 0).any(axis=1))
        if rows.size == 0:
            return S, W, h, speed
        if Y1 is not None:
            p, v, _, _ = self.kin.motion(Y[rows], Y1[rows], grad=False)
        else:
            P = self.kin.dense_positions(Y)
            v = np.gradient(P, t, axis=0)[rows]
            p = P[rows]
        hh, vt, _ = self._parts(p, v, S[rows], rows)
        h[rows], speed[rows] = hh, np.linalg.norm(vt, axis=-1)
        return S, W, h, speed

    def violation(self, Y: np.ndarray, t: np.ndarray | None = None) -> float | None:
        """Largest max(|h - h0|, tau |v_t|) [m] where a contact's sliding window w is full, i.e. not at
        the contact's ends, where the capture's own sites may already be up to 5 cm high (contacts end
        above 5 cm or 1 m/s, `solver.contacts`: 127_33's captured heel is 2.3-3.3 cm up in the last
        20 ms of its heel touch ending at 0.675 s, while the toe stays down). Velocities by finite differences of the samples. Times: `t`,
        else Y is taken as sampled evenly on `t_span`; None if neither is known or no sample is fully
        in contact."""
        t = _sample_times(Y, t, self.t_span)
        if t is None or not self.contacts:
            return None
        _, W, h, speed = self.residuals(t, Y)
        full = W >= FULL
        full[:, sorted(self.excused)] = False
        if not full.any():
            return None
        return float(np.max(np.where(full, np.maximum(np.abs(h), self.tau * speed), 0.0)))

    def _at_keyframes(self, times, qpos):
        """(S (k, C) whether each keyframe is in each contact: its closed interval [start, end], give or
        take KEYFRAME_AT_END for the files' 6 decimals; p (k, sites, 3) site positions, None if no
        keyframe is in a contact)."""
        times = np.asarray(times, float)
        S = np.zeros((len(times), len(self.contacts)), bool)
        for c, x in enumerate(self.contacts):
            S[:, c] = (times >= x.start - KEYFRAME_AT_END) & (times <= x.end + KEYFRAME_AT_END)
        return S, (self.kin.positions(np.asarray(qpos, float)) if S.any() else None)

    def conflicts(self, times, qpos, tolerance: float = KEYFRAME_TOLERANCE) -> ScheduleConflicts:
        """Keyframes that contradict the schedule's heights: a keyframe at time t in a contact (its
        closed interval [start, end], ends included, as in `slides`) whose site is more than
        `tolerance` [m] from the plant height h0 (keyframes are met exactly, so the term cannot pull
        that site down there). A query: the term is not changed.

        Args:
            times: (k,) keyframe times [s]. qpos: (k, nq) keyframe poses. tolerance: [m].
        Returns:
            ScheduleConflicts: found = (("planted", keyframe index, site, height - h0 [m]), ...), those
            contacts in `planted` (build the term with it to leave them out of `violation`: penalty
            continuation would raise the weight against a bound it cannot reach).
        """
        S, p = self._at_keyframes(times, qpos)
        found, excused = [], set()
        for c, contact in enumerate(self.contacts):
            if not S[:, c].any():
                continue
            h, _ = self.support.height(p[:, self._col[c]], self._surf[c])
            for i in np.flatnonzero(S[:, c] & (np.abs(h - self._h0[c]) > tolerance)):
                found.append(("planted", int(i), contact.site, float(h[i] - self._h0[c])))
                excused.add(contact)
        return ScheduleConflicts(found, planted=excused)

    def held(self, times, qpos, path, tolerance: float = KEYFRAME_TOLERANCE, rate: float = 480.0) -> ScheduleConflicts:
        """The part of each contact the keyframes leave to the term: where a keyframe inside a contact
        holds its site more than `tolerance` above or below the plant height (`conflicts`), the site is
        on its way up there (when the path through the keyframes rests longer before it than after it
        within the contact) or down (otherwise) - a heel
        rising through heel-off while its toe still pushes, which contact detection keeps in the contact
        up to 5 cm. The pull then stops where the path through the keyframes (the plain spline) leaves
        the tolerance on the way to that keyframe: pulling the site down right beside a keyframe that
        holds it up cannot succeed, and the optimizer paid for the attempt by turning the pelvis and
        legs elsewhere (docs/contacts.md "The contact terms"). A query: the term is not changed.

        Args:
            times: (k,) keyframe times [s]. qpos: (k, nq) keyframe poses. path: callable t (n,) ->
                (n, nq), the plain spline. tolerance: [m]. rate: [1/s] samples of the path per second.
        Returns:
            ScheduleConflicts: held = {contact: (lo, hi) [s]} for the contacts a keyframe contradicts
            (lo >= hi: nothing of the contact is left to the term).
        """
        S, p = self._at_keyframes(times, qpos)
        held = {}
        times = np.asarray(times, float)
        for c, contact in enumerate(self.contacts):
            keys = np.flatnonzero(S[:, c])
            if not len(keys):
                continue
            h, _ = self.support.height(p[keys, self._col[c]], self._surf[c])
            off = keys[np.abs(h - self._h0[c]) > tolerance]
            if not len(off):
                continue
            a, b = float(contact.start), float(contact.end)
            ts = np.linspace(a, b, max(3, int(np.ceil((b - a) * rate)) + 1))
            hs, _ = self.support.height(self.kin.positions(np.asarray(path(ts), float))[:, self._col[c]], self._surf[c])
            ok = np.abs(hs - self._h0[c]) <= tolerance
            lo, hi = a, b
            for k in off:
                tk = float(times[k])
                before, after = ts[(ts < tk) & ok], ts[(ts > tk) & ok]
                if len(before) >= len(after):  # on its way up: the pull ends where the path last rests
                    hi = min(hi, float(before.max()) if len(before) else a)
                else:  # on its way down: it starts where the path first rests after the keyframe
                    lo = max(lo, float(after.min()))
            held[contact] = (lo, hi)
        return ScheduleConflicts(held=held)

    def slides(self, times, qpos, tolerance: float = KEYFRAME_TOLERANCE) -> ScheduleConflicts:
        """Keyframes that make a planted site slide: two keyframes in one contact (its closed interval
        [start, end]: a keyframe at a contact's start or end counts, the natural way to write one) that
        hold the site more than `tolerance` [m] apart horizontally (capture's feet roll and pivot: 2-4 cm
        on the walk; no path can then keep the site still). A query: the term is not changed.

        Returns:
            ScheduleConflicts: found = (("sliding", index of the later keyframe, site, largest horizontal
            distance [m]), ...), those contacts in `planted` (left out of `violation` when the term is
            built with it; the term still pulls toward no sliding).
        """
        S, p = self._at_keyframes(times, qpos)
        found, excused = [], set()
        for c, contact in enumerate(self.contacts):
            inside = np.flatnonzero(S[:, c])
            if len(inside) < 2:
                continue
            xy = p[inside, self._col[c], :2]
            spread = float(np.max(np.linalg.norm(xy[:, None] - xy[None], axis=-1)))
            if spread > tolerance:
                found.append(("sliding", int(inside[-1]), contact.site, spread))
                excused.add(contact)
        return ScheduleConflicts(found, planted=excused)
