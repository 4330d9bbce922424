"""The quadrature points: the midpoint rule's integrals, with the spline's knots as points of weight 0, and
Simpson's rule on a clean's frames."""
import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from solver.errors import InputError
from solver.quadrature import MAX_QUADRATURE_POINTS, quadrature_points, quadrature_times, simpson_points


def test_knots_are_points_of_weight_zero_and_integrals_are_the_midpoint_rules():
    knots = np.array([0.0, 0.25, 0.5 + 0.005, 0.9, 1.3])  # 0.505 is a midpoint of the 100/s rule
    t, w = quadrature_points(0.0, 1.3, 100, knots)
    tm, h = quadrature_times(0.0, 1.3, 100)
    assert np.all(np.diff(t) > 0)
    assert np.all(np.isin(knots, t))
    assert len(t) == len(tm) + 4  # 0.505 is already a point: not twice
    np.testing.assert_allclose(w[w > 0], h, rtol=1e-15)
    assert np.count_nonzero(w == 0) == 4
    np.testing.assert_allclose(t[w > 0], tm, rtol=0, atol=1e-15)
    # the midpoint rule integrates a linear function exactly: int_0^1.3 (2 + 3 s) ds
    assert abs(w @ (2 + 3 * t) - (2 * 1.3 + 1.5 * 1.3 ** 2)) < 1e-12


def test_a_cubic_splines_peak_acceleration_is_seen_at_the_points():
    """A cubic's acceleration is linear between knots, so the points (knots included) see its peak over
    a 10 kHz grid; the midpoint rule's points alone miss it by up to half an interval's change."""
    rng = np.random.default_rng(5)
    knots = np.sort(np.concatenate([[0.0, 2.0], rng.uniform(0.05, 1.95, 8)]))
    s = CubicSpline(knots, rng.normal(size=(10, 3)), bc_type="natural")
    dense = np.linspace(0.0, 2.0, 20001)
    peak = np.linalg.norm(s(dense, 2), axis=1).max()
    t, _ = quadrature_points(0.0, 2.0, 100, knots)
    assert np.linalg.norm(s(t, 2), axis=1).max() >= peak * (1 - 1e-12)
    tm, _ = quadrature_times(0.0, 2.0, 100)
    assert np.linalg.norm(s(tm, 2), axis=1).max() < peak  # without the knots: the peak is missed


def test_a_pointwise_bound_prices_a_knots_pair_like_its_neighbours():
    """A knot's point adds nothing to an integral (weight 0) but a pointwise bound there is priced by one
    spacing, as at every other point: the method of multipliers must feel a jolt at a keyframe."""
    from solver.constraints.base import Constraint

    t, w = quadrature_points(0.0, 1.0, 100, [0.0, 0.333, 1.0])
    c = Constraint()
    c.rows = np.arange(len(t))
    np.testing.assert_allclose(c.pair_weights(w), 0.01, rtol=1e-12)
    assert abs(w.sum() - 1.0) < 1e-12


def test_simpson_points_integrate_a_piecewise_cubic_exactly_on_uneven_frames():
    """Simpson's rule is exact for a cubic on each interval: a continuous piecewise cubic with a knot at every
    one of uneven frames (scipy's not-a-knot spline through random values) integrates to its antiderivative's
    difference; its square, a sextic, does not (the check can fail)."""
    rng = np.random.default_rng(11)
    frames = np.cumsum(np.r_[0.0, rng.uniform(0.01, 0.05, 12)])
    p = CubicSpline(frames, rng.normal(size=13))
    t, w = simpson_points(frames)
    assert np.all(np.diff(t) > 0) and np.all(np.isin(frames, t))
    assert abs(w.sum() - (frames[-1] - frames[0])) < 1e-15
    exact = float(p.integrate(frames[0], frames[-1]))
    assert abs(w @ p(t) - exact) <= 1e-12 * max(1.0, abs(exact))
    xg, wg = np.polynomial.legendre.leggauss(4)  # Gauss-Legendre, 4 nodes an interval: exact to degree 7
    h = np.diff(frames)
    tg = (frames[:-1, None] + 0.5 * h[:, None] * (xg + 1)).ravel()
    sextic = float(((0.5 * h[:, None] * wg).ravel()) @ p(tg) ** 2)
    assert abs(w @ p(t) ** 2 - sextic) > 1e-6 * abs(sextic)


def test_simpson_points_integrate_a_natural_splines_squared_acceleration_exactly():
    """A natural cubic spline's acceleration is linear between its knots, so |q''|^2 is quadratic there and
    the rule at the knots and midpoints gives the integral Gauss-Legendre with 2 nodes an interval (exact to
    degree 3, other points) gives."""
    rng = np.random.default_rng(2)
    frames = np.sort(np.r_[0.0, 1.0, rng.uniform(0.05, 0.95, 20)])
    s = CubicSpline(frames, rng.normal(size=(22, 3)), bc_type="natural")
    t, w = simpson_points(frames)
    xg, wg = np.polynomial.legendre.leggauss(2)
    h = np.diff(frames)
    tg = (frames[:-1, None] + 0.5 * h[:, None] * (xg + 1)).ravel()
    exact = float((0.5 * h[:, None] * wg).ravel() @ (s(tg, 2) ** 2).sum(axis=1))
    assert abs(w @ (s(t, 2) ** 2).sum(axis=1) - exact) <= 1e-12 * exact


def test_simpson_points_refuse_more_frames_than_the_points_allow():
    """2m - 1 points for m frames: one frame more than the limit allows is named with the fix, in one line."""
    m = (MAX_QUADRATURE_POINTS + 1) // 2
    assert len(simpson_points(np.arange(m) / 120.0)[0]) == 2 * m - 1 <= MAX_QUADRATURE_POINTS
    with pytest.raises(InputError, match=f"{m + 1} frames need {2 * m + 1} quadrature points") as e:
        simpson_points(np.arange(m + 1) / 120.0)
    assert "in parts" in str(e.value) and "\n" not in str(e.value)


def test_simpson_points_in_panels_integrate_a_piecewise_cubic_exactly_and_keep_the_frames():
    """Composite Simpson over several panels of an interval is exact for a cubic on each panel, so for a
    piecewise cubic with a knot at every frame (scipy's spline, its antiderivative the reference); every frame
    is a point at the index two panels count to, the points are the panels' ends and midpoints, equally spaced
    within each interval; one panel each is the plain rule to the last bit."""
    rng = np.random.default_rng(4)
    frames = np.cumsum(np.r_[0.0, rng.uniform(0.01, 0.05, 9)])
    panels = np.array([1, 2, 4, 1, 8, 2, 3, 1, 5])
    p = CubicSpline(frames, rng.normal(size=10))
    t, w = simpson_points(frames, panels)
    assert len(t) == 2 * panels.sum() + 1 and np.all(np.diff(t) > 0)
    np.testing.assert_array_equal(t[np.r_[0, 2 * np.cumsum(panels)]], frames)
    for i, k in enumerate(panels):
        inside = t[2 * panels[:i].sum(): 2 * panels[: i + 1].sum() + 1]
        np.testing.assert_allclose(np.diff(inside), (frames[i + 1] - frames[i]) / (2 * k), rtol=1e-12)
    exact = float(p.integrate(frames[0], frames[-1]))
    assert abs(w @ p(t) - exact) <= 1e-12 * max(1.0, abs(exact))
    one_t, one_w = simpson_points(frames, np.ones(len(panels), int))
    plain_t, plain_w = simpson_points(frames)
    np.testing.assert_array_equal(one_t, plain_t)
    np.testing.assert_array_equal(one_w, plain_w)
