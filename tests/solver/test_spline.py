"""The natural cubic spline (solver/spline.py) against independent references."""
import numpy as np
import pytest

from solver.errors import InputError
from solver.quadrature import quadrature_times
from solver.spline import interpolate, spline_matrices
from solver.spline_basis import SplineBasis


def naive_natural_spline(x, y, t):
    """Textbook natural cubic spline by second-derivative moments (tridiagonal system), no scipy."""
    n = len(x) - 1
    h = np.diff(x)
    A = np.zeros((n + 1, n + 1))
    r = np.zeros(n + 1)
    A[0, 0] = A[n, n] = 1.0
    for i in range(1, n):
        A[i, i - 1], A[i, i], A[i, i + 1] = h[i - 1], 2 * (h[i - 1] + h[i]), h[i]
        r[i] = 6 * ((y[i + 1] - y[i]) / h[i] - (y[i] - y[i - 1]) / h[i - 1])
    M = np.linalg.solve(A, r)
    k = np.clip(np.searchsorted(x, t, side="right") - 1, 0, n - 1)
    a, b = x[k + 1] - t, t - x[k]
    return (M[k] * a**3 + M[k + 1] * b**3) / (6 * h[k]) + (y[k] / h[k] - M[k] * h[k] / 6) * a + (
        y[k + 1] / h[k] - M[k + 1] * h[k] / 6
    ) * b


def test_matches_textbook_natural_spline():
    rng = np.random.default_rng(0)
    x = np.cumsum(rng.uniform(0.1, 0.5, 9))
    y = rng.normal(size=9)
    t = np.linspace(x[0], x[-1], 777)
    np.testing.assert_allclose(interpolate(x, y[:, None], t)[:, 0], naive_natural_spline(x, y, t), atol=1e-12)


def truncated_power_cubic(knots, tau, c, a, b):
    """p(t) = a + b t + sum c_i (t - tau_i)_+^3 and its first two derivatives: a C2 piecewise cubic."""

    def p(t, nu=0):
        d = np.maximum(t[:, None] - tau[None, :], 0.0)
        if nu == 0:
            return a + b * t + (c * d**3).sum(1)
        if nu == 1:
            return b + (3 * c * d**2).sum(1)
        return (6 * c * d).sum(1)

    return p


def test_reproduces_natural_piecewise_cubics_exactly():
    """A natural cubic spline is the unique C2 piecewise cubic through its frames with zero second
    derivative at both ends, so it must reproduce any such function built another way. Built here in
    the truncated-power basis (breaks at interior frames), with c chosen so p''(t_end) = 0."""
    knots = np.array([0.0, 0.3, 0.7, 1.0, 1.6, 2.0])
    tau = knots[1:-1]
    c = np.array([1.0, -2.0, 0.5, 0.0])
    c[-1] = -(c[:-1] * (knots[-1] - tau[:-1])).sum() / (knots[-1] - tau[-1])  # p''(end) = 0
    p = truncated_power_cubic(knots, tau, c, 0.3, -1.2)
    t = np.linspace(0, 2, 501)
    W, W1, W2 = spline_matrices(knots, t)
    P = p(knots)
    np.testing.assert_allclose(W @ P, p(t), atol=1e-12)
    np.testing.assert_allclose(W1 @ P, p(t, 1), atol=1e-11)
    np.testing.assert_allclose(W2 @ P, p(t, 2), atol=1e-10)


def test_reproduces_linear_polynomials_and_cubic_pieces():
    """Linear functions exactly (the only polynomials with zero end curvature); and on every
    segment the spline is exactly one cubic polynomial (fourth derivative zero: four samples
    determine it)."""
    knots = np.array([0.0, 0.2, 0.5, 0.6, 1.1])
    t = np.linspace(0, 1.1, 300)
    np.testing.assert_allclose(interpolate(knots, (2 - 3 * knots)[:, None], t)[:, 0], 2 - 3 * t, atol=1e-13)
    y = np.array([0.0, 1.0, -1.0, 0.5, 2.0])
    for a, b in zip(knots[:-1], knots[1:]):
        s = np.linspace(a, b, 4)
        coef = np.polyfit(s, interpolate(knots, y[:, None], s)[:, 0], 3)
        u = np.linspace(a, b, 50)
        np.testing.assert_allclose(interpolate(knots, y[:, None], u)[:, 0], np.polyval(coef, u), atol=1e-12)


