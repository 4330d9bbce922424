"""Physical plausibility (paper sec. 6, docs/design.md "Judging a result"): the inverse-dynamics figures of `solver.metrics` against physical
expectations and MuJoCo, the lagged flight indicator of the root term, the shared reverse pass of
the dynamics terms, adaptive against global refinement, the plots, and the run-and-step regression
with every term on (`dynsplines run-and-step --terms all`).
"""
import json
from pathlib import Path

import mujoco
import numpy as np
import pytest

from runner.cli import main
from solver.frames import FrameSet
from solver.inverse_dynamics import constraint_free_copy
from solver.layout import StateLayout
from solver.metrics import dynamics_metrics, dynamics_series, path_metrics
from solver.terms.dynamics import RootResidual

from conftest import fd_gradient

REPO = Path(__file__).resolve().parents[2]
SCENE = REPO / "models" / "run_and_step.xml"
KEYFRAMES = REPO / "models" / "run_and_step.keyframes.json"


@pytest.fixture(scope="module")
def model():
    return mujoco.MjModel.from_xml_path(str(SCENE))


@pytest.fixture(scope="module")
def layout(model):
    return StateLayout.from_model(model)


@pytest.fixture(scope="module")
def keyframes(layout):
    from solver.keyframe_file import read_keyframes

    return read_keyframes(KEYFRAMES, layout)[0]


def still(model, layout, height, x=-3.0, duration=1.0, m=5):
    """Frames of a figure standing still in the identity pose, root at (x, 0, height) [m]."""
    q = np.zeros(layout.nq)
    for slot in layout.quat_slots:
        q[slot[0]] = 1.0
    q[:3] = [x, 0.0, height]
    return np.linspace(0.0, duration, m), np.tile(q, (m, 1))


def lowest_site_height(model, qpos):
    d = mujoco.MjData(model)
    d.qpos[:] = qpos
    mujoco.mj_kinematics(model, d)
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s) for s in ("l_heel", "l_toe", "r_heel", "r_toe")]
    return float(d.site_xpos[ids, 2].min())


# ------------------------------------------------------------------------------ metrics, physically


def test_still_in_the_air_is_flight_and_the_root_carries_the_weight(model, layout):
    """At rest 1 m above the open floor: all of it is flight, and the residual force on the root is
    the weight m g [N], straight up; the joint torques are MuJoCo's gravity torques."""
    times, frames = still(model, layout, height=2.5)
    s = dynamics_series(model, times, frames, rate=200.0)
    m = dynamics_metrics(s)
    mass = float(model.body_subtreemass[int(model.jnt_bodyid[0])])
    weight = mass * -model.opt.gravity[2]
    assert 60.0 < mass < 80.0  # a 70 kg figure
    assert s["flight"].all() and m["flight_s"] == pytest.approx(1.0, abs=0.01)
    np.testing.assert_allclose(s["root_force"], np.tile([0.0, 0.0, weight], (len(s["t"]), 1)), atol=1e-6)
    assert m["rms_root_force_flight_N"] == pytest.approx(weight, rel=1e-9)
    assert m["peak_root_force_flight_N"] == pytest.approx(weight, rel=1e-9)
    # independent: mj_inverse at rest (qvel = qacc = 0) on the constraint-free model
    mc = constraint_free_copy(model)
    d = mujoco.MjData(mc)
    d.qpos[:] = frames[0]
    mujoco.mj_inverse(mc, d)
    np.testing.assert_allclose(s["root_torque"][0], d.qfrc_inverse[3:6], atol=1e-8)
    balls = [j for j in layout.joints if j.kind == "ball"]
    dofs = [j.dofadr + i for j in balls for i in range(3)]
    np.testing.assert_allclose(s["joint_torque"][0], d.qfrc_inverse[dofs], atol=1e-8)
    assert s["joint_torque"].shape[1] == 33 and len(s["joint_names"]) == 11
    rms = np.sqrt((d.qfrc_inverse[dofs] ** 2).sum())  # RMS over time of the 33-vector's norm
    assert m["rms_joint_torque_Nm"] == pytest.approx(rms, rel=1e-9)


