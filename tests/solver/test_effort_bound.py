"""The effort bound (solver/constraints/effort.py): known answers against MuJoCo, the gradient against
central differences, the bound's composition, and the order in which limits give when the solve stalls.

Known answer: a figure held still in a pose needs only the torques that hold it against gravity, which
MuJoCo's `mj_inverse` gives with qvel = qacc = 0; the RMS of the joints' (not the root's) components over
time is then that vector's norm.
"""
import mujoco
import numpy as np
import pytest

import solver
from solver.constraints.effort import TorqueRMS
from solver.inverse_dynamics import InverseDynamics, constraint_free_copy
from solver.kinematics import TangentMap
from solver.least_change import build_least_change
from solver.path_state import PathState

from conftest import shipped_standing


@pytest.fixture(scope="module")
def figure():
    model, keyframes, info, layout, q = shipped_standing()
    engine = InverseDynamics(model, solver.Figure.from_model(model).contact_sites)
    dofs = np.array([j.dofadr + i for j in layout.joints if j.kind != "free" for i in range(j.nv)], int)
    return model, layout, q, engine, dofs, keyframes, info


def _state(figure, t, Y, Y1, Y2):
    model, layout, _, engine, *_ = figure
    return PathState(t, Y, Y1, Y2, TangentMap.from_layout(layout), engine)


def _still_capture(keyframes, q, fps=120.0):
    """A capture of the figure standing still in pose q over the keyframes' span (and 0.2 s beyond)."""
    times = np.arange(keyframes.times[0] - 0.2, keyframes.times[-1] + 0.2, 1.0 / fps)
    return times, np.tile(q, (len(times), 1))


def _gravity_torques(model, q, dofs) -> np.ndarray:
    m = constraint_free_copy(model)
    data = mujoco.MjData(m)
    data.qpos[:] = q
    data.qvel[:] = 0.0
    data.qacc[:] = 0.0
    mujoco.mj_inverse(m, data)
    return np.array(data.qfrc_inverse[dofs])


def test_a_still_figure_needs_mujocos_gravity_torques(figure):
    model, layout, q, _, dofs, *_ = figure
    n = 9
    t = np.linspace(0.0, 0.4, n)
    w = np.full(n, 0.05)  # [s]
    still = _state(figure, t, np.tile(q, (n, 1)), np.zeros((n, model.nq)), np.zeros((n, model.nq)))
    c = TorqueRMS(w, dofs, bound=10.0, tolerance=0.5)
    expected = np.linalg.norm(_gravity_torques(model, q, dofs))
    assert expected > 1.0  # [N m] a standing figure's hips and knees carry weight
    np.testing.assert_allclose(c.measure(still), [expected], rtol=1e-9)
    np.testing.assert_allclose(c.values(still), [expected - 10.0], rtol=1e-9)


def test_effort_gradient_matches_finite_differences(figure):
    model, layout, q, _, dofs, *_ = figure
    rng = np.random.default_rng(5)
    n = 12
    t = np.linspace(0.0, 0.5, n)
    w = rng.uniform(0.02, 0.06, size=n)  # [s] unequal quadrature weights
    Y = np.tile(q, (n, 1)) + rng.normal(size=(n, model.nq)) * 0.05
    Y1 = rng.normal(size=Y.shape)
    Y2 = rng.normal(size=Y.shape) * 10.0
    c = TorqueRMS(w, dofs, bound=50.0, tolerance=2.5)
    g = np.array([1.3])
    st = _state(figure, t, Y, Y1, Y2)
    c.pull(st, g.copy())
    grads = st.pullback()
    for G, k in zip(grads, range(3)):
        d = rng.normal(size=Y.shape)
        eps = 1e-6
        args = [Y, Y1, Y2]
        hi = [a + eps * d if i == k else a for i, a in enumerate(args)]
        lo = [a - eps * d if i == k else a for i, a in enumerate(args)]
        num = float(g @ (c.values(_state(figure, t, *hi)) - c.values(_state(figure, t, *lo)))) / (2 * eps)
        # central differences: truncation O(eps^2); the RMS is tens of N m
        assert float((G * d).sum()) == pytest.approx(num, rel=1e-5, abs=1e-6), k


@pytest.fixture(scope="module")
def captured(figure):
    """The shipped clip's problem with a still capture: the effort and no-jolt bounds join."""
    model, _, q, _, _, keyframes, info = figure
    lc = build_least_change(model, keyframes, contacts=info.contacts, flights=info.flights, rate=200.0,
                            capture=_still_capture(keyframes, q))
    return lc


def test_the_bound_is_the_larger_of_the_plain_splines_and_the_captures(figure, captured):
    model, layout, q, _, dofs, *_ = figure
    lc = captured
    (effort,) = [c for c in lc.al.constraints if c.name == "effort"]
    ref = lc.al.change.ref
    Y1, Y2 = (np.asarray(lc.plain.path(ref.t, nu)) for nu in (1, 2))
    plain = TorqueRMS(ref.weights, dofs, 1.0, 1.0).measure(_state(figure, ref.t, ref.qpos, Y1, Y2))[0]
    still = float(np.linalg.norm(_gravity_torques(model, q, dofs)))
    np.testing.assert_allclose(effort.limit, [max(plain, still)], rtol=1e-6)
    np.testing.assert_allclose(effort.tolerance, 0.05 * max(plain, still), rtol=1e-12)  # the no-jolt bounds' 5 %
    built = build_least_change(model, figure[5], contacts=figure[6].contacts, flights=figure[6].flights, rate=200.0)
    assert "effort" not in [c.name for c in built.al.constraints]  # without a capture: no bound
