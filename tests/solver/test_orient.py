"""The single-body orientation problem (paper sec. 3, solver/orient.py, runner/euler_lagrange.py,
`dynsplines orient`) against the exact optimum computed independently in runner/bench/sphere_reference/.

Acceptance-style checks: keyframes met exactly, relative gap (E - E*)/E* < 1e-3 with default settings on
the large-rotation sets (E = integral |covariant acceleration of q/|q||^2 dt, measured by the reference
module's own code), the paper's form on a moderate set, adaptive vs global frame counts, convergence of
E to E* as frames are added, the strong-form residual, the CLI and its error messages.
"""
import json

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from runner.bench.sphere_reference import (
    align,
    covariant_energy,
    great_circle_set,
    large_rotation_sets,
    moderate_rotation_set,
    natural_spline_energy_1d,
    riemannian_cubic_reference,
)
from runner.euler_lagrange import deviation_by_region, el_lhs, residual, spline_residual
from solver.errors import InputError
from solver.paper.orient import check_keyframes, default_options, orient
from solver.terms import NormalizedCovariantAcceleration

from conftest import fd_gradient

LARGE = {s.name: s for s in large_rotation_sets()}
MODERATE = moderate_rotation_set()
SLOT = np.arange(4).reshape(1, 4)


@pytest.fixture(scope="session")
def E_star():
    """Exact optimum E* of every test set (solve_bvp at tol 1e-6: agrees with tol 1e-9 to ~1e-10)."""
    sets = list(LARGE.values()) + [MODERATE]
    return {s.name: riemannian_cubic_reference(s.times, s.quats, tol=1e-6).E_star for s in sets}


def measured_energy(frames) -> float:
    """E of the result's normalized path by the reference module (dense samples, no solver code)."""
    t = np.concatenate([np.linspace(a, b, 161)[:-1] for a, b in zip(frames.times[:-1], frames.times[1:])]
                       + [frames.times[-1:]])
    return covariant_energy(t, frames.path(t), breaks=frames.times)


def gap(result, E) -> float:
    return (measured_energy(result.frames) - E) / E


# ------------------------------------------------------------------------------------------- the term
def test_normalized_covariant_gradient_and_scale_invariance():
    rng = np.random.default_rng(0)
    term = NormalizedCovariantAcceleration(SLOT)
    Y, Y1, Y2 = (rng.normal(size=(6, 4)) for _ in range(3))
    ev = term.evaluate(None, Y, Y1, Y2)
    for k, (X, g) in enumerate(((Y, ev.dY), (Y1, ev.dY1), (Y2, ev.dY2))):
        def f(Z, k=k):
            args = [Y, Y1, Y2]
            args[k] = Z
            return term.evaluate(None, *args, grad=False).f.sum()

        np.testing.assert_allclose(g, fd_gradient(f, X), rtol=1e-5, atol=1e-7, err_msg=f"d/dY{k}")
    np.testing.assert_allclose(term.evaluate(None, -2.5 * Y, -2.5 * Y1, -2.5 * Y2).f, ev.f, rtol=1e-12)
    # several quaternion slots in a longer state: the same per slot, summed
    two = NormalizedCovariantAcceleration(np.array([[1, 2, 3, 4], [5, 6, 7, 8]]))
    Z = [np.hstack([np.ones((6, 1)), A, 3 * A]) for A in (Y, Y1, Y2)]
    np.testing.assert_allclose(two.evaluate(None, *Z).f, 2 * ev.f, rtol=1e-12)


def test_normalized_covariant_value_against_finite_differences_of_the_unit_path():
    """f = |u'' - u (u''.u)|^2 with u = q/|q| differentiated numerically (no formula shared)."""
    t = np.linspace(0.2, 1.0, 5)
    q = lambda s: np.stack([1 + s, s**2, np.sin(3 * s), 0.3 - s**3], -1)  # noqa: E731
    d = [lambda s: np.stack([1 + 0 * s, 2 * s, 3 * np.cos(3 * s), -3 * s**2], -1),
         lambda s: np.stack([0 * s, 2 + 0 * s, -9 * np.sin(3 * s), -6 * s], -1)]
    h = 1e-4
    u = lambda s: q(s) / np.linalg.norm(q(s), axis=-1, keepdims=True)  # noqa: E731
    u0, u2 = u(t), (u(t + h) - 2 * u(t) + u(t - h)) / h**2
    expect = np.sum((u2 - u0 * np.sum(u2 * u0, -1, keepdims=True)) ** 2, -1)
    got = NormalizedCovariantAcceleration(SLOT).evaluate(t, q(t), d[0](t), d[1](t), grad=False).f
    np.testing.assert_allclose(got, expect, rtol=1e-5)


