"""The closed-form roots (solver.polynomial_roots) against numpy's companion-matrix eigenvalues (np.roots, an
independent method) and against cubics built from known roots, including the cases closed forms lose digits on: a
vanishing leading coefficient, clustered roots and one real root."""
import numpy as np
import pytest

from solver.polynomial_roots import cubic_roots, quadratic_roots


def _real_roots(coefficients, imag=1e-9):
    """The real roots np.roots finds for one polynomial (highest power first), sorted."""
    r = np.roots(coefficients)
    return np.sort(r[abs(r.imag) <= imag].real)


def _found(roots, value, atol):
    """Whether some entry of roots (NaN for none) is within atol of value."""
    return bool(np.any(abs(roots[np.isfinite(roots)] - value) <= atol))


@pytest.mark.parametrize("seed", range(3))
def test_cubic_roots_find_every_real_root_np_roots_finds(seed):
    rng = np.random.default_rng(seed)
    c = rng.normal(size=(4, 500))
    c[0, :100] *= 1e-10  # nearly quadratic
    c[0, 100:150] = 0.0  # quadratic
    got = cubic_roots(*c)
    for j in range(c.shape[1]):
        want = _real_roots(c[:, j])
        for w in want[abs(want) <= 10]:  # the roots a curve on [0, 1] can meet, and some beyond
            assert _found(got[j], w, 1e-9 * max(1.0, abs(w))), (j, c[:, j], want, got[j])
        # every entry is a root, or the real part of a complex pair (a candidate that is no root)
        parts = np.roots(c[:, j]).real
        for g in got[j][np.isfinite(got[j])]:
            assert np.any(abs(parts - g) <= 1e-6 * max(1.0, abs(g))), (j, c[:, j], np.roots(c[:, j]), got[j])


def test_cubic_roots_of_known_roots_in_the_unit_interval():
    roots = np.array([[0.1, 0.5, 0.9], [0.3, 0.3 + 1e-7, 0.8], [0.25, 0.25, 0.25], [0.0, 1.0, 0.5]])
    for scale in (1.0, 1e-6, 1e3):
        c = scale * np.array([np.poly(r) for r in roots]).T
        got = cubic_roots(*c)
        for j, r in enumerate(roots):
            for w in r:
                # a triple root is ill-conditioned: a 1e-16 coefficient error moves it by 1e-16^(1/3)
                atol = 1e-5 if j == 2 else 1e-6 if j == 1 else 1e-12
                assert _found(got[j], w, atol), (scale, r, got[j])


def test_a_cubic_with_one_real_root_also_returns_its_complex_pair_s_real_part():
    # (u - 0.4) ((u - 0.7)^2 + 1e-6): one real root, and a complex pair at 0.7 +- 1e-3 i where |p| has a near-zero dip
    c = np.poly([0.4, 0.7 + 1e-3j, 0.7 - 1e-3j]).real
    got = cubic_roots(*c)
    assert _found(got, 0.4, 1e-12)
    assert _found(got, 0.7, 1e-9)


def test_quadratic_roots_stay_exact_as_the_leading_coefficient_vanishes():
    a = np.array([1.0, 1e-12, 0.0, 1.0, 0.0])
    b = np.array([-3.0, 1.0, 2.0, 0.0, 0.0])
    c = np.array([2.0, -0.5, -1.0, 1.0, 1.0])
    got = quadratic_roots(a, b, c)
    assert sorted(got[0]) == pytest.approx([1.0, 2.0], abs=1e-15)
    assert _found(got[1], 0.5, 1e-12)  # 1e-12 u^2 + u - 0.5: the root near 0.5 to full precision
    assert _found(got[2], 0.5, 0.0) and np.isnan(got[2]).sum() == 1  # linear: one root
    assert np.isnan(got[3]).all()  # u^2 + 1: none
    assert np.isnan(got[4]).all()  # the constant 1: none
