"""Staying near the plain spline where nothing asks to leave it (docs/corpus.md "Near the plain spline").

The plain spline through the keyframes is the animator's motion; the soft constraints (penetration,
planted, clearance, the anatomical limits) say where it must change. Every departure the optimizer
makes elsewhere - a pelvis tilted or a hip turned to buy a little of a constraint's residual or of
the covariant acceleration - moves the motion away from the keyframes' intent, and on the corpus away
from the capture the keyframes came from. `NearPlain` prices that departure: a proximal (Tikhonov)
term, the squared distance of the path from a reference path at every instant (Nocedal & Wright,
Numerical Optimization, 2nd ed., sec. 10.3 on regularized least squares; the proximal-point view:
Parikh & Boyd, Proximal Algorithms, 2014, sec. 1.1 and 4.1). It is zero on the plain spline, so
eq. 7 leaves it unnormalized: its weight is absolute, one unit of E per radian^2 of mean squared
departure summed over the joints.

Distance at one instant, in the tangent space of the configuration (as `mj_differentiatePos`
measures it, in radians and metres):

- every quaternion (the root's orientation and each ball joint): 2 sin(theta/2) of the rotation theta
  between the path's unit quaternion and the reference's - the vector 2 s vec(conj(p) q/|q|) with
  s = sign(p . q), whose length is theta to 1 % up to theta = 28 degrees and which is smooth
  everywhere but theta = 180 degrees - so the term adds up the joint-angle error the motion metrics
  report (a geodesic angle per joint, `solver.motion_metrics`);
- the root's position (and slide joints) in metres over a length `length` (default half the figure's
  standing height, about the leg's: a hip rotation of delta rad moves the foot by about length x
  delta, a root translation by dp moves it by dp, so both are priced by how far they move the feet);
  hinge joints in radians.

With a contact schedule the term is priced like the planted term (`renormalize_like="planted"`,
`Objective.renormalize`): each residual is multiplied by `length` instead of 1/sqrt(T), so a rotation of
delta rad costs what moving a point `length` x delta away for as long costs in the planted term's
currency (m^2 s over planted's plain-spline integral, eq. 7), and the root's translation is in metres.
The constraint terms are renormalized by their plain-spline values, which are tiny where the plain
spline through a capture's keys nearly meets them; an absolute weight per rad^2 was then hundreds of
times cheaper than a millimetre of their violation, and the optimizer turned the pelvis and hips by
10-15 degrees to buy one (docs/corpus.md "Near the plain spline").
"""
from __future__ import annotations

import numpy as np

from solver.errors import InputError
from solver.quaternion import conj, mul, vec_of_conj_product
from solver.terms.base import Residual, Term, TermEval

__all__ = ["NearPlain", "reference_length"]

#: reference paths kept per term (blocks of quadrature points of the uniform rule, or Gauss nodes)
_CACHE = 64


def reference_length(figure) -> float:
    """[m] the length a root translation is divided by: half the figure's standing height (about the
    leg's length; module docstring), or 0.85 m for a figure without one."""
    h = float(getattr(figure, "standing_height", 0.0) or 0.0)
    return 0.5 * h if np.isfinite(h) and h > 0 else 0.85


