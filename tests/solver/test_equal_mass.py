"""The pose metric of a clean (`solver.reference.equal_mass_matrices`): the mass matrix of the figure with its
mass spread equally over its bodies, checked against the bodies' own displacements.

dq^T G dq must equal sum_k (m / b) |dc_k|^2 + dtheta_k^T (s_k I_k) dtheta_k over the bodies, dc_k the
displacement of body k's centre of mass and dtheta_k its rotation for a step dq, I_k its inertia in the
world frame and s_k = (m / b) / m_k: computed here from MuJoCo's forward kinematics alone (central
differences of `xipos` and `ximat` along dq, `mj_integratePos`), not from the composite rigid body
algorithm the code uses (the measure of change with this metric on a known change of the root:
`tests/solver/test_least_change.py`).
"""
import mujoco
import numpy as np
import pytest

import solver
from solver.layout import StateLayout
from solver.reference import equal_mass_matrices


@pytest.fixture(scope="module")
def shipped():
    model = solver.load_model(solver.shipped("run_and_step.xml"))
    keyframes, _ = solver.read_keyframes(solver.shipped("run_and_step.keyframes.json"), model)
    return model, keyframes


def _rotation_vector(R: np.ndarray) -> np.ndarray:
    """(3,) the rotation vector of a rotation matrix (small angles: the skew part)."""
    return 0.5 * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])


def _bodies_moved(model, q: np.ndarray, dq: np.ndarray, eps: float) -> float:
    """sum_k (m / b) |dc_k|^2 + dtheta_k^T (s_k I_k) dtheta_k per unit step along dq (central differences)."""
    data = mujoco.MjData(model)
    frames = []
    for sign in (1.0, -1.0):
        qq = q.copy()
        mujoco.mj_integratePos(model, qq, sign * eps * dq, 1.0)
        data.qpos[:] = qq
        mujoco.mj_kinematics(model, data)
        frames.append((data.xipos.copy(), data.ximat.copy().reshape(-1, 3, 3)))
    (cp, Rp), (cm, Rm) = frames
    masses = np.asarray(model.body_mass, float)
    has = masses > 0
    mean = masses[has].sum() / has.sum()
    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    total = 0.0
    for k in np.flatnonzero(has):
        dc = (cp[k] - cm[k]) / (2 * eps)
        dth = _rotation_vector(Rp[k] @ Rm[k].T) / (2 * eps)
        R = data.ximat[k].reshape(3, 3)
        inertia = R @ np.diag(model.body_inertia[k]) @ R.T * (mean / masses[k])
        total += mean * dc @ dc + dth @ inertia @ dth
    return float(total)


def test_the_metric_is_the_bodies_displacement_with_equal_masses(shipped):
    model, keyframes = shipped
    q = keyframes.values[2].copy()
    for slot in StateLayout.from_model(model).quat_slots:
        q[slot] /= np.linalg.norm(q[slot])
    G = equal_mass_matrices(model, q[None])[0]
    rng = np.random.default_rng(7)
    for _ in range(3):
        dq = rng.normal(size=model.nv)
        assert dq @ G @ dq == pytest.approx(_bodies_moved(model, q, dq, 1e-6), rel=1e-6)
    assert np.all(np.linalg.eigvalsh(G) > 0)  # every degree of freedom moves some body
