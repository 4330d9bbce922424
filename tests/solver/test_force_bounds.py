"""The force bounds of `--terms all` (solver/constraints/forces.py): known answers and gradients.

Known answers: a rigid figure thrown (the root on a parabola under gravity, no rotation) needs no
external wrench, so the flight bound is met with |F| = 0; the same figure held still on the ground needs
exactly its weight, straight up (F = (0, 0, m g), inside the cone, pushing). Gradients against central
differences.
"""
import numpy as np
import pytest

import solver
from solver.constraints.forces import FORCE_TOLERANCE, FlightWrench, GroundForce, figure_forces
from solver.inverse_dynamics import InverseDynamics
from solver.kinematics import TangentMap
from solver.path_state import PathState

from conftest import shipped_standing


@pytest.fixture(scope="module")
def figure():
    model, _, _, layout, q = shipped_standing()
    engine = InverseDynamics(model, solver.Figure.from_model(model).contact_sites)
    return model, layout, q, engine


def _state(figure, t, Y, Y1, Y2):
    model, layout, _, engine = figure
    return PathState(t, Y, Y1, Y2, TangentMap.from_layout(layout), engine)


def _weight(model):
    return float(np.sum(model.body_mass)) * float(np.linalg.norm(model.opt.gravity))


def test_thrown_rigid_figure_needs_no_wrench_and_a_still_one_its_weight(figure):
    model, layout, q, _ = figure
    t = np.linspace(0.0, 0.3, 7)
    g = np.asarray(model.opt.gravity)
    v0 = np.array([1.5, 0.2, 2.0])  # [m/s] a running take-off
    Y = np.tile(q, (len(t), 1))
    Y1, Y2 = np.zeros_like(Y), np.zeros_like(Y)
    Y[:, :3] += t[:, None] * v0 + 0.5 * t[:, None] ** 2 * g
    Y1[:, :3] = v0 + t[:, None] * g
    Y2[:, :3] = g
    thrown = _state(figure, t, Y, Y1, Y2)
    cs = figure_forces(model, t, [(-1.0, 1.0)])
    assert [type(c) for c in cs] == [FlightWrench, GroundForce] and cs[1].size == 0
    # |F| = 0 exactly up to rounding: the smoothed norm is 0 there (1e-6 of the tolerance)
    assert np.abs(cs[0].measure(thrown) / cs[0].tolerance).max() < 1e-6

    still = _state(figure, t, np.tile(q, (len(t), 1)), np.zeros_like(Y), np.zeros_like(Y))
    W = _weight(model)
    (ground,) = figure_forces(model, t, [], peak_bw=1.0)
    m = ground.measure(still).reshape(len(t), 3)
    np.testing.assert_allclose(m[:, 0], -W, rtol=1e-9)  # pull: -F_z = -W
    np.testing.assert_allclose(m[:, 1], -0.8 * W, rtol=1e-9, atol=1e-6 * W)  # friction: 0 - mu W
    d = FORCE_TOLERANCE * W  # the smoothing width of the norms
    np.testing.assert_allclose(m[:, 2], np.hypot(W, d) - d, rtol=1e-9)  # peak: |F| = W (smoothed), its bound
    assert np.all(ground.values(still) <= ground.tolerance)


def test_force_bound_gradients_match_finite_differences(figure):
    model, layout, q, _ = figure
    rng = np.random.default_rng(3)
    n = 12
    t = np.linspace(0.0, 0.5, n)
    Y = np.tile(q, (n, 1)) + rng.normal(size=(n, model.nq)) * 0.05
    Y1 = rng.normal(size=Y.shape)
    Y2 = rng.normal(size=Y.shape) * 10.0
    W = _weight(model)
    cs = figure_forces(model, t, [(0.2, 0.4)], peak_bw=0.5)
    for c in cs:
        w = rng.normal(size=c.size)
        st = _state(figure, t, Y, Y1, Y2)
        c.pull(st, w.copy())
        gY, gY1, gY2 = st.pullback()
        for G, k in ((gY, 0), (gY1, 1), (gY2, 2)):
            d = rng.normal(size=Y.shape)
            eps = 1e-6
            args = [Y, Y1, Y2]
            hi = [a + eps * d if i == k else a for i, a in enumerate(args)]
            lo = [a - eps * d if i == k else a for i, a in enumerate(args)]
            num = (w @ c.values(_state(figure, t, *hi)) - w @ c.values(_state(figure, t, *lo))) / (2 * eps)
            # central differences, truncation O(eps^2); forces of order W
            assert float((G * d).sum()) == pytest.approx(num, rel=1e-5, abs=1e-6 * W), (c.name, k)
    assert FORCE_TOLERANCE * W < 10.0  # the tolerance is a few newtons for a 70 kg figure
