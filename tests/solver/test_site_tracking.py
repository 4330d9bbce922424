"""The tracking bound (solver/constraints/tracking.py): a known answer against MuJoCo's kinematics, the gradient
against central differences, its bound against the plain spline and the capture sampled by scipy and MuJoCo,
and where it is posed (a keyed path with a capture; not a clean, not without a capture).

Known answer: the figure moved rigidly by a translation delta (its root's position) moves every site by delta,
so every site is |delta| from where it was and the mean distance is |delta|.
"""
import mujoco
import numpy as np
import pytest
from scipy.interpolate import CubicSpline

import solver
from solver.constraints.base import RELATIVE_TOLERANCE
from solver.constraints.tracking import SiteTracking
from solver.inverse_dynamics import InverseDynamics
from solver.kinematics import TangentMap, mujoco_site_positions
from solver.least_change import build_least_change
from solver.path_state import PathState

from conftest import shipped_standing


@pytest.fixture(scope="module")
def figure():
    model, keyframes, info, layout, q = shipped_standing()
    sites = solver.Figure.from_model(model).contact_sites
    return model, layout, q, InverseDynamics(model, sites), sites, keyframes, info


def _state(figure, t, Y, Y1=None, Y2=None):
    model, layout, _, engine, *_ = figure
    Y1 = np.zeros_like(Y) if Y1 is None else Y1
    Y2 = np.zeros_like(Y) if Y2 is None else Y2
    return PathState(t, Y, Y1, Y2, TangentMap.from_layout(layout), engine)


def _mujoco_sites(model, sites, qpos: np.ndarray) -> np.ndarray:
    """(n, k, 3) the sites' world positions [m] by `mj_kinematics` (`solver.kinematics.mujoco_site_positions`,
    independent of the solver's vectorized kinematics)."""
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s) for s in sites]
    return mujoco_site_positions(model, mujoco.MjData(model), ids, qpos)


def test_a_figure_moved_rigidly_is_as_far_as_the_move(figure):
    model, _, q, _, sites, *_ = figure
    n = 7
    t = np.linspace(0.0, 0.3, n)
    w = np.full(n, 0.05)  # [s]
    delta = np.array([0.03, -0.04, 0.012])  # [m]
    target = _mujoco_sites(model, sites, np.tile(q, (n, 1)))
    moved = np.tile(q, (n, 1))
    moved[:, 0:3] += delta  # the free root's position
    c = SiteTracking(w, target, bound=0.04)
    np.testing.assert_allclose(c.measure(_state(figure, t, moved)), [np.linalg.norm(delta)], rtol=1e-9)
    # the limit sits a whole relative tolerance below the bound (and round-off's allowance above that)
    np.testing.assert_allclose(c.limit, [0.04 * (1 - RELATIVE_TOLERANCE)], rtol=1e-7)
    np.testing.assert_allclose(c.tolerance, 0.04 * RELATIVE_TOLERANCE, rtol=1e-12)


def test_tracking_gradient_matches_finite_differences(figure):
    model, _, q, _, sites, *_ = figure
    rng = np.random.default_rng(7)
    n = 10
    t = np.linspace(0.0, 0.45, n)
    w = rng.uniform(0.02, 0.06, size=n)  # [s] unequal quadrature weights
    Y = np.tile(q, (n, 1)) + rng.normal(size=(n, model.nq)) * 0.05
    target = _mujoco_sites(model, sites, np.tile(q, (n, 1))) + rng.normal(size=(n, len(sites), 3)) * 0.02
    c = SiteTracking(w, target, bound=0.05)
    g = np.array([0.7])
    st = _state(figure, t, Y)
    c.pull(st, g.copy())
    G = st.pullback()[0]  # d/dY; the sites do not depend on Y' or Y''
    d = rng.normal(size=Y.shape)
    eps = 1e-6
    num = float(g @ (c.values(_state(figure, t, Y + eps * d)) - c.values(_state(figure, t, Y - eps * d)))) / (2 * eps)
    # central differences: truncation O(eps^2) on distances of centimetres
    assert float((G * d).sum()) == pytest.approx(num, rel=1e-6, abs=1e-9)


def test_the_bound_is_the_plain_splines_distance_from_the_capture(figure):
    """With a capture the keyed problem holds its contact sites to the plain spline's mean distance from the
    capture's, both natural cubic splines through their frames (scipy) placed by MuJoCo (the plain spline's
    frames: the keyframes, a partial keyframe's free components filled by `build_least_change`)."""
    model, layout, q, _, sites, keyframes, info = figure
    times = np.arange(keyframes.times[0] - 0.1, keyframes.times[-1] + 0.1, 1.0 / 60.0)
    rng = np.random.default_rng(3)
    capture = np.tile(q, (len(times), 1)) + 0.02 * np.sin(np.outer(times, rng.uniform(1, 4, model.nq)))
    lc = build_least_change(model, keyframes, contacts=info.contacts, flights=info.flights,
                            capture=(times, capture))
    (c,) = [c for c in lc.al.constraints if c.name == "tracking"]
    t = lc.al.t
    plain = CubicSpline(lc.plain.times, lc.plain.values, bc_type="natural")(t)  # the keyframes, partial ones filled
    captured = CubicSpline(times, capture, bc_type="natural")(t)
    dist = np.linalg.norm(_mujoco_sites(model, sites, plain) - _mujoco_sites(model, sites, captured), axis=2)
    w = c.w  # the quadrature weights of the points
    bound = float(w @ dist.mean(axis=1) / w.sum())
    assert bound > 0.01  # [m] the keyed figure stands centimetres from this capture
    np.testing.assert_allclose(c.limit, [bound * (1 - RELATIVE_TOLERANCE)], rtol=1e-7)
    assert c.priority == next(a.priority for a in lc.al.constraints if a.name == "acceleration")


def test_no_tracking_bound_without_a_capture_or_in_a_clean(figure):
    model, _, q, _, sites, keyframes, info = figure
    lc = build_least_change(model, keyframes, contacts=info.contacts, flights=info.flights)
    assert "tracking" not in [c.name for c in lc.al.constraints]
    from solver.displacement import build_displacement

    times = np.arange(0.0, 0.5, 1.0 / 60.0)
    qpos = np.tile(q, (len(times), 1))
    disp = build_displacement(model, times, qpos)
    assert "tracking" not in [c.name for c in disp.lc.al.constraints]