# --------------------------------------------------------------------------------- acceptance checks
@pytest.mark.parametrize("name", list(LARGE))
def test_default_settings_meet_keyframes_and_reach_gap_1e3(name, E_star):
    s = LARGE[name]
    r = orient(s.times, s.quats)
    keys = align(s.quats)
    assert np.abs(r.path(s.times) - keys).max() <= 1e-12
    assert np.array_equal(r.frames.values[r.frames.is_keyframe], keys)
    g = gap(r, E_star[name])
    assert 0 <= g < 1e-3, g
    # the library's own energy (Gauss-Legendre) agrees with the independent measurement
    assert abs(r.energy - measured_energy(r.frames)) <= 1e-6 * r.energy
    assert r.max_norm_deviation < 0.1  # reported; the normalized form only holds |q| near 1
    assert r.solution.rounds[-1].result.ok


def test_paper_form_on_moderate_rotations(E_star):
    s = MODERATE
    paper = orient(s.times, s.quats, form="paper")  # 2:5 (sec. 3), renormalized on the start path
    assert paper.renormalize == "start" and paper.weights == (2.0, 5.0)
    assert paper.max_norm_deviation < 2e-3  # the paper's figure 9: < 0.2%; measured 0.023%
    assert gap(paper, E_star[s.name]) < 1e-3  # measured 6.3e-5 (three adaptive rounds)
    assert paper.keyframe_error < 1e-12
    # the other reading of eq. 7's "initial" path, the plain spline through the keyframes alone: its
    # (1 - q.q)^2 integral is ~130x larger here, so the same 2:5 holds |q| far less (measured 0.41%)
    plain = orient(s.times, s.quats, form="paper", renormalize="keyframes")
    assert plain.solution.scales["unit"] > 30 * paper.solution.scales["unit"]
    assert plain.max_norm_deviation > 2 * paper.max_norm_deviation
    # with the paper form's three adaptive rounds, the normalized form is nearer the exact optimum (its
    # optimum is E*; the paper form's trades smoothness for |q|): measured 2.3e-6 against 6.3e-5
    normalized = orient(s.times, s.quats, options=default_options(rounds=3))
    assert gap(normalized, E_star[s.name]) < gap(paper, E_star[s.name])


def test_paper_form_drifts_from_unit_length_on_large_rotations(E_star):
    """The trade-off the normalized form removes: shrinking q lowers eq. 9's f2. With 2:5 renormalized
    on the plain keyframe spline (the issue's trial) the unit term is too weak to stop it."""
    s = LARGE["large_nonuniform"]
    paper = orient(s.times, s.quats, form="paper", renormalize="keyframes")
    normalized = orient(s.times, s.quats)
    assert paper.max_norm_deviation > 0.1 > normalized.max_norm_deviation
    assert gap(paper, E_star[s.name]) > 10 * gap(normalized, E_star[s.name])
    # renormalized on the start path the unit term is ~50x stiffer and holds |q| (measured 0.38%)
    held = orient(s.times, s.quats, form="paper")
    assert held.max_norm_deviation < 0.01
    assert gap(held, E_star[s.name]) < 1e-3


def test_energy_converges_to_the_exact_optimum_as_frames_are_added(E_star):
    s = LARGE["large_uniform"]
    gaps = []
    for n in (0, 1, 2, 3):
        r = orient(s.times, s.quats, options=default_options(subdivision="global", per_segment=n), rate=100)
        gaps.append(gap(r, E_star[s.name]))
    assert all(g >= -1e-7 for g in gaps)  # never below the exact optimum
    assert gaps[0] > 0.05 and gaps[-1] < 2e-4
    assert all(b < a / 3 for a, b in zip(gaps, gaps[1:])), gaps


def test_great_circle_keyframes_give_the_flat_optimum():
    """Keyframes on one great circle: the optimum is the 1-D natural spline in the angle (exact E*)."""
    times = np.array([0.0, 0.7, 1.5, 2.0, 3.1])
    th = np.array([0.0, 0.9, 1.2, 2.4, 2.9])
    t, q = great_circle_set(times, th)
    E_flat = natural_spline_energy_1d(times, th)
    r = orient(t, q, options=default_options(subdivision="global", per_segment=3), rate=100)
    assert abs(measured_energy(r.frames) - E_flat) < 1e-3 * E_flat