class NearPlain(Term):
    """f(t) = (1/T) sum_k |r_k(t)|^2 [rad^2/s]: the squared tangent-space distance of the path from a
    reference path (the plain spline through the keyframes), so that the integral is its mean over the
    keyframe interval of length T (the weight means the same on a short clip and a long one).

    r_k per joint (module docstring): 2 s vec(conj(p_k) q_k/|q_k|) for a quaternion q_k with the
    reference's p_k (3 rows, [rad]); (y_k - y_ref,k) / `length` for the root's position and slide
    joints ([m] / [m]); y_k - y_ref,k for hinge joints [rad].

    Args:
        layout: StateLayout of the model. reference: callable t (n,) [s] -> (n, nq) qpos of the
            reference path (e.g. `FrameSet.path` of the plain spline), or None: no reference, the term
            is zero (an objective built without keyframes, `figure_objective` without `plain`). t_span: (t0, t1) [s], T = t1 - t0.
        length: [m] > 0, the root translation's length scale (`reference_length`).
        renormalize_like: None (f averaged over the clip, weight per rad^2), or the name of the term
            whose eq. 7 scale this one takes (then r is multiplied by `length`, f in m^2; module docstring).
    Raises:
        InputError: a length that is not > 0, an empty interval.
    """

    name = "near"
    units = "rad^2/s"
    needs = (0,)
    pointwise = True

    def __init__(self, layout, reference, t_span, length: float = 0.85, renormalize_like: str | None = None):
        T = float(t_span[1]) - float(t_span[0])
        if not (np.isfinite(length) and length > 0):
            raise InputError(f"near term: length {length} m; it must be > 0 (e.g. half the figure's height)")
        if not (np.isfinite(T) and T > 0):
            raise InputError(f"near term: the keyframe interval {t_span} s is empty")
        self.reference, self.length, self.T = reference, float(length), T
        self.renormalize_like = renormalize_like
        #: residual factor: 1/sqrt(T) (the mean over the clip, absolute weight) or, priced like another
        #: term, `length` (a rotation of delta rad costs as a site moved length x delta for as long)
        self._c = 1.0 / np.sqrt(T) if renormalize_like is None else self.length
        self.slots = np.asarray(layout.quat_slots, int).reshape(-1, 4)
        lin, scale = [], []
        for j in layout.joints:
            if j.kind in ("free", "slide"):
                n = 3 if j.kind == "free" else 1
                lin += range(j.qposadr, j.qposadr + n)
                scale += [1.0 / self.length] * n
            elif j.kind == "hinge":
                lin.append(j.qposadr)
                scale.append(1.0)
        self.linear = np.asarray(lin, int)
        self.scale = np.asarray(scale, float)
        self._cache: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}

    def _ref(self, t: np.ndarray) -> np.ndarray:
        """(n, nq) the reference at t, kept for the next evaluation at the same points."""
        key = (len(t), float(t[0]), float(t[-1])) if len(t) else (0,)
        hit = self._cache.get(key)
        if hit is not None and np.array_equal(hit[0], t):
            return hit[1]
        Yr = np.asarray(self.reference(np.asarray(t, float)), float)
        if len(self._cache) >= _CACHE:
            self._cache.clear()
        self._cache[key] = (np.array(t, float), Yr)
        return Yr

    def _parts(self, t, Y):
        """Residuals (n, m) [rad] and what their Jacobian needs: per slot the unit quaternion u
        (n, s, 4), |q| (n, s, 1), the reference's unit quaternion p (n, s, 4), the factor k (n, s) =
        2 s / sqrt(T) and the slot's residual rows k vec(conj(p) u) (n, s, 3)."""
        Yr = self._ref(t)
        c = self._c
        r_lin = c * (Y[:, self.linear] - Yr[:, self.linear]) * self.scale
        q, p = Y[:, self.slots], Yr[:, self.slots]
        norm = np.linalg.norm(q, axis=-1, keepdims=True)
        u = q / norm
        p = p / np.linalg.norm(p, axis=-1, keepdims=True)
        k = np.where(np.einsum("nsi,nsi->ns", p, u) < 0, -2.0 * c, 2.0 * c)
        Gu = k[..., None] * mul(conj(p), u)[..., 1:]
        return np.concatenate([r_lin, Gu.reshape(len(Y), -1)], axis=1), u, norm, p, k, Gu

    def evaluate(self, t, Y, Y1, Y2, grad=True) -> TermEval:
        if self.reference is None:
            return TermEval(np.zeros(len(Y)), dY=np.zeros_like(Y) if grad else None)
        r, u, norm, p, k, Gu = self._parts(t, Y)
        f = np.einsum("nm,nm->n", r, r)
        if not grad:
            return TermEval(f)
        dY = np.zeros_like(Y)
        nl = len(self.linear)
        dY[:, self.linear] = 2.0 * r[:, :nl] * (self.scale * self._c)
        if len(self.slots):  # 2 r^T G (I - u u^T) / |q| with G = k G(p), r = G u; G(p)^T v = p (0, v)
            rG = k[..., None] * mul(p, np.concatenate([np.zeros(Gu.shape[:-1] + (1,)), Gu], axis=-1))
            rr = np.einsum("nsi,nsi->ns", Gu, Gu)
            dY[:, self.slots] = 2.0 * (rG - rr[..., None] * u) / norm
        return TermEval(f, dY=dY)

    def residual(self, ctx) -> Residual:
        """r as in the class docstring, (n, m) with m = (linear components) + 3 x (quaternion slots)
        [rad]; compact blocks: each linear component's own, and per slot the 3 rows over its 4 qpos
        components, G(p) (I - u u^T) / |q| with u = q/|q|."""
        Y = ctx.Y
        if self.reference is None:
            return Residual(np.zeros((len(Y), 0)), compact=[], nq=Y.shape[1])
        r, u, norm, p, k, Gu = self._parts(ctx.t, Y)
        G = k[..., None, None] * vec_of_conj_product(p)  # (n, s, 3, 4)
        n, nl = len(Y), len(self.linear)
        c = self.scale * self._c
        groups = [(np.array([i]), np.array([k]), (np.full((n, 1, 1), c[i]), None, None))
                  for i, k in enumerate(self.linear)]
        J = (G - Gu[..., :, None] * u[..., None, :]) / norm[..., None]  # G(p) (I - u u^T) / |q|
        for k, slot in enumerate(self.slots):
            groups.append((nl + 3 * k + np.arange(3), np.asarray(slot), (J[:, k], None, None)))
        return Residual(r, compact=groups, nq=Y.shape[1])
