"""The forces term and its bounds (`solver.terms.force_bounds`, `solver.peak_bounds`): the gradient against
central differences, a hand-built rigid motion whose peaks are known in closed form, the capture filter
against the Butterworth response, and the wiring through `make_problem`."""
from pathlib import Path

import mujoco
import numpy as np
import pytest

from solver.frames import FrameSet
from solver.layout import StateLayout
from solver.path_context import PathContext
from solver.peak_bounds import CUTOFF_HZ, PeakBounds, capture_peaks, filter_capture, peak_bounds
from solver.terms.force_bounds import PeakForces

from conftest import fd_gradient, random_qpos

REPO = Path(__file__).resolve().parents[3]
SCENE = REPO / "models" / "run_and_step.xml"
G = 9.81


@pytest.fixture(scope="module")
def figure():
    model = mujoco.MjModel.from_xml_path(str(SCENE))
    return model, StateLayout.from_model(model)


def rigid_bounce(layout, t, amplitude, omega, x=-3.0, height=1.0):
    """(Y, Y1, Y2) of the figure in its identity pose translated rigidly: z = height + A sin(w t)."""
    Y = np.zeros((len(t), layout.nq))
    for slot in layout.quat_slots:
        Y[:, slot[0]] = 1.0
    Y[:, 0], Y[:, 2] = x, height + amplitude * np.sin(omega * t)
    Y1, Y2 = np.zeros_like(Y), np.zeros_like(Y)
    Y1[:, 2] = amplitude * omega * np.cos(omega * t)
    Y2[:, 2] = -amplitude * omega ** 2 * np.sin(omega * t)
    return Y, Y1, Y2


def lowest_site(model, qpos) -> float:
    """The lowest contact site's height at qpos [m] (MuJoCo's kinematics)."""
    d = mujoco.MjData(model)
    d.qpos[:] = qpos
    mujoco.mj_kinematics(model, d)
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s) for s in ("l_heel", "l_toe", "r_heel", "r_toe")]
    return float(d.site_xpos[ids, 2].min())


def test_a_rigid_bounce_has_the_peaks_of_newtons_second_law(figure):
    """A body translating rigidly needs F = m (x'' + g) at its root: peak |F| / (m g) = 1 + A w^2 / g and
    peak |x''| = A w^2; the term is the squared excess over the bounds, in body weights and in g."""
    model, layout = figure
    g = float(np.linalg.norm(model.opt.gravity))
    A, w = 0.05, 2 * np.pi * 2.0  # 5 cm at 2 Hz: 7.9 m/s^2
    t = np.linspace(0.0, 0.5, 201)  # sin(w t) = 1 at t = 1/8 s (sample 50)
    Y, Y1, Y2 = rigid_bounce(layout, t, A, w)
    bounds = PeakBounds(1.2, 0.5 * A * w ** 2, 0.0, 0.0)
    term = PeakForces(model, bounds)
    force, acc = term.peaks(t, Y, Y1, Y2)
    assert acc.max() == pytest.approx(A * w ** 2, rel=1e-12)
    np.testing.assert_allclose(force, np.abs(1.0 - A * w ** 2 * np.sin(w * t) / g), rtol=1e-9)
    f = term.evaluate(t, Y, Y1, Y2, grad=False).f
    k = np.argmin(np.sin(w * t))  # the bottom of the bounce: pushing up hardest, x'' = +A w^2
    expected = (1.0 + A * w ** 2 / g - 1.2) ** 2 + (0.5 * A * w ** 2 / g) ** 2
    assert f[k] == pytest.approx(expected, rel=1e-9)
    assert np.all(f[np.abs(np.sin(w * t)) < 0.2] == 0.0)  # within both bounds: nothing
    assert term.violation(Y, t) == pytest.approx(max(1.0 + A * w ** 2 / g - 1.2, 0.5 * A * w ** 2 / g), rel=1e-3)


