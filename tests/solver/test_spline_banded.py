"""SplineBasis's banded evaluation (the tridiagonal moment system, docs/scaling.md) against the dense
matrices, an independent spline (scipy CubicSpline, natural ends) and its own transpose, at thousands
of frames."""
import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from solver.errors import InputError
from solver.quadrature import gauss_times, quadrature_times
from solver.spline_basis import DENSE_MAX_ENTRIES, SplineBasis


def knots_and_points(m, n, seed=0, rate=None):
    """Non-uniform knots (m) and n uniform midpoint quadrature times over them."""
    rng = np.random.default_rng(seed)
    x = np.concatenate([[0.0], np.cumsum(rng.uniform(0.02, 0.2, m - 1))])
    t, _ = quadrature_times(x[0], x[-1], n / (x[-1] - x[0]))
    return x, t


@pytest.mark.parametrize("m", [2, 3, 4, 5, 17, 1200])
def test_banded_equals_dense(m):
    x, t = knots_and_points(m, 2 * m + 50, seed=m)
    rng = np.random.default_rng(1)
    P = rng.normal(size=(m, 7))
    dense, banded = SplineBasis(x, t, mode="dense"), SplineBasis(x, t, mode="banded")
    assert banded.banded and not dense.banded
    for yd, yb in zip(dense.evaluate(P), banded.evaluate(P)):
        np.testing.assert_allclose(yb, yd, rtol=0, atol=1e-9 * (1 + np.abs(yd).max()))
    g = [rng.normal(size=(len(t), 7)) for _ in range(3)]
    for gs in (g, (g[0], None, g[2]), (None, g[1], None)):
        gd, gb = dense.pullback(*gs), banded.pullback(*gs)
        np.testing.assert_allclose(gb, gd, rtol=0, atol=1e-9 * (1 + np.abs(gd).max()))
    # the dense matrices of a banded basis (built on first use, one at a time) are the dense basis's
    for name in ("W", "W1", "W2"):
        fresh = SplineBasis(x, t, mode="banded")
        Wd = getattr(dense, name)
        np.testing.assert_allclose(getattr(fresh, name), Wd, atol=1e-12 * (1 + np.abs(Wd).max()))
        assert fresh._B3 is None
    np.testing.assert_allclose(banded.B, dense.B, atol=1e-12 * (1 + np.abs(dense.B).max()))


def test_needs_and_shapes():
    x, t = knots_and_points(40, 900)
    b = SplineBasis(x, t, mode="banded")
    P = np.random.default_rng(2).normal(size=(40, 3))
    Y, Y1, Y2 = b.evaluate(P, needs=(0, 2))
    assert Y1 is None and Y.shape == Y2.shape == (900, 3)


@pytest.mark.parametrize("m", [6, 2500])
def test_reproduces_scipy_natural_cubic_spline(m):
    """An independent reference: scipy's CubicSpline with natural ends, values and two derivatives,
    on frames sampled from a smooth function (the spline through them, not the function, is compared)."""
    x, t = knots_and_points(m, 3 * m + 40, seed=3)
    P = np.stack([np.sin(3 * x), np.cos(x) * x, x**3 - 2 * x], axis=1)
    ref = CubicSpline(x, P, bc_type="natural")
    Y, Y1, Y2 = SplineBasis(x, t, mode="banded").evaluate(P)
    for nu, Yk in enumerate((Y, Y1, Y2)):
        r = ref(t, nu)
        np.testing.assert_allclose(Yk, r, rtol=0, atol=1e-8 * (1 + np.abs(r).max()))


def test_reproduces_a_natural_piecewise_cubic_exactly():
    """Frames sampled from a C2 piecewise cubic with breaks at the knots and zero second derivative at
    both ends (a natural spline built another way: truncated powers) are interpolated exactly, on 1000
    frames. A plain cubic would not be: its second derivative at the ends is not zero. (The tolerance
    is the reference's: its truncated-power sums cancel to ~1e-9 relative.)"""
    rng = np.random.default_rng(4)
    m = 1000
    x = np.concatenate([[0.0], np.cumsum(rng.uniform(0.01, 0.05, m - 1))])
    tau = x[1:-1]
    c = rng.normal(size=m - 2)
    c[-1] = -(c[:-1] * (x[-1] - tau[:-1])).sum() / (x[-1] - tau[-1])  # p''(end) = 0; p''(0) = 0 already

    def p(s, nu):
        d = np.maximum(s[:, None] - tau[None, :], 0.0)
        return (0.3 - 1.2 * s + (c * d**3).sum(1), -1.2 + (3 * c * d**2).sum(1), (6 * c * d).sum(1))[nu]

    t, _ = quadrature_times(x[0], x[-1], 3 * m / x[-1])
    Ys = SplineBasis(x, t, mode="banded").evaluate(p(x, 0)[:, None])
    for nu, Yk in enumerate(Ys):
        ref = p(t, nu)
        np.testing.assert_allclose(Yk[:, 0], ref, rtol=0, atol=1e-7 * (1 + np.abs(ref).max()))