def test_adaptive_needs_fewer_frames_than_global_for_the_same_gap(E_star):
    """Figure 10's argument, measured: the gap of global subdivision with 2 frames per interval (12
    frames) is reached by adaptive subdivision, one frame per round, with fewer frames (measured: 10)."""
    s = LARGE["large_nonuniform_b"]
    E = E_star[s.name]
    target = gap(orient(s.times, s.quats, options=default_options(subdivision="global", per_segment=2)), E)
    adaptive = None
    for rounds in range(0, 6):
        r = orient(s.times, s.quats, options=default_options(rounds=rounds, per_round=1))
        if gap(r, E) <= target:
            adaptive = r.n_variable
            break
    assert adaptive is not None and adaptive < 12, (adaptive, target)


# ------------------------------------------------------------------------------- Euler-Lagrange
def test_strong_form_is_zero_on_a_great_circle_at_constant_speed():
    w = 1.7
    a, b = np.linalg.qr(np.random.default_rng(3).normal(size=(4, 2)))[0].T

    def path(t, nu, scale=1.0):
        c = np.cos(w * t + nu * np.pi / 2) * w**nu
        s = np.sin(w * t + nu * np.pi / 2) * w**nu
        return scale * (c[:, None] * a + s[:, None] * b)

    t = np.linspace(0.0, 2.0, 41)
    assert np.abs(residual(path, t, [0.0, 2.0], unit_weight=5.0)).max() < 1e-8 * w**4
    big = lambda t, nu: path(t, nu, 1.3)  # noqa: E731  (|q| = 1.3: eq. 10 on q has Z = 2 lambda (b-1) q)
    el = residual(big, t, [0.0, 2.0], unit_weight=5.0)
    np.testing.assert_allclose(el, 2 * 5.0 * (1.3**2 - 1) * path(t, 0, 1.3), atol=1e-8)
    assert np.abs(residual(big, t, [0.0, 2.0], normalized=True)).max() < 1e-8 * w**4


def test_el_lhs_matches_appendix_b_partial_derivatives():
    """eq. 10 = (dF/dq + d2/dt2 dF/dq'') / 2 with F of eq. 25, dF/dq'' = 2 Y; check X and Z parts
    against the UnitQuaternion/CovariantAcceleration gradients (independently coded terms)."""
    from solver.terms import CovariantAcceleration, UnitQuaternion

    rng = np.random.default_rng(1)
    q, q2 = rng.normal(size=(5, 4)), rng.normal(size=(5, 4))
    lam = 0.7
    zero = np.zeros((5, 4))
    el = el_lhs(q, zero, q2, zero, np.zeros(5), np.zeros(5), lam)  # T', T'', q', q'''' = 0
    T = (q * q2).sum(1, keepdims=True) / (q * q).sum(1, keepdims=True)
    dFdq = CovariantAcceleration(SLOT).evaluate(None, q, None, q2).dY + lam * UnitQuaternion(SLOT).evaluate(
        None, q, None, None).dY
    np.testing.assert_allclose(el, 0.5 * dFdq - q2 * T, atol=1e-12)  # Y'' = -q'' T here


def test_strong_form_residual_decreases_with_optimization():
    s = LARGE["large_uniform"]
    r = orient(s.times, s.quats, options=default_options(subdivision="global", per_segment=1))
    init = r.solution.initial
    d0 = deviation_by_region(init.times, init.values, normalized=True)
    d1 = deviation_by_region(r.frames.times, r.frames.values, normalized=True)
    assert d0.shape == (10,) and np.all(d0 > 0)
    assert d1.sum() < 0.7 * d0.sum()
    # and where the plain spline's deviation was largest, the optimized path's is smaller
    worst = int(np.argmax(d0))
    assert d1[worst] < 0.5 * d0[worst]


def test_residual_rejects_times_outside_the_path():
    with pytest.raises(InputError, match="residual times"):
        spline_residual([0.0, 1.0, 2.0], np.eye(3, 4) + 0.5, [2.5])