def test_gradient_and_residual_match_central_differences(toy_model):
    """dY, dY', dY'' of sum f against central differences, and f = |r|^2 with J^T g against central
    differences of g . r, on random paths where both parts exceed their bounds at some points."""
    layout = StateLayout.from_model(toy_model)
    rng = np.random.default_rng(7)
    n = 6
    t = np.linspace(0.0, 1.0, n)
    Y = random_qpos(rng, layout, n, spread=0.3)
    Y1, Y2 = rng.normal(size=Y.shape), 4.0 * rng.normal(size=Y.shape)
    term = PeakForces(toy_model, PeakBounds(1.0, 9.0, 0.0, 0.0))
    term.set_knots(np.array([0.0, 0.5, 1.0]))
    term.prepare(t, Y, Y1, Y2)  # a knot slack at the points next to 0.5 s, fixed during the evaluations
    assert np.any(term._slack_at(t) > 0)
    ev = term.evaluate(t, Y, Y1, Y2)
    r = term.residual(PathContext(t, Y, Y1, Y2))
    for col in r.r.T:  # each part above its bound at some points and within it at others
        assert np.any(col > 0) and np.any(col == 0), "the check checks nothing"
    np.testing.assert_allclose((r.r ** 2).sum(1), ev.f, rtol=1e-12)
    for k, grad in enumerate((ev.dY, ev.dY1, ev.dY2)):
        def total(Z, k=k):
            moved = [Y, Y1, Y2]
            moved[k] = Z
            return term.evaluate(t, *moved, grad=False).f.sum()

        fd = fd_gradient(total, (Y, Y1, Y2)[k])
        np.testing.assert_allclose(grad, fd, atol=1e-6 * np.abs(fd).max() + 1e-12, err_msg=f"d/dY{k}")
    g = rng.normal(size=r.r.shape)
    D = [rng.normal(size=Y.shape) for _ in range(3)]

    def gr(eps):
        return float((g * term.residual(PathContext(t, *(a + eps * d for a, d in zip((Y, Y1, Y2), D)))).r).sum())

    fd = (gr(1e-6) - gr(-1e-6)) / 2e-6
    an = sum(float((p * d).sum()) for p, d in zip(r.vjp(g), D) if p is not None)
    assert an == pytest.approx(fd, rel=1e-5)


def test_peak_bounds_of_a_bounce_through_frames(figure):
    """The plain spline through frames of the bounce (accelerations 0 at both ends, as the natural
    spline's are) has the closed-form peaks to 0.5 % (a cubic spline's second derivative of a sine is off
    by about (w h)^2 / 12 = 0.2 % at frame spacing h = 1/80 s); with no capture the bounds are the plain's."""
    model, layout = figure
    A, w = 0.05, 2 * np.pi * 2.0
    times = np.linspace(0.0, 1.0, 81)  # two whole periods: sin = 0 at both ends
    Y, _, _ = rigid_bounce(layout, times, A, w)
    plain = FrameSet(times, Y, np.ones(Y.shape, bool), np.ones(len(times), bool))
    b = peak_bounds(model, plain)
    g = float(np.linalg.norm(model.opt.gravity))
    assert b.plain_pelvis_acceleration_ms2 == pytest.approx(A * w ** 2, rel=5e-3)
    assert b.plain_ground_force_bw == pytest.approx(1.0 + A * w ** 2 / g, rel=5e-3)
    assert (b.ground_force_bw, b.pelvis_acceleration_ms2) == (b.plain_ground_force_bw, b.plain_pelvis_acceleration_ms2)
    assert b.capture_ground_force_bw is None


def test_the_capture_filter_is_winters_two_pass_butterworth(figure):
    """At 120 Hz: a 6 Hz sine comes out at the -3 dB point (amplitude 1/sqrt(2), 2 %: the bilinear
    transform's warping), 1 Hz unchanged (0.5 %), 30 Hz nearly gone, with no phase lag; the quaternions
    stay unit."""
    _, layout = figure
    fs = 120.0
    t = np.arange(600) / fs
    gain = {}
    for f in (1.0, CUTOFF_HZ, 30.0):
        q = np.zeros((len(t), layout.nq))
        for slot in layout.quat_slots:
            q[:, slot[0]] = 1.0
        q[:, 0] = np.sin(2 * np.pi * f * t)
        out = filter_capture(t, q, layout)[:, 0]
        mid = slice(120, 480)  # away from the ends' padding
        gain[f] = np.abs(out[mid]).max()
        if f == 1.0:
            assert np.argmax(out[mid]) == np.argmax(q[mid, 0])  # zero lag
        assert np.allclose(np.linalg.norm(filter_capture(t, q, layout)[:, layout.quat_slots[0]], axis=1), 1.0)
    assert gain[1.0] == pytest.approx(1.0, abs=0.005)
    assert gain[CUTOFF_HZ] == pytest.approx(1 / np.sqrt(2), abs=0.02)
    assert gain[30.0] < 0.01


def test_capture_peaks_see_the_motion_not_the_markers_noise(figure):
    """A 1 Hz bounce of 5 cm (2 m/s^2) captured with 1 mm of 30 Hz jitter (36 m/s^2 raw): the filtered
    capture's peak pelvis acceleration is the bounce's (5 %), its peak force 1 + A w^2 / g."""
    model, layout = figure
    A, w = 0.05, 2 * np.pi * 1.0
    t = np.arange(480) / 120.0
    Y, _, _ = rigid_bounce(layout, t, A, w)
    Y[:, 2] += 0.01 + A - lowest_site(model, Y[0])  # the bottom of the bounce 1 cm above the floor
    Y[:, 2] += 0.001 * np.sin(2 * np.pi * 30.0 * t)
    force, acc = capture_peaks(model, t, Y, (1.0, 3.0))
    assert acc == pytest.approx(A * w ** 2, rel=0.05)
    assert force == pytest.approx(1.0 + A * w ** 2 / G, rel=0.01)


