"""The reference motion a solve changes as little as it can: its pose, acceleration and mass matrix at the
quadrature points (docs/design.md "The problem").

The reference is a path Y_ref(t) of the figure's `qpos`. Today it is the plain spline through the
keyframes (`ReferenceMotion.from_frames`); a captured clip can be one as well (`from_samples`: the
natural cubic spline through its frames), which is the interface a cleanup mode that tracks every frame
of a capture uses. What the measure of change (`solver.change`) reads is computed here once per
problem, at the fixed quadrature points: qpos, MuJoCo's `qacc` (`solver.kinematics.TangentMap`), and
the lower Cholesky factor L of the joint-space mass matrix M(q_ref) (MuJoCo's composite rigid body
algorithm, `mj_crb` and `mj_fullM`), so that (a - a_ref)^T M (a - a_ref) = |L^T (a - a_ref)|^2.
"""
from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from solver.errors import InputError
from solver.frames import FrameSet
from solver.kinematics import TangentMap
from solver.layout import StateLayout
from solver.spline import interpolate

__all__ = ["ReferenceMotion", "equal_mass_matrices", "mass_matrices", "mass_matrix_factors"]


def mass_matrices(model, qpos: np.ndarray) -> np.ndarray:
    """The joint-space mass matrix at each pose (MuJoCo's composite rigid body algorithm, `mj_crb`).

    Args:
        model: mujoco.MjModel (not modified). qpos: (n, nq) poses (quaternions normalized here).
    Returns:
        (n, nv, nv) M(qpos) [kg, kg m, kg m^2 by block].
    Raises:
        InputError: qpos does not fit the model.
    """
    q = _normalized(model, qpos)
    data = mujoco.MjData(model)
    M = np.zeros((len(q), model.nv, model.nv))
    for i, y in enumerate(q):
        data.qpos[:] = y
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        mujoco.mj_crb(model, data)
        _full_m(model, data, M[i])
    return M


def mass_matrix_factors(model, qpos: np.ndarray) -> np.ndarray:
    """The lower Cholesky factors of the joint-space mass matrix at each pose (`mass_matrices`).

    Args:
        model: mujoco.MjModel (not modified). qpos: (n, nq) poses (quaternions normalized here).
    Returns:
        (n, nv, nv) L with L L^T = M(qpos) [kg, kg m, kg m^2 by block].
    Raises:
        InputError: qpos does not fit the model.
    """
    return np.linalg.cholesky(mass_matrices(model, qpos))


def equal_mass_matrices(model, qpos: np.ndarray) -> np.ndarray:
    """The joint-space mass matrix of the figure with its mass spread equally over its bodies, at each pose.

    Every body of mass m_k > 0 is given the figure's mean body mass m / b (b bodies with mass) and its
    rotational inertia scaled by the same factor (m / b) / m_k, so its radius of gyration is kept:
    dq^T G dq is then (m / b) times the sum over the bodies of |dx_k|^2 + |dR_k|^2_k, the squared
    displacement of each body's centre of mass and its rotation weighted by its own radius of gyration.
    Every body counts alike, as the field's mean per-joint position error (MPJPE: Ionescu et al.,
    "Human3.6M", TPAMI 36(7), 2014) counts every joint; moving the whole figure costs its mass, as in M.
    Positive definite wherever M is: every degree of freedom moves some body.

    Args:
        model: mujoco.MjModel (not modified: a copy is changed). qpos: (n, nq) poses.
    Returns:
        (n, nv, nv) G [kg, kg m, kg m^2 by block].
    Raises:
        InputError: qpos does not fit the model.
    """
    import copy

    equal = copy.deepcopy(model)
    m = np.asarray(equal.body_mass, float)
    has = m > 0
    mean = float(m[has].sum()) / max(int(has.sum()), 1)
    scale = np.where(has, mean / np.where(has, m, 1.0), 0.0)
    equal.body_mass[:] = m * scale
    equal.body_inertia[:] = np.asarray(equal.body_inertia) * scale[:, None]
    equal.dof_armature[:] = 0.0  # a motor's rotor inertia moves no body
    return mass_matrices(equal, qpos)


