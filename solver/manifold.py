"""The optimizer's variables of a frame set: free components, with each free quaternion moved on its sphere.

A frame's quaternion q (not necessarily unit: frames inserted by subdivision carry the path's value,
whose norm the spline does not keep at 1) is moved by a rotation vector delta in its body frame,

    q(delta) = q0 (x) exp(delta),   exp(delta) = (cos(|delta|/2), sin(|delta|/2) delta/|delta|),

the "boxplus" of a quaternion manifold (Hertzberg et al., "Integrating generic sensor fusion algorithms
with sound state representations through encapsulation of manifolds", Information Fusion 14, 2013;
Sola et al., "A micro Lie theory for state estimation in robotics", 2018, eq. 15). So the optimizer has
three variables per free quaternion, the three rotational degrees of freedom MuJoCo's `qvel` has, in the
same units (rad about the child's local axes): |q| is kept as it is, and no unit-norm term is needed
for the figure (the paper's eq. 9 f1 fixes the radial direction with a penalty; here it is not a
variable). Root positions and the components of a quaternion a partial keyframe fixes only in part are
variables as they are.
"""
from __future__ import annotations

import numpy as np

from solver.frames import FrameSet
from solver.quaternion import left_matrix, mul

__all__ = ["FrameVariables", "exp_rotation", "exp_rotation_vjp"]

#: [rad] below this |delta| the series of sin(x/2)/x is used (its relative error there is below 1e-17)
_SMALL = 1e-4


def exp_rotation(delta: np.ndarray) -> np.ndarray:
    """exp(delta) = (cos(t/2), sin(t/2) delta/t), t = |delta|: the unit quaternion of a rotation vector.

    Args:
        delta: (..., 3) rotation vectors [rad].
    Returns:
        (..., 4) unit quaternions (w, x, y, z).
    """
    delta = np.asarray(delta, float)
    t = np.linalg.norm(delta, axis=-1)
    small = t < _SMALL
    ts = np.where(small, 1.0, t)
    s = np.where(small, 0.5 - t * t / 48.0, np.sin(0.5 * ts) / ts)
    return np.concatenate([np.cos(0.5 * t)[..., None], s[..., None] * delta], axis=-1)


def exp_rotation_vjp(delta: np.ndarray, h: np.ndarray) -> np.ndarray:
    """h^T d exp(delta) / d delta, the product with the (4, 3) Jacobian of `exp_rotation` without forming it: with
    t = |delta|, s = sin(t/2)/t and ds = (cos(t/2) t/2 - sin(t/2)) / t^3 (= s'(t)/t), d cos(t/2) = -s delta / 2 and
    d (s delta) = s I + ds delta delta^T, so the product is -h_w s delta / 2 + s h_xyz + ds (h_xyz . delta) delta
    (series in t below `_SMALL`).

    Args:
        delta: (r, 3) rotation vectors [rad]. h: (r, 4) the adjoint of exp(delta).
    Returns:
        (r, 3).
    """
    t = np.linalg.norm(delta, axis=-1)
    small = t < _SMALL
    ts = np.where(small, 1.0, t)
    half = 0.5 * ts
    s = np.where(small, 0.5 - t * t / 48.0, np.sin(half) / ts)
    ds = np.where(small, -1.0 / 24.0 + t * t / 960.0, (np.cos(half) * half - np.sin(half)) / ts ** 3)
    hv = h[:, 1:]
    coef = ds * np.einsum("rk,rk->r", hv, delta) - 0.5 * s * h[:, 0]
    return s[:, None] * hv + coef[:, None] * delta


class FrameVariables:
    """x (n,) <-> the frame values of a frame set (module docstring), around the set's current values: a
    linear variable is the change of its component, a rotation variable the rotation vector delta.

    Args:
        frames: FrameSet; its values are the base q0 (x = 0 gives them back).
        quat_slots: (s, 4) qpos indices of the quaternions (`StateLayout.quat_slots`).
    Attributes:
        size: n, the number of variables.
        base: (m, nq) the frame values at x = 0.
    """

    def __init__(self, frames: FrameSet, quat_slots: np.ndarray):
        self.frames = frames
        self.base = np.array(frames.values, float)
        free = np.asarray(frames.free, bool)
        slots = np.asarray(quat_slots, int).reshape(-1, 4)
        whole = free[:, slots].all(axis=2) if slots.size else np.zeros((len(free), 0), bool)  # (m, s)
        self._rows, self._slot = np.nonzero(whole)  # the free quaternions: frame and slot
        self._idx = slots[self._slot]  # (r, 4) their qpos indices
        lin = free.copy()
        lin[self._rows[:, None], self._idx] = False
        self._lin = lin
        self._q0 = self.base[self._rows[:, None], self._idx]  # (r, 4)
        self._L0 = left_matrix(self._q0)  # (r, 4, 4)
        self.n_linear = int(lin.sum())
        self.size = self.n_linear + 3 * len(self._rows)

    def values(self, x: np.ndarray) -> np.ndarray:
        """(m, nq) the frame values at x (n,)."""
        P = self.base.copy()
        P[self._lin] += x[: self.n_linear]
        if len(self._rows):
            d = x[self.n_linear:].reshape(-1, 3)
            P[self._rows[:, None], self._idx] = mul(self._q0, exp_rotation(d))
        return P

    def frame_set(self, x: np.ndarray) -> FrameSet:
        """The FrameSet at x (the base's times, masks and keyframes)."""
        f = self.frames
        return FrameSet(f.times, self.values(x), f.fixed, f.is_keyframe)

    def pullback(self, x: np.ndarray, G: np.ndarray) -> np.ndarray:
        """dE/dx (n,) from dE/dP (m, nq) at x (the chain rule through `values`)."""
        out = np.empty(self.size)
        out[: self.n_linear] = G[self._lin]
        if len(self._rows):
            d = x[self.n_linear:].reshape(-1, 3)
            g = G[self._rows[:, None], self._idx]  # (r, 4)
            h = (g[:, None, :] @ self._L0)[:, 0, :]  # (r, 4): g^T L0, the adjoint of exp(d) (q = L0 exp(d))
            out[self.n_linear:] = exp_rotation_vjp(d, h).ravel()
        return out

    def quaternion_frames(self) -> tuple[np.ndarray, np.ndarray]:
        """(rows (r,), slots (r,)): frame and quaternion-slot index of each rotation variable (in x order,
        three variables each after the n_linear linear ones)."""
        return self._rows, self._slot

    def linear_mask(self) -> np.ndarray:
        """(m, nq) bool: the components that are variables as they are (in x order: row-major)."""
        return self._lin