def test_make_problem_carries_the_bounds_with_the_term(figure):
    """--terms all builds the forces term with the problem's bounds (the plain spline's without a
    capture), zero on the plain spline (its peaks there are the bounds, read at the same instants); other terms leave the bounds out."""
    from solver.keyframe_file import read_keyframes
    from solver.problem import make_problem

    model, layout = figure
    keyframes, info = read_keyframes(REPO / "models" / "run_and_step.keyframes.json", layout)
    problem = make_problem(model, keyframes, "all", contacts=info.contacts, rate=100.0)
    assert "forces" in problem.weights
    term = problem.objective.terms[problem.objective.names.index("forces")]
    assert term.bounds is problem.force_bounds and problem.force_bounds.capture_ground_force_bw is None
    ev = problem.objective.evaluate(problem.initial.times, problem.initial.values, grad=False)
    from solver.objective import RENORMALIZE_FLOOR

    assert ev.integrals["forces"] < RENORMALIZE_FLOOR  # zero up to rounding: eq. 7 leaves its scale at 1
    assert make_problem(model, keyframes, "unit,smooth", rate=100.0).force_bounds is None


def test_the_summary_prints_the_bounds_and_marks_the_rows_above_them():
    """The two bounded rows carry "<= B" in their label; a figure above B by more than 1 % and the printed
    digit is marked "over bound" (with "worse" when also worse than the plain spline); within: unmarked."""
    from types import SimpleNamespace

    from runner.console import BOUND_LEGEND, OVER, WORSE, summary_table

    base = {"max_penetration_mm": 0.0, "penetration_mm_by_site": {"l_toe": 0.0}, "max_norm_deviation": 0.0,
            "max_hyperextension_deg": 0.0, "keyframe_error": 0.0, "rms_joint_torque_Nm": 100.0,
            "peak_joint_torque_Nm": 150.0, "flight_s": 0.2, "rms_root_force_flight_N": 600.0,
            "peak_root_force_flight_N": 700.0, "rms_root_torque_flight_Nm": 40.0, "peak_root_torque_flight_Nm": 70.0,
            "rms_root_force_ground_bw": 1.1, "peak_root_force_ground_bw": 1.72, "peak_pelvis_acceleration_ms2": 5.9}
    sol = SimpleNamespace(E_initial=1.0, E_final=0.5, integrals_initial={"forces": 0.0, "torque": 1.0},
                          integrals_final={"forces": 0.1, "torque": 1.0}, initial=SimpleNamespace(count=8),
                          frames=SimpleNamespace(n_variable=8), rounds=[1], n_evals=10, wall_time_s=1.0)
    bounds = PeakBounds(2.54, 16.4, 1.72, 5.9, 2.54, 16.4)
    opt = {**base, "peak_root_force_ground_bw": 2.56, "peak_pelvis_acceleration_ms2": 48.7}
    lines = summary_table(base, opt, sol, {"forces": 1000.0}, force_bounds=bounds).splitlines()
    pelvis = next(x for x in lines if x.startswith("peak pelvis acceleration [m/s^2] <= 16.4"))
    force = next(x for x in lines if x.startswith("peak root force on ground [body wt] <= 2.54"))
    assert pelvis.endswith(f"{WORSE}, {OVER}") and "forces" in pelvis
    assert not force.endswith(OVER)  # 2.56 is within 1 % and 0.01 of 2.54
    assert BOUND_LEGEND in lines and bounds.describe() in lines
    within = {**base, "peak_root_force_ground_bw": 2.4}
    text = summary_table(base, within, sol, {"forces": 1000.0}, force_bounds=bounds)
    assert OVER not in text.replace(BOUND_LEGEND, "")
    assert "<=" not in summary_table(base, opt, sol, {"torque": 1.0})  # no forces term: no bounds


def test_knot_slack_reaches_the_kink_of_a_piecewise_linear_signal():
    """x(t) piecewise linear with kinks at the knots (as the spline's x''): each knot's neighbouring
    points carry |x(knot)| - |x(point)|, so |x| + slack is the kink's value there; far points carry 0."""
    from solver.terms.force_bounds import knot_slack

    knots = np.array([0.0, 0.1013, 0.2, 0.3])
    h = 0.0025
    t = np.arange(h / 2, 0.3, h)
    peak = {0.0: 0.0, 0.1013: 5.0, 0.2: -2.0, 0.3: 1.0}

    def x_of(s):
        z = np.interp(s, knots, [peak[k] for k in knots])
        return np.stack([z, 0.5 * z, np.zeros_like(z)], axis=1)

    x = x_of(t)
    slack = knot_slack(t, knots, (x, 2.0 * x))
    norm = np.linalg.norm(x, axis=1)
    for k in (0.1013, 0.2):
        for near in (np.flatnonzero(t < k)[-1], np.flatnonzero(t > k)[0]):
            assert norm[near] + slack[near, 0] == pytest.approx(np.linalg.norm(x_of(np.array([k]))[0]), rel=1e-9)
            assert slack[near, 1] == pytest.approx(2.0 * slack[near, 0], rel=1e-9)
    assert np.all(slack[np.abs(t - 0.15) < 0.02] == 0.0) and np.all(slack >= 0.0)