def test_standing_on_the_floor_is_not_flight(model, layout):
    times, frames = still(model, layout, height=1.0)
    frames[:, 2] -= lowest_site_height(model, frames[0])  # lowest contact site exactly on the floor
    m = dynamics_metrics(dynamics_series(model, times, frames, rate=200.0))
    assert m["flight_s"] == 0.0
    assert np.isnan(m["rms_root_force_flight_N"]) and np.isnan(m["peak_root_torque_flight_Nm"])
    # 2 cm above the floor is inside the contact band (phi < 0.5), 4 cm is flight
    frames[:, 2] += 0.02
    assert dynamics_metrics(dynamics_series(model, times, frames, rate=200.0))["flight_s"] == 0.0
    frames[:, 2] += 0.02
    assert dynamics_metrics(dynamics_series(model, times, frames, rate=200.0))["flight_s"] == pytest.approx(1.0, abs=0.01)


def test_a_foot_rolled_about_its_long_axis_puts_its_sole_s_inner_edge_into_the_floor(model, layout):
    """The figure standing with its soles on the floor, its left foot turned 20 degrees about its long axis (x)
    at the ankle: the sole's inner edge site at (x, y, z) in the foot's frame goes to the ankle's height plus
    y sin 20 + z cos 20 (a rotation by hand), into the floor; the soles' metric names it with that depth. The
    outer edge rises out of the floor, and the heel and toe, on the axis, stay out of it."""
    times, frames = still(model, layout, height=1.0)
    frames[:, 2] -= lowest_site_height(model, frames[0])
    d = mujoco.MjData(model)
    d.qpos[:] = frames[0]
    mujoco.mj_kinematics(model, d)
    ankle = d.body("l_foot").xpos[2]
    a = np.radians(20.0)
    slot = model.joint("l_ankle").qposadr[0]
    frames[:, slot:slot + 4] = [np.cos(a / 2), np.sin(a / 2), 0.0, 0.0]
    _, y, z = model.site("l_sole_in").pos
    assert y < 0  # the inner edge of the left foot: toward the body's midline
    m = path_metrics(model, times, frames, dynamics=False)
    depth = -1000 * (ankle + y * np.sin(a) + z * np.cos(a))  # [mm] 12.2
    assert m["sole_mm_by_site"]["l_sole_in"] == pytest.approx(depth, abs=5e-4)  # rounded to the micrometre
    assert m["sole_mm_by_site"]["l_sole_out"] == 0.0 and m["max_penetration_mm"] == 0.0


def test_path_metrics_report_the_dynamics_figures_against_mujoco(model, layout, keyframes):
    """The plain spline of the shipped clip: torques of a few samples against mj_inverse, and the
    summary figures against their definitions."""
    fs = FrameSet.from_keyframes(keyframes, layout.quat_slots)
    out = path_metrics(model, fs.times, fs.values, keyframes, rate=1000.0)
    for key in ("rms_joint_torque_Nm", "peak_joint_torque_Nm", "flight_s", "rms_root_force_flight_N",
                "peak_root_force_flight_N", "rms_root_torque_flight_Nm", "peak_root_torque_flight_Nm"):
        assert np.isfinite(out[key]), key
    s = dynamics_series(model, fs.times, fs.values, rate=1000.0)
    F = np.linalg.norm(s["root_force"][s["flight"]], axis=1)
    assert out["rms_root_force_flight_N"] == pytest.approx(np.sqrt(np.mean(F**2)))
    assert out["peak_joint_torque_Nm"] == pytest.approx(s["joint_torque_norm"].max())
    assert 0.1 < out["flight_s"] < 0.5  # the plain spline is airborne about 0.25 s of 1.7 s
    # MuJoCo's inverse dynamics at a few samples, from the spline's own derivatives
    from solver.kinematics import TangentMap

    tm = TangentMap.from_layout(layout)
    mc = constraint_free_copy(model)
    d = mujoco.MjData(mc)
    idx = [100, 700, 1300]
    t = s["t"][idx]
    Y, Y1, Y2 = (fs.path(t, nu) for nu in (0, 1, 2))
    mo = tm.motion(Y, Y1, Y2)
    balls = [j for j in layout.joints if j.kind == "ball"]
    dofs = [j.dofadr + i for j in balls for i in range(3)]
    for k, i in enumerate(idx):
        d.qpos[:], d.qvel[:], d.qacc[:] = Y[k], mo.qvel[k], mo.qacc[k]
        mujoco.mj_inverse(mc, d)
        np.testing.assert_allclose(s["joint_torque"][i], d.qfrc_inverse[dofs], atol=1e-6)
        np.testing.assert_allclose(s["root_force"][i], d.qfrc_inverse[:3], atol=1e-6)


