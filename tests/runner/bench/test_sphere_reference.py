"""Tests of the independent reference (runner/bench/sphere_reference/): the natural Riemannian cubic on S^3."""
from __future__ import annotations

import math

import numpy as np
import pytest

from runner.bench import sphere_reference as sr


def _orthonormal(seed, k):
    return np.linalg.qr(np.random.default_rng(seed).normal(size=(4, k)))[0].T


ALL_SETS = sr.large_rotation_sets() + [sr.moderate_rotation_set()]


# ---------------------------------------------------------------------------------- covariant_energy


def test_covariant_energy_great_circle_constant_speed_is_zero():
    a, b = _orthonormal(0, 2)
    t = np.linspace(0.0, 3.0, 2001)
    th = 1.3 * t
    u = np.cos(th)[:, None] * a + np.sin(th)[:, None] * b
    assert sr.covariant_energy(t, u) < 1e-12


def test_covariant_energy_great_circle_accelerating_matches_theta_dd():
    # theta = t^2 on a great circle: covariant acceleration = theta'' = 2, E = 4 T
    a, b = _orthonormal(1, 2)
    t = np.linspace(0.0, 1.5, 1501)
    th = t**2
    u = np.cos(th)[:, None] * a + np.sin(th)[:, None] * b
    assert sr.covariant_energy(t, u) == pytest.approx(4 * 1.5, rel=1e-9)


def test_covariant_energy_small_circle_analytic():
    # u = cos(al) e0 + sin(al) (cos(w t) e1 + sin(w t) e2): |cov. acc.|^2 = w^4 sin^2(al) cos^2(al)
    e0, e1, e2 = _orthonormal(2, 3)
    al, w, T = 0.7, 2.3, 2.0
    t = np.linspace(0.0, T, 3001)
    u = math.cos(al) * e0 + math.sin(al) * (np.cos(w * t)[:, None] * e1 + np.sin(w * t)[:, None] * e2)
    want = T * w**4 * math.sin(al) ** 2 * math.cos(al) ** 2
    # the samples may be non-unit and any sign: covariant_energy normalizes and fixes signs
    scale = (1.0 + 0.1 * np.sin(3 * t))[:, None]
    flip = np.where(np.arange(len(t)) % 7 == 3, -1.0, 1.0)[:, None]
    assert sr.covariant_energy(t, u * scale * flip) == pytest.approx(want, rel=1e-9)


# ---------------------------------------------------------------------------------- exact cases


def test_geodesic_two_keyframes_has_zero_energy():
    a, b = _orthonormal(3, 2)
    q = np.stack([a, math.cos(1.2) * a + math.sin(1.2) * b])
    ref = sr.riemannian_cubic_reference(np.array([0.0, 2.0]), q)
    assert abs(ref.E_star) < 1e-8
    t, u = ref.dense(200)
    assert sr.covariant_energy(t, u) < 1e-9
    # slerp at constant speed
    th = np.arccos(np.clip(u @ a, -1, 1))
    assert np.allclose(th, 1.2 * t / 2.0, atol=1e-7)


def test_great_circle_uniform_speed_keyframes_have_zero_energy():
    times = np.array([0.0, 0.5, 1.7, 2.0, 3.1])
    t, q = sr.great_circle_set(times, 0.6 * times)
    assert abs(sr.riemannian_cubic_reference(t, q).E_star) < 1e-9


def test_great_circle_nonuniform_times_matches_1d_natural_spline():
    times = np.array([0.0, 0.7, 1.5, 2.1, 3.4, 4.0, 5.2])
    thetas = np.array([0.0, 0.8, 0.5, 1.6, 2.0, 1.2, 2.5])
    t, q = sr.great_circle_set(times, thetas)
    want = sr.natural_spline_energy_1d(times, thetas)
    ref = sr.riemannian_cubic_reference(t, q)
    assert ref.E_star == pytest.approx(want, rel=1e-8)
    disc = sr.discrete_sphere_reference(t, q)
    assert disc.E_star == pytest.approx(want, rel=1e-7)
    # the path stays on the great circle and follows the 1-D spline in theta
    tt, u = ref.dense(100)
    from scipy.interpolate import CubicSpline

    th = CubicSpline(times, thetas, bc_type="natural")(tt)
    _, qa = sr.great_circle_set(np.zeros(1), np.zeros(1))
    _, qb = sr.great_circle_set(np.zeros(1), np.full(1, np.pi / 2))
    assert np.allclose(u, np.cos(th)[:, None] * qa[0] + np.sin(th)[:, None] * qb[0], atol=1e-7)


