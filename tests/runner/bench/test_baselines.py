"""Tests of the two baselines (runner/bench/) against the independent reference."""
from __future__ import annotations

import types

import numpy as np
import pytest

from runner.bench import barr92, common
from runner.bench import baselines as bl
from runner.bench import sphere_reference as sr

MOD = sr.moderate_rotation_set()
LARGE = sr.large_rotation_sets()[1]


def _fd_check(problem, x, rng, n_dirs=6, eps=1e-6):
    f, g = problem.objective(x)
    for _ in range(n_dirs):
        d = rng.normal(size=x.size)
        fp, _ = problem.objective(x + eps * d)
        fm, _ = problem.objective(x - eps * d)
        fd = (fp - fm) / (2 * eps)
        assert g @ d == pytest.approx(fd, rel=1e-6, abs=1e-8 * (abs(f) + 1)), "gradient mismatch"


@pytest.mark.parametrize("kset", [MOD, LARGE], ids=lambda s: s.name)
def test_barr_gradients(kset):
    rng = np.random.default_rng(0)
    pb = bl.BarrProblem(kset.times, kset.quats, 3)
    x = pb.x0 + 0.05 * rng.normal(size=pb.x0.size)  # off the sphere: the general formula
    _fd_check(pb, x, rng)
    J = pb.constraint_jac(x)
    for _ in range(3):
        d = rng.normal(size=x.size)
        fd = (pb.constraint(x + 1e-6 * d) - pb.constraint(x - 1e-6 * d)) / 2e-6
        assert np.allclose(J @ d, fd, rtol=1e-6, atol=1e-8)


@pytest.mark.parametrize("kset", [MOD, LARGE], ids=lambda s: s.name)
def test_bspline_gradients(kset):
    rng = np.random.default_rng(1)
    pb = bl.BSplineProblem(kset.times, kset.quats, 2, lam=1e3)
    x = pb.x0 + 0.05 * rng.normal(size=pb.x0.size)
    _fd_check(pb, x, rng)
    # the start (natural cubic spline through the keyframes) is feasible; constraints are linear
    assert np.max(np.abs(pb.constraint(pb.x0))) < 1e-12
    d = rng.normal(size=x.size)
    assert np.allclose(pb.constraint(x + d) - pb.constraint(x), pb.constraint_jac(x) @ d, atol=1e-12)


def _check_result(r, kset):
    assert r.path_u.shape == (len(r.path_times), 4)
    assert np.allclose(np.linalg.norm(r.path_u, axis=1), 1.0)
    assert r.path_times[0] == kset.times[0] and r.path_times[-1] == kset.times[-1]
    # passes through the keyframes
    idx = np.searchsorted(r.path_times, kset.times)
    assert np.allclose(r.path_times[idx], kset.times)
    assert np.max(np.abs(r.path_u[idx] - sr.align(kset.quats))) < 1e-8
    # the method's own E agrees with the independent measurement of its sampled path
    assert sr.covariant_energy(r.path_times, r.path_u) == pytest.approx(r.E, rel=1e-6)


def test_barr_gap_decreases_with_resolution():
    ref = sr.riemannian_cubic_reference(MOD.times, MOD.quats)
    gaps = []
    for m in (2, 4, 8):
        r = bl.barr92_discrete(MOD.times, MOD.quats, m, max_time_s=30)
        assert r.status == "converged"
        assert r.extra["sample_norm_error"] < 1e-8  # hard constraints hold at the samples
        _check_result(r, MOD)
        gaps.append((r.E - ref.E_star) / ref.E_star)
    assert gaps[0] > gaps[1] > gaps[2] > 0
    assert gaps[2] < 3e-3


def test_bspline_gap_decreases_with_resolution():
    ref = sr.riemannian_cubic_reference(MOD.times, MOD.quats)
    gaps = []
    for res in (1, 2, 3):
        r = bl.bspline_coefficients(MOD.times, MOD.quats, res, max_time_s=30)
        assert r.status == "converged"
        assert r.extra["keyframe_error"] < 1e-10
        _check_result(r, MOD)
        gaps.append((r.E - ref.E_star) / ref.E_star)
    assert gaps[0] > gaps[1] > gaps[2] > 0
    assert gaps[2] < 1e-3


def test_deterministic_and_time_limit(monkeypatch):
    a = bl.bspline_coefficients(MOD.times, MOD.quats, 2)
    b = bl.bspline_coefficients(MOD.times, MOD.quats, 2)
    assert a.E == b.E and np.array_equal(a.path_u, b.path_u) and a.n_evals == b.n_evals
    # a fake clock, one second per reading, instead of the wall clock: the limit is checked before
    # every evaluation and stops at the first one past it. Readings: 0 (start of the run), 1 (start
    # of SLSQP), 2, 3, 4 (evaluations 1-3, elapsed 1-3 s), 5 (elapsed 4 s > 3.5 s: stop), 6 (end).
    ticks = iter(range(1000))
    clock = types.SimpleNamespace(perf_counter=lambda: float(next(ticks)))
    monkeypatch.setattr(barr92, "time", clock)  # the run's start and end
    monkeypatch.setattr(common, "time", clock)  # the SLSQP driver's limit check
    r = bl.barr92_discrete(LARGE.times, LARGE.quats, 24, max_time_s=3.5)
    assert r.status == "time_limit"
    assert r.n_evals == 3 and r.wall_time_s == 6.0
    assert np.isfinite(r.E) and r.E > 0


def test_time_to_gap_logic_with_a_fake_method():
    """gap = 1/res^2: reaches 1e-2 at res 12, 1e-3 at res 32, never 1e-4 within the ladder cut."""

    def fake(times, quats, res, max_time_s):
        return bl.BaselineResult(
            path_times=np.asarray(times), path_u=np.asarray(quats), wall_time_s=0.01 * res, n_evals=1,
            status="converged", E=1.0 + 1.0 / res**2,
        )

    log = []
    out = bl.baseline_time_to_gap(fake, MOD.times, MOD.quats, 1.0, resolutions=(1, 2, 4, 12, 32),
                                  log=log)
    assert out[1e-2] == (pytest.approx(0.12), 12, pytest.approx(1 / 144))
    assert out[1e-3] == (pytest.approx(0.32), 32, pytest.approx(1 / 1024))
    assert out[1e-4] == (None, 32, pytest.approx(1 / 1024))
    assert [e["resolution"] for e in log] == [1, 2, 4, 12, 32]


def test_time_to_gap_real_bspline_small_budget():
    ref = sr.riemannian_cubic_reference(MOD.times, MOD.quats)
    out = bl.baseline_time_to_gap("bspline", MOD.times, MOD.quats, ref.E_star, gaps=(1e-1, 1e-3),
                                  max_time_s=20)
    t, res, gap = out[1e-1]
    assert t is not None and gap <= 1e-1 and res >= 1
