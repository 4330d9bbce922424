"""The curvature a constraint or the measure of change gives the Gauss-Newton preconditioner
(`solver.gauss_newton`), in factored form at the quadrature points.

A `Curvature` is sum over its points i of F_i^T K_i F_i in the path's tangent at the point (its pose, qvel
and qacc: orders 0, 1, 2), F_i = [F_i^0, F_i^1, F_i^2] the derivative of k quantities by each order on a few
degrees of freedom (`support`) and K_i (k, k) symmetric positive semidefinite: a Gauss-Newton matrix
J^T W J (Nocedal & Wright, Numerical Optimization, 2nd ed., sec. 10.3). An `Outer` is a sum of rank-one
terms d2_p g_p g_p^T whose vectors g_p each span many points (an integral constraint's pair), kept apart
because they are not banded, and computed exactly: an error e in such a stiff direction leaves curvature
e^2 d2 |g|^2, which a penalty's d2 makes large.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Curvature", "Outer", "quaternion_dofs"]


@dataclass(frozen=True)
class Curvature:
    """sum_i F_i^T K_i F_i (module docstring).

    Attributes:
        points: (q,) quadrature point of each term. support: (s,) the qvel indices F acts on, or (q, s) each
            term's own.
        factors: {order r: (q, k, s)} F^r [the quantity's unit per rad or m (r = 0), per rad/s or m/s (1),
            per rad/s^2 or m/s^2 (2)]; or {"qpos": (q, k, s_q)}: the derivative by the qpos components
            `qpos_support` ((s_q,) or (q, s_q)) themselves, for a quantity that sees a quaternion's norm, which
            the tangent does not (the preconditioner maps it by the frames' own quaternions). K: (q, k, k) [Phi
            per quantity squared].
    """

    points: np.ndarray
    support: np.ndarray
    factors: dict
    K: np.ndarray
    qpos_support: np.ndarray | None = None


@dataclass(frozen=True)
class Outer:
    """sum_p d2_p g_p g_p^T, g_p the gradient of the pair's value c_p, which spans many points (module
    docstring); the preconditioner computes each g_p exactly by the constraint's own reverse pass (`pull`),
    one pass for pairs that share no point.

    Attributes:
        constraint: the Constraint. points: (q,) quadrature point of each term. pair: (q,) the pair of each
            term. d2: (p,) [Phi per the pair's unit squared] >= 0.
    """

    constraint: object
    points: np.ndarray
    pair: np.ndarray
    d2: np.ndarray


def quaternion_dofs(tmap, quats: np.ndarray) -> np.ndarray:
    """(q, 3) the qvel indices of each quaternion given by its qpos indices `quats` (q, 4) (a `TangentMap`'s
    `quat_q` and `quat_v`): the support of a `Curvature` whose "qpos" factor is on those components."""
    v_of = {tuple(int(x) for x in qq): vv for qq, vv in zip(tmap.quat_q, tmap.quat_v)}
    return np.array([v_of[tuple(int(x) for x in q)] for q in np.asarray(quats)])