# ------------------------------------------------------------------------------ the terms


def test_lagged_flight_indicator(model, layout):
    """After `prepare`, phi_eff = phi at the prepared path, never falls below the prepared value when
    the feet come down, rises when they go up, and the gradient matches finite differences."""
    times, frames = still(model, layout, height=1.0, m=4)
    frames[:, 2] += 0.03 - lowest_site_height(model, frames[0])  # 3 cm up: phi between 0 and 1
    rng = np.random.default_rng(3)
    frames[1:-1] += rng.normal(scale=0.01, size=frames[1:-1].shape)
    fs = FrameSet(times, frames, np.zeros_like(frames, bool), np.ones(len(times), bool))
    t = np.linspace(0.05, 0.95, 7)
    Y, Y1, Y2 = (fs.path(t, nu) for nu in (0, 1, 2))
    lagged, path = RootResidual(model), RootResidual(model, flight="path")
    f_path = path.evaluate(t, Y, Y1, Y2, grad=False).f
    lagged.prepare(t, Y, Y1, Y2)
    np.testing.assert_allclose(lagged.evaluate(t, Y, Y1, Y2, grad=False).f, f_path, rtol=1e-12)
    # moving the root straight up or down leaves the wrench as it is; only the indicator changes
    e = RootResidual.LAG_SMOOTHING
    down, up = Y.copy(), Y.copy()
    down[:, 2] -= 0.02
    up[:, 2] += 0.05
    wr = lagged.wrench(Y, Y1, Y2)
    r = (wr[:, :3] ** 2).sum(1) + (wr[:, 3:] ** 2).sum(1) / lagged.torque_arm**2  # f = phi r
    phi0 = f_path / r
    assert np.all((phi0 > 0.1) & (phi0 < 0.9))
    f_down = lagged.evaluate(t, down, Y1, Y2, grad=False).f
    assert np.all(f_down >= (phi0 - e / 2) * r)  # lowering the feet gains at most e/2 of phi ...
    assert np.all(path.evaluate(t, down, Y1, Y2, grad=False).f < 0.5 * f_path)  # ... "path": all of it
    f_up, f_up_own = lagged.evaluate(t, up, Y1, Y2, grad=False).f, path.evaluate(t, up, Y1, Y2, grad=False).f
    assert np.all(f_up > 2 * f_path) and np.all(f_up >= f_up_own - e / 2 * r)  # lifting them costs
    # gradient of the lagged term at a point away from the prepared one
    Z = Y + rng.normal(scale=0.003, size=Y.shape)
    ev = lagged.evaluate(t, Z, Y1, Y2)
    want = fd_gradient(lambda X: lagged.evaluate(t, X, Y1, Y2, grad=False).f.sum(), Z)
    np.testing.assert_allclose(ev.dY, want, rtol=0, atol=1e-6 * np.abs(want).max())
    with pytest.raises(Exception, match="flight mode"):
        RootResidual(model, flight="sometimes")


# ------------------------------------------------------------------------------ run-and-step --terms all


@pytest.fixture(scope="module")
def all_terms(tmp_path_factory):
    d = tmp_path_factory.mktemp("all")
    out = d / "run_and_step_all.npz"
    code = main(["run-and-step", "--terms", "all", "--no-render", "--quiet", "--save-path", str(out),
                 "--plot", str(d / "plots")])
    assert code == 0
    z = np.load(out)
    return json.loads(str(z["metrics_json"])), z, d / "plots"