# ---------------------------------------------------------------------------------- the solve_bvp solution


@pytest.mark.parametrize("kset", ALL_SETS[:1] + ALL_SETS[-1:], ids=lambda s: s.name)
def test_solution_interpolates_is_unit_and_natural(kset):
    ref = sr.riemannian_cubic_reference(kset.times, kset.quats)
    y = ref.states(kset.times)
    assert np.allclose(y[:, 0:4], sr.align(kset.quats), atol=1e-10)
    tt, u = ref.dense(50)
    st = ref.states(tt)
    u, V, A, J = st[:, 0:4], st[:, 4:8], st[:, 8:12], st[:, 12:16]
    assert np.max(np.abs(np.linalg.norm(u, axis=1) - 1)) < 1e-8
    for w in (V, A, J):  # tangent vectors
        assert np.max(np.abs(np.sum(u * w, axis=1))) < 1e-7 * (1 + np.max(np.abs(w)))
    # natural ends: covariant acceleration 0 at t_0 and t_{K-1}
    assert np.linalg.norm(y[0, 8:12]) < 1e-9 and np.linalg.norm(y[-1, 8:12]) < 1e-9
    # E* agrees with the independent measurement of the sampled path
    assert sr.covariant_energy(tt, u) == pytest.approx(ref.E_star, rel=1e-6)


def test_c2_at_interior_keyframes():
    """One-sided polynomial fits of the position u(t) alone (no states) on each side of a keyframe."""
    kset = sr.large_rotation_sets()[1]
    ref = sr.riemannian_cubic_reference(kset.times, kset.quats, tol=1e-7)
    h = np.diff(kset.times)
    jumps3 = []
    for i in range(1, len(kset.times) - 1):
        ti, d = kset.times[i], 0.2  # keyframe intervals are >= 0.5 s

        def u_on(j, tt):
            return ref.sol.sol((tt - kset.times[j]) / h[j])[17 * j : 17 * j + 4].T

        tl, tr = np.linspace(ti - d, ti, 60), np.linspace(ti, ti + d, 60)
        pl = np.polynomial.polynomial.polyfit(tl - ti, u_on(i - 1, tl), 10)
        pr = np.polynomial.polynomial.polyfit(tr - ti, u_on(i, tr), 10)
        dl = [pl[k] * math.factorial(k) for k in range(4)]
        dr = [pr[k] * math.factorial(k) for k in range(4)]
        scale = [1.0] + [np.linalg.norm(dl[k]) + 1.0 for k in (1, 2, 3)]
        for k, tol in ((0, 1e-10), (1, 1e-8), (2, 1e-6)):
            assert np.linalg.norm(dl[k] - dr[k]) < tol * scale[k], (i, k)
        jumps3.append(np.linalg.norm(dl[3] - dr[3]))
    # the third derivative jumps (as for a cubic spline): the fits are able to see a discontinuity
    assert max(jumps3) > 0.1


@pytest.mark.parametrize("kset", ALL_SETS[:1] + ALL_SETS[-1:], ids=lambda s: s.name)
def test_euler_lagrange_residual_of_paper_eq10_is_small(kset):
    ref = sr.riemannian_cubic_reference(kset.times, kset.quats)
    t = np.linspace(kset.times[0], kset.times[-1], 401)[1:-1]
    res, scale = sr.euler_lagrange_residual(ref, t)
    assert np.max(np.linalg.norm(res, axis=1) / scale) < 1e-7


