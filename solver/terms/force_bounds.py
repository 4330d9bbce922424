"""forces: the ground force and the pelvis acceleration held within what a body shows (docs/dynamics.md).

The root term (sec. 6, appendix A) asks for a ballistic flight; without a bound the cheapest way there
is a push-off and a landing no body makes. This soft constraint (the paper's penalty form, sec. 5) is a
one-sided quadratic penalty on each quadrature point's excess over the problem's `PeakBounds`
(`solver.peak_bounds`: the larger of the plain spline's and the filtered capture's peaks):

    f = e_F^2 + e_a^2,   e_F = max(0, |F| / W - B_F),   e_a = max(0, |x''| - B_a) / g   [body weights^2]

with F the contact-free root force (the free root's first 3 generalized forces of the inverse dynamics,
world frame) [N], W = m g the figure's weight [N], x'' the root position's second derivative [m/s^2],
g = |gravity|: an acceleration counts in g, so 1 g of excess costs as much as one body weight.
The force part applies on the ground and in flight alike (in flight the root term asks for F = 0, far
below the bound): no flight indicator the optimizer could lift the feet to switch off. f is C1 (a
squared hinge). Its weight is absolute: it is not renormalized (eq. 7; `renormalized = False`), since
it is zero on the plain spline up to rounding.

Peaks between the quadrature points: the spline's Y'' is linear between its knots (eq. 2-6), so the
pelvis acceleration peaks at a knot, and the optimizer can raise it there between two quadrature points
(on run-and-step: 16.8 m/s^2 at knots while the points held 16.4). At the start of each round
(`prepare`, with the frame times from `set_knots`) each knot's value is extrapolated linearly from the
two nearest points on either side within its segment (exact for x'', to O(h^2) for F), and the point
nearest the knot on each side carries the excess of that value over its own as a slack s >= 0 for the
round: e = max(0, |x| + s - B). The slack is lagged (fixed during a round, like the root term's flight
indicator), so the term stays pointwise and its residual exact.

Gradients: e_F through the shared inverse-dynamics engine's reverse pass (deferred, summed with the
torque, root and cone terms' adjoints), e_a directly in Y''. `residual` gives r = (e_F, e_a) (n, 2) for
the least-squares back end.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from solver.errors import InputError
from solver.kinematics import TangentMap
from solver.layout import StateLayout
from solver.path_context import EngineGradient, PathContext
from solver.terms.base import Residual, Term, TermEval
from solver.terms.contact_schedule import _sample_times


@dataclass(frozen=True)
class PeakBounds:
    """The largest ground force and pelvis acceleration one problem's optimized path may show.

    Attributes:
        ground_force_bw: bound on the root force |F| / (m g) [body weights]: the larger of the plain
            spline's peak and the capture's peak on the ground.
        pelvis_acceleration_ms2: bound on |x''| of the root [m/s^2], the larger of the two peaks.
        plain_ground_force_bw: the plain spline's peak |F| / (m g) over all its samples (on the ground,
            and in flight, where the root term asks for 0: so that the `forces` term is zero on the
            plain spline and keeps its own units, eq. 7).
        plain_pelvis_acceleration_ms2: the plain spline's peak [m/s^2].
        capture_ground_force_bw, capture_pelvis_acceleration_ms2: the filtered capture's peaks on the
            ground and over the keyframes' span, or None without a capture.
        cutoff_hz: the capture filter's cutoff [Hz].
    """

    ground_force_bw: float
    pelvis_acceleration_ms2: float
    plain_ground_force_bw: float
    plain_pelvis_acceleration_ms2: float
    capture_ground_force_bw: float | None = None
    capture_pelvis_acceleration_ms2: float | None = None
    cutoff_hz: float = 6.0

    def as_dict(self) -> dict:
        """The fields as a JSON-ready dict."""
        return asdict(self)

    def describe(self) -> str:
        """One line: the two bounds and where they come from."""
        cap = ("no capture" if self.capture_ground_force_bw is None else
               f"capture {self.capture_ground_force_bw:.2f} body wt, {self.capture_pelvis_acceleration_ms2:.1f} m/s^2 "
               f"(filtered at {self.cutoff_hz:g} Hz)")
        return (f"force bounds: ground {self.ground_force_bw:.2f} body wt, pelvis {self.pelvis_acceleration_ms2:.1f} "
                f"m/s^2 = max(plain {self.plain_ground_force_bw:.2f} body wt, {self.plain_pelvis_acceleration_ms2:.1f} "
                f"m/s^2; {cap})")


class PeakForces(Term):
    """f = e_F^2 + e_a^2 [body weights^2]: root force and pelvis acceleration beyond their bounds (module
    docstring).

    Args:
        model: MjModel of the scene (a figure with a free root; gravity not zero).
        bounds: `PeakBounds` (`solver.peak_bounds.peak_bounds`: ground_force_bw [body weights], pelvis_acceleration_ms2
            [m/s^2]), or None: the peaks of the path the solve starts from (the plain spline), read at the
            quadrature points by the first `prepare` (until then the term is 0 and has no violation).
        engine: an inverse-dynamics engine (`solver.terms.dynamics.make_engine`) to share with the other
            dynamics terms; default a new one.
        t_span: (t0, t1) [s] the keyframe interval (for `violation` on evenly spaced samples).
    Raises:
        InputError: no free joint, no gravity, bounds that are not finite and >= 0.
    """

    name = "forces"
    units = "body weights^2"
    needs = (0, 1, 2)
    fixed_points = True  # the knots' slack is kept per quadrature point (`prepare`)
    renormalized = False  # a bound: its weight is absolute (`Objective.renormalize`)

    def __init__(self, model, bounds, engine=None, t_span=None):
        from solver.terms.dynamics import _free_joint, make_engine

        self.layout = StateLayout.from_model(model)
        self.tmap = TangentMap.from_layout(self.layout)
        root = _free_joint(model, self.layout)
        adr, qadr = int(model.jnt_dofadr[root]), int(model.jnt_qposadr[root])
        self.force_dofs = np.arange(adr, adr + 3)
        self.root_pos = np.arange(qadr, qadr + 3)
        self.g = float(np.linalg.norm(model.opt.gravity))
        if not self.g > 0:
            raise InputError("the forces term measures force in body weights; the model's gravity is zero")
        self.weight_N = float(np.sum(model.body_mass)) * self.g
        for label, value in (() if bounds is None else (("ground force", bounds.ground_force_bw),
                                                         ("pelvis acceleration", bounds.pelvis_acceleration_ms2))):
            if not (np.isfinite(value) and value >= 0):
                raise InputError(f"the forces term's {label} bound is {value}; it must be finite and >= 0")
        self.bounds = bounds
        self.engine = engine if engine is not None else make_engine(model, ())
        self.t_span = t_span
        self._knots: np.ndarray | None = None
        self._slack: tuple[np.ndarray, np.ndarray] | None = None  # (t (n,), slack (n, 2)) from `prepare`

    def peaks(self, t, Y, Y1, Y2) -> tuple[np.ndarray, np.ndarray]:
        """Per sample: |F| / W [body weights] and |x''| [m/s^2] ((n,) each; t (n,) [s], Y* (n, nq))."""
        _, res = PathContext(t, Y, Y1, Y2).forward(self.engine, self.tmap)
        F = res.tau[:, self.force_dofs]
        return np.linalg.norm(F, axis=1) / self.weight_N, np.linalg.norm(Y2[:, self.root_pos], axis=1)

    def set_knots(self, knots: np.ndarray) -> None:
        """The spline's frame times (m,) [s] for the next `prepare` (`Objective.prepare` calls it)."""
        self._knots = np.asarray(knots, float)

    def prepare(self, t, Y, Y1, Y2) -> None:
        """At a round's start, on the path at the quadrature points t (n,) [s], Y* (n, nq): the knots'
        slack (module docstring); without bounds, also the bounds: the peaks of this path (the first
        round's start, the plain spline)."""
        _, res = PathContext(t, Y, Y1, Y2).forward(self.engine, self.tmap)
        X = (res.tau[:, self.force_dofs] / self.weight_N, Y2[:, self.root_pos])
        if self.bounds is None:
            force, acc = (float(np.linalg.norm(x, axis=1).max()) for x in X)
            self.bounds = PeakBounds(force, acc, force, acc)
        self._slack = (np.array(t, float), knot_slack(np.asarray(t, float), self._knots, X))

    def _slack_at(self, t) -> np.ndarray | None:
        """The slack (n, 2) if `prepare` was called for these quadrature points, else None."""
        got = self._slack
        if got is None or t is None or np.shape(t) != got[0].shape or not np.array_equal(t, got[0]):
            return None
        return got[1]

    def _excess(self, ctx):
        """(motion, result, e (n, 2), unit directions dF (n, 3) of F and da (n, 3) of x'')."""
        mo, res = ctx.forward(self.engine, self.tmap)
        F = res.tau[:, self.force_dofs]
        a = ctx.Y2[:, self.root_pos]
        nF, na = np.linalg.norm(F, axis=1), np.linalg.norm(a, axis=1)
        bF, ba = (np.inf, np.inf) if self.bounds is None else (self.bounds.ground_force_bw,
                                                              self.bounds.pelvis_acceleration_ms2)
        s = self._slack_at(ctx.t)
        sF, sa = (0.0, 0.0) if s is None else (s[:, 0], s[:, 1])
        e = np.stack([np.maximum(nF / self.weight_N + sF - bF, 0.0), np.maximum(na + sa - ba, 0.0) / self.g], axis=1)
        uF = F / np.where(nF > 0, nF, 1.0)[:, None]
        ua = a / np.where(na > 0, na, 1.0)[:, None]
        return mo, res, e, uF, ua

    def _pull(self, ctx, mo, res, ge, uF, ua):
        """(dY2 (n, nq), EngineGradient) of sum ge . e, ge (n, 2) (zero where e is 0)."""
        g_tau = np.zeros(res.tau.shape)
        g_tau[:, self.force_dofs] = (ge[:, 0] / self.weight_N)[:, None] * uF
        dY2 = np.zeros(ctx.Y.shape)
        dY2[:, self.root_pos] = (ge[:, 1] / self.g)[:, None] * ua
        return dY2, EngineGradient(self.engine, res, mo, g_tau)

    def evaluate_in(self, ctx, grad=True) -> TermEval:
        """`Term.evaluate_in`: the force part's gradient left to the engine's reverse pass."""
        mo, res, e, uF, ua = self._excess(ctx)
        f = (e * e).sum(axis=1)
        if not grad:
            return TermEval(f)
        dY2, deferred = self._pull(ctx, mo, res, 2.0 * e, uF, ua)
        return TermEval(f, dY2=dY2, deferred=deferred)

    def residual(self, ctx) -> Residual:
        """r = (e_F, e_a) (n, 2) [body weights] (f = |r|^2); vector-Jacobian products through the
        engine's reverse pass (force) and Y'' (acceleration); a hinge's derivative is 0 where it is 0."""
        mo, res, e, uF, ua = self._excess(ctx)

        def pull(g):
            dY2, deferred = self._pull(ctx, mo, res, np.asarray(g) * (e > 0), uF, ua)
            dY, dY1, dY2e = deferred.pullback()
            return dY, dY1, dY2 if dY2e is None else dY2 + dY2e

        return Residual(e, pull=pull)

    def violation(self, Y: np.ndarray, t: np.ndarray | None = None) -> float | None:
        """The largest excess over the bounds [body weights; the acceleration's in g]: max over the
        samples of max(|F| / W - B_F, (|x''| - B_a) / g, 0); Y', Y'' by finite differences of the
        samples (times: `t`, else even on `t_span`; None if unknown or without bounds)."""
        t = _sample_times(Y, t, self.t_span)
        if t is None or len(Y) < 3 or self.bounds is None:
            return None
        Y1 = np.gradient(Y, t, axis=0, edge_order=2)
        Y2 = np.gradient(Y1, t, axis=0, edge_order=2)
        force, acc = self.peaks(t, Y, Y1, Y2)
        return float(max(np.max(force) - self.bounds.ground_force_bw,
                         (np.max(acc) - self.bounds.pelvis_acceleration_ms2) / self.g, 0.0))