@pytest.mark.parametrize("quadrature", ["uniform", "gauss"])
def test_pullback_is_the_transpose_of_evaluate(quadrature):
    """<W_k P, G_k> summed over orders = <P, pullback(G)>: the adjoint identity, at 4000 frames."""
    rng = np.random.default_rng(5)
    m = 4000
    x = np.concatenate([[0.0], np.cumsum(rng.uniform(0.01, 0.1, m - 1))])
    t = quadrature_times(x[0], x[-1], 2 * m / x[-1])[0] if quadrature == "uniform" else gauss_times(x, 3)[0]
    b = SplineBasis(x, t)  # auto: banded at this size
    assert b.banded
    P = rng.normal(size=(m, 5))
    G = [rng.normal(size=(len(t), 5)) for _ in range(3)]
    lhs = sum(np.vdot(Yk, Gk) for Yk, Gk in zip(b.evaluate(P), G))
    rhs = np.vdot(P, b.pullback(*G))
    assert abs(lhs - rhs) <= 1e-10 * (abs(lhs) + np.sqrt(sum(np.vdot(g, g) for g in G) * np.vdot(P, P)))


@pytest.mark.parametrize("m", [3, 4, 12, 300])
def test_bending_hessian_equals_dense(m):
    x, t = knots_and_points(m, 5 * m + 30, seed=6)
    w = np.random.default_rng(7).uniform(0.5, 2.0, len(t))
    Hd = SplineBasis(x, t, mode="dense")
    expected = (Hd.W2.T * w) @ Hd.W2
    for mode in ("dense", "banded"):
        H = SplineBasis(x, t, mode=mode).bending_hessian(w)
        np.testing.assert_allclose(H, expected, rtol=0, atol=1e-10 * np.abs(expected).max())
    # a scalar weight (uniform quadrature, the preconditioner's 2 h)
    np.testing.assert_allclose(SplineBasis(x, t, mode="banded").bending_hessian(0.5),
                               0.5 * Hd.W2.T @ Hd.W2, rtol=0, atol=1e-10 * np.abs(expected).max())


@pytest.mark.parametrize("m", [2, 3, 4, 12, 300])
def test_value_gram_equals_dense(m):
    """gram(0, w) = W^T diag(w) W without W on a banded basis (the unit term's radial curvature)."""
    x, t = knots_and_points(m, 5 * m + 30, seed=8)
    w = np.random.default_rng(9).uniform(0.5, 2.0, len(t))
    W = SplineBasis(x, t, mode="dense").W
    expected = (W.T * w) @ W
    for mode in ("dense", "banded"):
        np.testing.assert_allclose(SplineBasis(x, t, mode=mode).gram(0, w), expected, rtol=0,
                                   atol=1e-12 * np.abs(expected).max())
    with pytest.raises(ValueError, match="order must be 0 or 2"):
        SplineBasis(x, t).gram(1, w)


def test_bending_hessian_two_frames_is_zero():
    b = SplineBasis(np.array([0.0, 1.0]), np.linspace(0, 1, 10), mode="banded")
    assert not b.bending_hessian(1.0).any()


def test_auto_mode_switches_by_size():
    x, t = knots_and_points(10, 100)
    assert not SplineBasis(x, t).banded  # 1000 entries
    x, t = knots_and_points(100, DENSE_MAX_ENTRIES // 100 + 1)
    assert SplineBasis(x, t).banded
    with pytest.raises(InputError, match="mode"):
        SplineBasis(x, t, mode="sparse")


def test_banded_basis_forms_no_dense_matrix():
    """Work and memory O(n + m): a 20000-frame basis evaluates without an (n, m) array (which would
    be 40000 x 20000 x 8 bytes = 6.4 GB)."""
    x, t = knots_and_points(20000, 40000, seed=8)
    b = SplineBasis(x, t)
    P = np.random.default_rng(9).normal(size=(20000, 2))
    Y, Y1, Y2 = b.evaluate(P)
    g = b.pullback(Y, None, Y2)
    assert b._B3 is None and g.shape == P.shape and np.all(np.isfinite(g))
