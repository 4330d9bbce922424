"""The contact sites no further from the capture than the plain spline keeps them (keyframes from a capture).

    (1/T) integral (1/k) sum_s |x_s(t) - x*_s(t)| dt  <=  B - tol,   tol = RELATIVE_TOLERANCE B      [m]

x_s the path's contact site s (a heel, a toe), x*_s the capture's (the motion the keyframes came from, the
natural spline through its frames), k the contact sites, T the path's length, and B the plain spline's own
figure: the mean per-site position error against the reference (`runner.motion_metrics` site_position_cm: mean
per-joint position error, taken on the contact sites), held as a limit. The contact constraints move the feet,
and nothing else in the least change knows where the capture put them: a foot planted or kept from sliding
could settle further from the capture's stance than the plain spline's in-betweens stray (on four pairs of
83_02 and 05_09, keyed every 0.2-0.33 s and at contacts, 2-23 % further).

The tolerance is the relative one of every bound read off a reference's own figure (`RELATIVE_TOLERANCE`), and
the limit lies a whole tolerance below B, so that met (within the tolerance) means at most B: the acceptance's
"below the plain spline's" on any machine. (Half a tolerance below, a solve that stopped with every pair met
ended 1.8 % above B on 83_02 keyed every 0.2 s with OpenBLAS's Sandybridge kernel.) The plain spline then
sits on the tolerance's edge, and it must stay met there: the least change of a plain spline that meets every
constraint is itself. So the limit is raised by `ROUND_OFF` of B, which round-off in the plain spline's figure
(sampled by another spline evaluation than the solve's) cannot reach.

One integral constraint: one pair standing for the path's whole length. |d| has a kink at d = 0, where a
full keyframe puts the path on the capture; a keyframe's values are fixed, so no variable moves a site there
and the gradient is taken as 0.
"""
from __future__ import annotations

import numpy as np

from solver.constraints.base import RELATIVE, RELATIVE_TOLERANCE, Constraint

__all__ = ["ROUND_OFF", "SiteTracking", "mean_site_distance"]

#: [1] the limit's allowance for round-off, relative to B (module docstring): the square root of double
#: precision's epsilon (1.5e-8), the customary allowance for round-off in a computed quantity, far above that
#: of a mean of thousands of distances and far below any figure a user reads; not a tuned number
ROUND_OFF = float(np.sqrt(np.finfo(float).eps))


def mean_site_distance(sites: np.ndarray, target: np.ndarray, weights: np.ndarray) -> float:
    """The mean distance of the sites from the target's, (1/T) sum_i w_i (1/k) sum_s |sites[i, s] - target[i, s]|
    [m], of (n, k, 3) positions [m] at quadrature weights (n,) [s], T = sum w."""
    d = np.linalg.norm(sites - target, axis=2)
    return float(weights @ d.mean(axis=1) / weights.sum())


class SiteTracking(Constraint):
    """The contact sites' mean distance from the capture's <= the plain spline's [m] (module docstring).

    Args:
        weights: (n,) quadrature weights [s]. target: (n, k, 3) the capture's contact sites at the points [m],
            in the order of the engine's sites. bound: B [m] > 0, the plain spline's figure.
    Raises:
        ValueError: bound is not a positive number.
    """

    name, unit, scale = "tracking", "mm", 1e-3
    priority = RELATIVE

    def __init__(self, weights: np.ndarray, target: np.ndarray, bound: float):
        if not (np.isfinite(bound) and bound > 0):
            raise ValueError(f"the tracking bound must be a positive distance [m], got {bound!r}")
        self.w = np.asarray(weights, float)
        self.T = float(self.w.sum())
        self.target = np.asarray(target, float)
        self.rows = np.array([len(self.w) // 2])
        self.labels = np.array(["contact sites"], object)
        self.tolerance = RELATIVE_TOLERANCE * float(bound)
        self.limit = np.array([float(bound) * (1.0 + ROUND_OFF) - self.tolerance])

    def pair_weights(self, weights):
        """The one pair stands for the whole path [s]."""
        return np.array([float(np.sum(weights))])

    def _offsets(self, state):
        """(d (n, k, 3) [m], |d| (n, k, 1) [m]): the sites less the capture's, once per state (`measure` and
        `pull` of one evaluation share them)."""
        key = ("tracking", id(self))
        hit = state.cache.get(key)
        if hit is None:
            d = state.sites - self.target
            state.cache[key] = hit = (d, np.linalg.norm(d, axis=2, keepdims=True))
        return hit

    def measure(self, state):
        r = self._offsets(state)[1][..., 0]
        return np.array([float(self.w @ r.mean(axis=1) / self.T)])

    def pull(self, state, g):
        if not g.any():
            return
        d, r = self._offsets(state)
        unit = np.divide(d, r, out=np.zeros_like(d), where=r > 0.0)  # 0 on the capture (a keyframe: fixed)
        state.add_sites(float(g[0]) * (self.w / (self.T * d.shape[1]))[:, None, None] * unit)