def test_figure10_numbers():
    """The figure's data: optimization lowers the integrated deviation; a few adaptive frames lower it
    most where the initial spline's is largest."""
    from runner.figure10 import CURVES, compute

    s = LARGE["large_uniform"]
    data = compute(s.times, s.quats)
    assert list(data) == list(CURVES)
    dev = {k: v[1] for k, v in data.items()}
    init, one, three, adapt = (dev[k] for k in CURVES)
    assert one.sum() < init.sum() and three.sum() < init.sum()
    assert data[list(CURVES)[3]][0].n_variable == 2
    worst = int(np.argmax(init))
    assert adapt[worst] < 0.8 * init[worst]


# -------------------------------------------------------------------------------------- API errors
def test_bad_keyframes_raise_clear_errors():
    q = np.tile([1.0, 0, 0, 0], (3, 1))
    with pytest.raises(InputError, match="one time per quaternion"):
        check_keyframes([0, 1], q)
    with pytest.raises(InputError, match=r"quaternion 1 .*zero"):
        check_keyframes([0, 1, 2], [[1, 0, 0, 0], [0, 0, 0, 0], [1, 0, 0, 0]])
    with pytest.raises(InputError, match="strictly increasing"):
        check_keyframes([0, 2, 1], q)
    with pytest.raises(InputError, match=r"\[w, x, y, z\]"):
        check_keyframes([0, 1, 2], np.ones((3, 3)))
    with pytest.raises(InputError, match="unknown objective form 'exact'; choose one of: normalized, paper"):
        orient([0, 1, 2], q, form="exact")
    with pytest.raises(InputError, match="weights must be two numbers"):
        orient([0, 1, 2], q, weights=(1, 2, 3))
    with pytest.raises(InputError, match="renormalize must be True, False, 'start' or 'keyframes', got 'plain'"):
        orient([0, 1, 2], q, form="paper", renormalize="plain")


def test_non_unit_and_opposite_sign_keyframes_are_normalized_and_aligned():
    q = np.array([[2.0, 0, 0, 0], [0, 0, 0, -3.0], [0.5, 0.5, 0.5, 0.5]])
    r = orient([0.0, 1.0, 2.0], q, options=default_options(subdivision="global"))
    keys = align(q)
    np.testing.assert_allclose(r.keyframes, keys, atol=0)
    assert np.abs(r.path([0.0, 1.0, 2.0]) - keys).max() <= 1e-12


# ------------------------------------------------------------------------------------------------ CLI
def write(path, obj):
    path.write_text(json.dumps(obj))
    return str(path)


