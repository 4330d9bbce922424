"""The pose metric of a clean (`solver.reference.equal_mass_matrices`): the mass matrix of the figure with its
mass spread equally over its bodies, checked against the bodies' own displacements.

dq^T G dq must equal sum_k (m / b) |dc_k|^2 + dtheta_k^T (s_k I_k) dtheta_k over the bodies, dc_k the
displacement of body k's centre of mass and dtheta_k its rotation for a step dq, I_k its inertia in the
world frame and s_k = (m / b) / m_k: computed here from MuJoCo's forward kinematics alone (central
differences of `xipos` and `ximat` along dq, `mj_integratePos`), not from the composite rigid body
algorithm the code uses. A translation of the free root moves every body alike: it costs the figure's
mass, as in the mass matrix; the measure of change with this metric prices a known change of the root by
that mass.
"""
import mujoco
import numpy as np
import pytest

import solver
from solver.change import MeasureOfChange
from solver.kinematics import TangentMap
from solver.layout import StateLayout
from solver.path_state import PathState
from solver.reference import ReferenceMotion, equal_mass_matrices
from solver.spline import interpolate


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


def test_moving_the_root_costs_the_figures_mass(shipped):
    """D of x(t) = A sin(pi (t - t0) / T) added to the root's x with this pose metric: the root's acceleration
    changes by -A (pi/T)^2 sin(...) and every body moves by x(t), so D = sum_i w_i (a_i^2 + omega^4 x_i^2) m,
    m the figure's mass, in both parts."""
    model, keyframes = shipped
    layout = StateLayout.from_model(model)
    tmap = TangentMap.from_layout(layout)
    plain = solver.FrameSet.from_keyframes(keyframes, layout.quat_slots)
    t0, t1, n = plain.times[0], plain.times[-1], 200
    h = (t1 - t0) / n
    t = t0 + h * (np.arange(n) + 0.5)
    ref = ReferenceMotion.from_frames(model, plain, t, np.full(n, h))
    omega = 3.0
    change = MeasureOfChange(ref, tmap, omega=omega, pose=equal_mass_matrices(model, ref.qpos))
    Y, Y1, Y2 = interpolate(plain.times, plain.values, t, (0, 1, 2))
    A, k = 0.01, np.pi / (t1 - t0)
    s = np.sin(k * (t - t0))
    Y, Y1, Y2 = Y.copy(), Y1.copy(), Y2.copy()
    Y[:, 0] += A * s
    Y1[:, 0] += A * k * np.cos(k * (t - t0))
    Y2[:, 0] += -A * k * k * s
    mass = float(np.sum(model.body_mass))
    expected = float(np.sum(h * ((A * k * k * s) ** 2 + omega ** 4 * (A * s) ** 2) * mass))
    assert change.evaluate(PathState(t, Y, Y1, Y2, tmap), grad=False) == pytest.approx(expected, rel=1e-9)