def knot_slack(t: np.ndarray, knots: np.ndarray | None, X: tuple) -> np.ndarray:
    """How far each quantity's norm rises from a quadrature point to the spline knot next to it.

    For every knot, from each side: the value at the knot extrapolated linearly from the two points
    nearest it within the segment on that side, x(k) = x_1 + (x_1 - x_2) (k - t_1) / (t_1 - t_2), and
    the slack of the nearer point t_1: |x(k)| - |x_1| where positive (the largest over its knots).

    Args:
        t: (n,) quadrature times [s], increasing. knots: (m,) the spline's frame times [s], or None.
        X: a tuple of c arrays (n, 3) (vectors at the points).
    Returns:
        (n, c) slack >= 0 (zeros without knots).
    """
    slack = np.zeros((len(t), len(X)))
    if knots is None or len(t) < 2:
        return slack
    seg = np.searchsorted(knots, t, side="right")  # points with seg == j lie between knots j-1 and j
    for j, k in enumerate(knots):
        for side in (j, j + 1):  # the segment ending at the knot, the one starting there
            pts = np.flatnonzero(seg == side)
            if len(pts) < 2:
                continue
            near, far = (pts[-1], pts[-2]) if side == j else (pts[0], pts[1])
            c = (k - t[near]) / (t[near] - t[far])
            for q, x in enumerate(X):
                rise = np.linalg.norm(x[near] + c * (x[near] - x[far])) - np.linalg.norm(x[near])
                slack[near, q] = max(slack[near, q], rise)
    return slack