def _normalized(model, qpos: np.ndarray) -> np.ndarray:
    """(n, nq) qpos with its quaternions normalized; InputError where it does not fit the model."""
    qpos = np.atleast_2d(np.asarray(qpos, float))
    if qpos.shape[1] != model.nq:
        raise InputError(f"qpos has {qpos.shape[1]} components but the model has nq = {model.nq}")
    q = qpos.copy()
    for slot in StateLayout.from_model(model).quat_slots:
        q[:, slot] /= np.linalg.norm(q[:, slot], axis=1, keepdims=True)
    return q


def _full_m(model, data, out: np.ndarray) -> None:
    """The dense mass matrix into `out`: `mj_fullM(m, d, dst)` (MuJoCo 3.3.3 and later) or
    `mj_fullM(m, dst, d.qM)` (earlier 3.x)."""
    if hasattr(data, "qM"):
        mujoco.mj_fullM(model, out, data.qM)
    else:
        mujoco.mj_fullM(model, data, out)


@dataclass(frozen=True)
class ReferenceMotion:
    """A reference motion at the quadrature points (module docstring).

    Attributes:
        t: (n,) quadrature times [s]. weights: (n,) quadrature weights [s] (sum: the span).
        qpos: (n, nq) the reference's qpos (quaternions as the spline has them). qacc: (n, nv) its
            MuJoCo acceleration [m/s^2, rad/s^2].
        chol: (n, nv, nv) lower Cholesky factors of M(qpos) (`mass_matrix_factors`).
        span: (t0, t1) [s].
    """

    t: np.ndarray
    weights: np.ndarray
    qpos: np.ndarray
    qacc: np.ndarray
    chol: np.ndarray
    span: tuple

    @classmethod
    def from_frames(cls, model, frames: FrameSet, t: np.ndarray, weights: np.ndarray) -> ReferenceMotion:
        """The natural cubic spline through `frames` (the plain spline: `FrameSet.from_keyframes`).

        Args:
            model: MjModel of the figure's scene. frames: FrameSet, values (m, nq).
            t, weights: (n,) quadrature times [s] and weights [s].
        """
        return cls.from_samples(model, frames.times, frames.values, t, weights)

    @classmethod
    def from_samples(cls, model, times: np.ndarray, qpos: np.ndarray, t: np.ndarray,
                     weights: np.ndarray) -> ReferenceMotion:
        """The natural cubic spline through samples (a capture's frames, or frames of a spline).

        Args:
            model: MjModel. times: (k,) increasing [s]. qpos: (k, nq). t, weights: (n,) quadrature times
                [s] inside [times[0], times[-1]] and weights [s].
        Raises:
            InputError: shapes that do not fit the model, times outside the samples' span.
        """
        times, t = np.asarray(times, float), np.asarray(t, float)
        if np.asarray(qpos).shape[-1] != model.nq:
            raise InputError(f"reference qpos has {np.asarray(qpos).shape[-1]} components but the model has nq = {model.nq}")
        if t.min() < times[0] - 1e-9 or t.max() > times[-1] + 1e-9:
            raise InputError(f"quadrature points {t.min():g}..{t.max():g} s outside the reference's "
                             f"{times[0]:g}..{times[-1]:g} s")
        Y, Y1, Y2 = interpolate(times, qpos, t, (0, 1, 2))
        tmap = TangentMap.from_layout(StateLayout.from_model(model))
        qacc = np.ascontiguousarray(tmap.motion(Y, Y1, Y2).qacc)
        return cls(t, np.asarray(weights, float), Y, qacc, mass_matrix_factors(model, Y),
                   (float(times[0]), float(times[-1])))

    @property
    def duration(self) -> float:
        """[s] the reference's span."""
        return self.span[1] - self.span[0]