@pytest.mark.slow
def test_run_and_step_all_terms_is_more_physical_and_keeps_the_bounds(all_terms):
    """`--terms all` solves the least change with the force bounds (solver/constraints/forces.py),
    judged by the independent metrics (solver/metrics.py at 1000 Hz, runner/jolts.py)."""
    metrics, z, _ = all_terms
    plain, opt = metrics["plain"], metrics["optimized"]
    stalled = json.loads(str(z["unmet_json"]))  # what the solve reports out of reach [SI]
    # the main job's bounds, up to what the solve reports it could not meet (in m)
    assert opt["max_penetration_mm"] <= 1.0 + 1e3 * stalled.get("penetration", 0.0) + 0.1  # 0.1 mm: 1000 Hz vs 1600 Hz
    assert opt["keyframe_error"] < 1e-9
    assert opt["max_norm_deviation"] <= 0.05
    assert opt["max_hyperextension_deg"] <= 2.0
    # physical plausibility: nearly no wrench in flight (the plain spline: about its body weight)
    assert opt["rms_root_force_flight_N"] <= 0.25 * plain["rms_root_force_flight_N"]
    # ... without ending the flight phases
    assert opt["flight_s"] >= 0.5 * plain["flight_s"]
    # ... and no jolts: RMS joint torque at most 1.25x the larger of the plain spline's and the capture's
    motion = metrics["motion"]["optimized"]
    capture_torque = motion["reference"]["rms_joint_torque_Nm"]
    assert opt["rms_joint_torque_Nm"] <= 1.25 * max(plain["rms_joint_torque_Nm"], capture_torque)
    # ... and forces the body makes: within the bounds (the capture's filtered peaks) to their 5 % tolerance
    bounds = metrics["force_bounds"]
    assert bounds["capture_ground_force_bw"] is not None  # the keyframe file names its clip
    assert opt["peak_root_force_ground_bw"] <= 1.05 * bounds["ground_force_bw"]
    # the pelvis: within its bound and 5 % tolerance at every frame of the saved spline (the root's x'' of
    # its natural cubic spline, computed here) and at 1000 Hz (the metrics): a cubic's acceleration is
    # linear between frames, so its peak is at a frame, and every frame is a point where the bound is posed
    # (the keyframes by `solver.quadrature.quadrature_points`, the variable frames by `on_points`)
    from scipy.interpolate import CubicSpline

    opts = json.loads(str(z["options_json"]))
    ft = z["frame_times"]
    root = CubicSpline(ft, z["frames"][:, :3], bc_type="natural")(ft, 2)
    assert np.linalg.norm(root, axis=1).max() <= 1.05 * bounds["pelvis_acceleration_ms2"]
    assert opt["peak_pelvis_acceleration_ms2"] <= 1.05 * bounds["pelvis_acceleration_ms2"]
    assert opts["terms"] == "all" and "min_gap" in opts["solve"]  # --terms all, solved by the least change


@pytest.mark.slow
def test_plots_are_written(all_terms):
    _, _, plots = all_terms
    names = sorted(p.name for p in plots.glob("*.png"))
    assert names == ["dynamics.png", "euler_lagrange.png", "foot_heights.png", "objective.png"]
    for p in plots.glob("*.png"):
        assert p.stat().st_size > 20_000  # a real figure, not an empty canvas


def test_summary_lists_the_dynamics_rows_and_the_constraints(model, layout, keyframes):
    """With the force bounds the summary has the dynamics rows, the bound rows and each constraint's
    worst value over its tolerance, a target column naming them."""
    import solver
    from runner.console import summary_table
    from solver.keyframe_file import read_keyframes

    contacts = read_keyframes(KEYFRAMES, layout)[1].contacts  # the flights between them: the flight wrench
    problem = solver.build_problem(model, solver.ProblemSpec(keyframes, contacts, forces=True))
    sol = solver.solve_problem(problem, solver.LeastChangeOptions(max_subproblems=1, max_evals=3))
    plain = path_metrics(model, sol.initial.times, sol.initial.values, keyframes, rate=200.0)
    opt = path_metrics(model, sol.frames.times, sol.frames.values, keyframes, rate=200.0)
    text = summary_table(plain, opt, sol, force_bounds=problem.force_bounds)
    for row in ("RMS joint torque [N m]", "peak joint torque [N m]", "flight (all feet clear) [s]",
                "RMS root force in flight [N]", "peak root force in flight [N]",
                "RMS root torque in flight [N m]", "peak root torque in flight [N m]",
                "peak root force on ground [body wt]", "penetration: worst / tolerance",
                "flight wrench: worst / tolerance"):
        assert row in text, row
    assert "force bounds: ground" in text and "target: the constraint" in text