def test_cli_round_trip(tmp_path, capsys):
    from runner.cli import main

    s = LARGE["large_nonuniform"]
    kf = write(tmp_path / "k.json", {"times": s.times.tolist(), "quaternions": s.quats.tolist()})
    out = tmp_path / "sub" / "path.npz"
    assert main(["orient", kf, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "max |1 - |q||" in printed and "variable frames" in printed and "ms" in printed
    z = np.load(out)
    for key in ("frame_times", "frames", "keyframe_times", "keyframes", "wall_time_s", "objective_trace"):
        assert key in z.files
    assert z["frames"].shape == (len(z["frame_times"]), 4)
    r = orient(s.times, s.quats)  # the same defaults as the library
    np.testing.assert_allclose(z["frames"], r.frames.values, atol=1e-12)
    np.testing.assert_allclose(z["keyframes"], align(s.quats), atol=0)
    assert np.all(np.diff(z["objective_trace"][: len(r.solution.rounds[0].result.trace)]) <= 0)
    assert not list(out.parent.glob(".*tmp*"))  # the temporary file was renamed away
    # global subdivision and a frame cap
    assert main(["orient", kf, "--out", str(out), "--subdivision", "global", "--per-segment", "2",
                 "--quiet"]) == 0
    assert len(np.load(out)["frame_times"]) == 7 + 12
    assert main(["orient", kf, "--out", str(out), "--max-frames", "3", "--quiet"]) == 0
    assert len(np.load(out)["frame_times"]) <= 7 + 3


def test_cli_plot(tmp_path, capsys):
    from runner.cli import main

    png = tmp_path / "fig.png"
    kf = write(tmp_path / "k.json", {"times": [0, 1, 2.5, 3], "quaternions": [[1, 0, 0, 0], [0.7, 0.7, 0, 0],
                                                                               [0, 0, 1, 0], [0.5, 0.5, 0.5, 0.5]]})
    assert main(["orient", kf, "--out", str(tmp_path / "p.npz"), "--plot", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "figure 10" in capsys.readouterr().out


@pytest.mark.parametrize(
    "content, message",
    [
        ("{not json", "invalid JSON at line 1"),
        ('{"times": [0, 1]}', "missing field 'quaternions'"),
        ('{"times": [0, "a"], "quaternions": [[1,0,0,0],[1,0,0,0]]}', "field 'times' must be a list of numbers"),
        ('{"times": [0, 1], "quaternions": [[1,0,0,0],[1,0,0]]}', r"quaternions\[1\] is \[1, 0, 0\]"),
        ('{"times": [0, 1, 2], "quaternions": [[1,0,0,0],[1,0,0,0]]}', "3 times but 2 quaternions"),
        ('{"times": [0, 0], "quaternions": [[1,0,0,0],[1,0,0,0]]}', "strictly increasing"),
        ('{"times": [0, 1], "quaternions": [[1,0,0,0],[0,0,0,0]]}', "quaternion 1 is .* \\(zero\\)"),
        ('[1, 2]', "expected a JSON object"),
    ],
)
def test_cli_bad_input_messages(tmp_path, capsys, content, message):
    from runner.cli import main

    kf = tmp_path / "bad.json"
    kf.write_text(content)
    assert main(["orient", str(kf), "--out", str(tmp_path / "p.npz")]) == 2
    err = capsys.readouterr().err
    assert str(kf) in err and len(err.strip().splitlines()) == 1
    import re

    assert re.search(message, err), err


def test_cli_bad_paths(tmp_path, capsys):
    from runner.cli import main

    assert main(["orient", str(tmp_path / "missing.json"), "--out", str(tmp_path / "p.npz")]) == 2
    assert "does not exist" in capsys.readouterr().err
    kf = write(tmp_path / "k.json", {"times": [0, 1], "quaternions": [[1, 0, 0, 0], [0, 1, 0, 0]]})
    assert main(["orient", kf, "--out", str(tmp_path / "p.txt")]) == 2
    assert "ending in .npz" in capsys.readouterr().err


def test_quadrature_choice_gauss_by_default_uniform_on_request(E_star):
    s = LARGE["large_nonuniform"]
    opts = default_options(subdivision="global", per_segment=2)
    g = orient(s.times, s.quats, options=opts)
    assert g.points == 4 and g.rate is None
    u = orient(s.times, s.quats, options=opts, rate=100.0)
    assert u.rate == 100.0 and u.points is None
    # both integrate the same objective: the same optimum to well within the gap
    assert abs(gap(g, E_star[s.name]) - gap(u, E_star[s.name])) < 5e-5
    with pytest.raises(InputError, match="not both"):
        orient(s.times, s.quats, rate=100.0, points=3)


def test_renormalize_start_is_the_papers_starting_path_whatever_the_frames():
    """eq. 7's divisors: "start" is the spline through the keyframes and one variable frame per interval
    at its midpoint, on the unit sphere (sec. 3), whatever frames the solve uses; "keyframes" the plain
    spline; each checked against the unit term's integral computed here
    by dense midpoint sums (no solver quadrature; the solver's 4-point Gauss rule integrates this
    degree-12 polynomial to ~3e-4), the two readings ~130x apart."""
    s = MODERATE

    def unit_integral(times, values, n=20000):
        t = times[0] + (np.arange(n) + 0.5) * (times[-1] - times[0]) / n
        q = CubicSpline(times, values, bc_type="natural")(t)
        return float(np.mean((1.0 - np.einsum("ni,ni->n", q, q)) ** 2) * (times[-1] - times[0]))

    mids = 0.5 * (s.times[:-1] + s.times[1:])
    plain_mid = CubicSpline(s.times, s.quats, bc_type="natural")(mids)
    t_start = np.sort(np.concatenate([s.times, mids]))
    v_start = CubicSpline(s.times, s.quats, bc_type="natural")(t_start)
    v_start[1::2] = plain_mid / np.linalg.norm(plain_mid, axis=1, keepdims=True)
    expected = unit_integral(t_start, v_start)
    for per_segment in (1, 3):
        opts = default_options("paper", subdivision="global", per_segment=per_segment)
        start = orient(s.times, s.quats, form="paper", options=opts)
        assert start.solution.scales["unit"] == pytest.approx(expected, rel=2e-3)
    keyf = orient(s.times, s.quats, form="paper", renormalize="keyframes")
    assert keyf.solution.scales["unit"] == pytest.approx(unit_integral(s.times, s.quats), rel=2e-3)