def test_euler_lagrange_check_detects_a_wrong_curvature_sign(monkeypatch):
    """With R(X,Y)Z of the opposite sign in the ODE, the eq. 10 residual is O(1) and E is higher."""
    kset = sr.moderate_rotation_set()
    good = sr.riemannian_cubic_reference(kset.times, kset.quats)
    rhs = sr.bvp._rhs

    def flipped(y):
        out = rhs(y)
        V, A = y[4:8], y[8:12]
        out[12:16] += 2 * (np.sum(V * V, axis=0) * A - np.sum(V * A, axis=0) * V)
        return out

    def flipped_jac(y):
        h, jac = 1e-7, np.zeros((17, 17, y.shape[1]))
        for k in range(17):
            e = np.zeros((17, 1))
            e[k] = h
            jac[:, k, :] = (flipped(y + e) - flipped(y - e)) / (2 * h)
        return jac

    monkeypatch.setattr(sr.bvp, "_rhs", flipped)
    monkeypatch.setattr(sr.bvp, "_rhs_jac", flipped_jac)
    bad = sr.bvp._reference_cached.__wrapped__(*sr.bvp._key(kset.times, kset.quats), 1e-6)  # bypass the cache
    t = np.linspace(kset.times[0], kset.times[-1], 201)[1:-1]
    res, scale = sr.euler_lagrange_residual(bad, t)
    assert np.max(np.linalg.norm(res, axis=1) / scale) > 1e-2
    assert bad.E_star > good.E_star * (1 + 1e-5)


@pytest.mark.parametrize("kset", ALL_SETS, ids=lambda s: s.name)
def test_bvp_and_discrete_methods_agree(kset):
    ref = sr.riemannian_cubic_reference(kset.times, kset.quats)
    disc = sr.discrete_sphere_reference(kset.times, kset.quats)
    assert disc.E_star == pytest.approx(ref.E_star, rel=1e-6)
    # the discrete levels converge at O(h^2) toward E* from below
    e = np.array(disc.energies)
    assert np.all(e < ref.E_star) and np.all(np.diff(e) > 0)
    ratio = (ref.E_star - e[:-1]) / (ref.E_star - e[1:])
    assert np.all((ratio > 3.5) & (ratio < 4.5))


def test_reference_is_cached_and_fast():
    kset = sr.large_rotation_sets()[2]
    before = sr.bvp._reference_cached.cache_info()
    a = sr.riemannian_cubic_reference(kset.times, kset.quats)
    middle = sr.bvp._reference_cached.cache_info()
    b = sr.riemannian_cubic_reference(kset.times.copy(), kset.quats.copy())
    after = sr.bvp._reference_cached.cache_info()
    assert a is b
    assert middle.misses - before.misses <= 1  # solved at most once (once when this file runs alone)
    assert (after.hits, after.misses) == (middle.hits + 1, middle.misses)  # equal copies: a cache hit
    # fast as a count of work, not seconds: measured 4 Newton iterations on 182 nodes (max_nodes 20000)
    assert a.sol.status == 0 and a.sol.niter <= 10 and a.n_nodes <= 1000


# ---------------------------------------------------------------------------------- keyframe sets


def test_keyframe_sets():
    sets = sr.large_rotation_sets()
    again = sr.large_rotation_sets()
    assert len(sets) >= 3
    uniform = nonuniform = 0
    for s, s2 in zip(sets, again):
        assert np.array_equal(s.times, s2.times) and np.array_equal(s.quats, s2.quats)
        assert s.times.shape == (7,) and s.quats.shape == (7, 4)
        assert np.allclose(np.linalg.norm(s.quats, axis=1), 1.0)
        assert np.all(np.sum(s.quats[1:] * s.quats[:-1], axis=1) > 0)  # hemisphere-aligned
        ang = sr.rotation_angles_deg(s.quats)
        assert np.all(ang >= 30 - 1e-9) and np.all(ang <= 150 + 1e-9)
        if np.allclose(np.diff(s.times), np.diff(s.times)[0]):
            uniform += 1
        else:
            nonuniform += 1
    assert uniform >= 1 and nonuniform >= 1
    m = sr.moderate_rotation_set()
    assert m.times.shape == (7,) and m.quats.shape == (7, 4)
    assert np.all(sr.rotation_angles_deg(m.quats) <= 60 + 1e-9)