def test_passes_through_frames_with_natural_ends_and_c2():
    rng = np.random.default_rng(1)
    knots = np.cumsum(rng.uniform(0.2, 0.6, 7))
    P = rng.normal(size=(7, 5))
    W, W1, W2 = spline_matrices(knots, knots)
    np.testing.assert_allclose(W @ P, P, atol=1e-13)
    np.testing.assert_allclose((W2 @ P)[[0, -1]], 0.0, atol=1e-10)
    # C2: fit each segment's cubic from 4 samples, compare value, slope, curvature at interior knots
    pieces = []
    for a, b in zip(knots[:-1], knots[1:]):
        s = np.linspace(a, b, 4)
        pieces.append(np.polyfit(s, interpolate(knots, P, s)[:, 0], 3))
    for k, left, right in zip(knots[1:-1], pieces[:-1], pieces[1:]):
        for nu in range(3):
            lv, rv = np.polyval(np.polyder(left, nu), k), np.polyval(np.polyder(right, nu), k)
            assert abs(lv - rv) <= 1e-7 * (1 + abs(lv)), (k, nu, lv, rv)


def test_basis_pullback_is_transpose():
    rng = np.random.default_rng(2)
    knots = np.array([0.0, 0.4, 1.0, 1.3])
    t, h = quadrature_times(0.0, 1.3, 100)
    assert np.isclose(h * len(t), 1.3) and t[0] > 0 and t[-1] < 1.3
    B = SplineBasis(knots, t)
    P = rng.normal(size=(4, 3))
    g = [rng.normal(size=(len(t), 3)) for _ in range(3)]
    Y = B.evaluate(P)
    lhs = sum((a * b).sum() for a, b in zip(Y, g))
    rhs = (B.pullback(*g) * P).sum()
    assert np.isclose(lhs, rhs)


def test_two_frames_give_a_straight_line():
    t = np.linspace(0, 1, 11)
    W, W1, W2 = spline_matrices([0.0, 1.0], t)
    np.testing.assert_allclose(W @ [0.0, 2.0], 2 * t, atol=1e-14)
    np.testing.assert_allclose(W2, 0.0)


@pytest.mark.parametrize("knots", [[0.0], [0.0, 0.0, 1.0], [0.0, np.nan]])
def test_bad_knots_raise(knots):
    with pytest.raises(InputError, match="knots"):
        spline_matrices(knots, [0.0])


@pytest.mark.parametrize("m", [2, 3, 4, 9, 30])
def test_matrices_and_interpolate_match_scipy_make_interp_spline(m):
    """The direct construction (moments by solve_banded) against scipy's natural cubic interpolant,
    value and derivatives 1-3, at random times and at the knots (third derivative: right segment)."""
    from scipy.interpolate import make_interp_spline

    rng = np.random.default_rng(m)
    x = np.cumsum(rng.uniform(0.05, 1.5, m))
    t = np.concatenate([np.sort(rng.uniform(x[0], x[-1], 300)), x])
    k = 3 if m > 2 else 1
    bc = "natural" if k == 3 else None
    phi = make_interp_spline(x, np.eye(m), k=k, bc_type=bc)
    W, W1, W2 = spline_matrices(x, t)
    scale = 1.0 / np.diff(x).min()
    np.testing.assert_allclose(W, phi(t), atol=1e-13)
    np.testing.assert_allclose(W1, phi.derivative(1)(t), atol=1e-13 * scale)
    np.testing.assert_allclose(W2, phi.derivative(2)(t) if k == 3 else 0.0, atol=1e-13 * scale**2)
    y = rng.normal(size=(m, 3))
    spl = make_interp_spline(x, y, k=k, bc_type=bc)
    for nu in range(5):
        expect = spl.derivative(nu)(t) if nu <= k else np.zeros((len(t), 3))
        np.testing.assert_allclose(interpolate(x, y, t, nu), expect, atol=1e-12 * scale**nu, err_msg=f"nu={nu}")
    assert interpolate(x, y[:, 0], t).shape == (len(t),) and interpolate(x, y, 0.5).shape == (3,)


def test_interpolate_several_orders_at_once():
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.uniform(0.1, 0.5, 8))
    y = rng.normal(size=(8, 2))
    t = np.linspace(x[0], x[-1], 57)
    got = interpolate(x, y, t, (0, 2, 1, 4))
    assert isinstance(got, tuple) and len(got) == 4
    for g, nu in zip(got, (0, 2, 1, 4)):
        np.testing.assert_array_equal(g, interpolate(x, y, t, nu))


def test_interpolate_segments_equals_interpolate_at_the_same_times():
    from solver.spline import interpolate_segments

    rng = np.random.default_rng(4)
    for m in (2, 3, 9):
        x = np.cumsum(rng.uniform(0.1, 0.5, m))
        y = rng.normal(size=(m, 3))
        tau = np.array([0.0, 0.1, 0.5, 0.93])
        t = (x[:-1, None] + np.diff(x)[:, None] * tau).ravel()
        for nu in range(5):
            expect = interpolate(x, y, t, nu)
            got = interpolate_segments(x, y, tau, nu)
            np.testing.assert_allclose(got, expect, atol=1e-13 * (1 + np.abs(expect).max()), err_msg=f"m={m} nu={nu}")
        assert len(interpolate_segments(x, y, tau, (0, 2))) == 2

