"""The summary says where the optimized path is worse than the plain spline, which rows the constraints
bound, prints no "nan" and no negative zero, and has the figures that come with the force bounds: the
root force on the ground."""
from pathlib import Path
from types import SimpleNamespace

import mujoco
import numpy as np
import pytest

from runner.console import (
    LEGEND,
    MISSING_LEGEND,
    MOTION_LEGEND,
    TARGET_LEGEND,
    cell,
    comparison_rows,
    motion_metrics_table,
    summary_table,
)
from runner.verdict import FLIGHT_CHANGE, MOTION_MARGINS, TOWARD, WORSE, motion_mark, motion_worse
from solver.layout import StateLayout
from solver.metrics import dynamics_metrics, dynamics_series

REPO = Path(__file__).resolve().parents[2]


def metrics(**over):
    """path_metrics-like figures: run-and-step's plain spline and its default-terms optimization."""
    m = {"max_penetration_mm": 101.43, "penetration_mm_by_site": {"l_toe": 101.43, "r_toe": 79.0},
         "max_norm_deviation": 0.0508, "max_hyperextension_deg": 0.0, "keyframe_error": 2.2e-16,
         "rms_joint_torque_Nm": 103.5, "peak_joint_torque_Nm": 178.4, "flight_s": 0.252,
         "rms_root_force_flight_N": 624.8, "peak_root_force_flight_N": 761.5,
         "rms_root_torque_flight_Nm": 40.6, "peak_root_torque_flight_Nm": 71.9,
         "peak_pelvis_acceleration_ms2": 20.0, "rms_root_force_ground_bw": 1.1, "peak_root_force_ground_bw": 2.5}
    return {**m, **over}


#: the constraints of the least change (`solver.constraint_set`; with --terms all also FORCE_CONSTRAINTS)
CONSTRAINTS = ("penetration", "planted", "slide", "flight", "ground", "hinge", "hyperextension", "rom", "unit",
               "acceleration")
FORCE_CONSTRAINTS = ("flight wrench", "ground force")


def solution(names=CONSTRAINTS):
    """A least-change Solution's fields the summary reads: each constraint's worst value / tolerance."""
    return SimpleNamespace(E_initial=0.0, E_final=0.4,
                           integrals_initial=dict.fromkeys(names, 3.0), integrals_final=dict.fromkeys(names, 0.5),
                           initial=SimpleNamespace(count=8),
                           frames=SimpleNamespace(count=30, n_variable=22), rounds=[1, 2], n_evals=450, wall_time_s=8.9)


def marked(text):
    return {line.rsplit("  ", 1)[0].split("  ")[0].strip() for line in text.splitlines() if line.endswith(f"  {WORSE}")}


def test_rows_where_the_optimized_path_is_worse_are_marked_with_a_legend():
    plain = metrics()
    opt = metrics(max_penetration_mm=0.0, penetration_mm_by_site={"l_toe": 0.0, "r_toe": 0.3},
                  max_norm_deviation=0.0012, keyframe_error=1.1e-15,  # round-off: not worse
                  rms_joint_torque_Nm=111.5, peak_joint_torque_Nm=169.5, flight_s=0.425,
                  rms_root_force_flight_N=842.2, peak_root_force_flight_N=1715.1,
                  rms_root_torque_flight_Nm=120.1, peak_root_torque_flight_Nm=71.9,
                  max_hyperextension_deg=1.5)
    text = summary_table(plain, opt, solution())
    assert marked(text) == {"RMS joint torque [N m]", "flight (all feet clear) [s]", "RMS root force in flight [N]",
                            "peak root force in flight [N]", "RMS root torque in flight [N m]",
                            "max hyperextension [deg]"}
    assert LEGEND in text.splitlines()
    # a constraint's worst value over its tolerance is not an acceptance figure
    assert not any(line.endswith(WORSE) for line in text.splitlines() if "worst / tolerance" in line)


def test_flight_is_worse_when_it_changes_either_way():
    for flight, worse in [(0.252, False), (0.227, False), (0.252 * (1 - FLIGHT_CHANGE) - 0.02, True), (0.425, True)]:
        rows = {r[0]: r[4] for r in comparison_rows(metrics(), metrics(flight_s=flight))}
        assert rows["flight (all feet clear) [s]"] is worse, flight


def test_the_force_bounds_add_the_ground_rows_with_their_bound():
    from solver.peak_bounds import PeakBounds

    plain, opt = metrics(), metrics(peak_pelvis_acceleration_ms2=45.0, peak_root_force_ground_bw=4.2)
    default = summary_table(plain, opt, solution())
    assert "peak pelvis acceleration [m/s^2]" in marked(default) and "on ground" not in default  # no jolts: always
    bounds = PeakBounds(3.0, 30.0, 2.5, 20.0)
    text = summary_table(plain, opt, solution(CONSTRAINTS + FORCE_CONSTRAINTS), force_bounds=bounds)
    assert "RMS root force on ground [body wt]" in text and bounds.describe() in text.splitlines()
    assert _row(text, "peak root force on ground [body wt] <= 3.00").endswith("over bound")


@pytest.fixture(scope="module")
def model():
    return mujoco.MjModel.from_xml_path(str(REPO / "models" / "run_and_step.xml"))


def test_standing_still_the_ground_carries_one_body_weight_and_the_pelvis_does_not_accelerate(model):
    layout = StateLayout.from_model(model)
    q = np.zeros(layout.nq)
    for slot in layout.quat_slots:
        q[slot[0]] = 1.0
    q[:3] = [-3.0, 0.0, 1.0]  # identity pose, soles on the floor
    m = dynamics_metrics(dynamics_series(model, np.linspace(0, 1, 5), np.tile(q, (5, 1)), rate=200.0))
    assert m["peak_pelvis_acceleration_ms2"] == pytest.approx(0.0, abs=1e-9)
    assert m["rms_root_force_ground_bw"] == pytest.approx(1.0, rel=1e-9)
    assert m["peak_root_force_ground_bw"] == pytest.approx(1.0, rel=1e-9)




def _row(text, label):
    """The line of the table whose label is `label` (the label, then two spaces or more)."""
    lines = [line for line in text.splitlines() if line.startswith(label + "  ")]
    assert len(lines) == 1, (label, text)
    return lines[0]


def _target(text, label):
    """The target column of a row: what follows the two value columns (without the worse mark)."""
    head = next(line for line in text.splitlines() if line.rstrip().endswith("target"))
    start = head.index("target")
    return _row(text, label)[start:].removesuffix(WORSE).strip()


def test_a_motion_without_flight_prints_a_dash_not_nan():
    no_flight = dict(flight_s=0.0, rms_root_force_flight_N=float("nan"), peak_root_force_flight_N=float("nan"),
                     rms_root_torque_flight_Nm=float("nan"), peak_root_torque_flight_Nm=float("nan"))
    text = summary_table(metrics(**no_flight), metrics(**no_flight), solution())
    assert "nan" not in text.lower()
    assert _row(text, "RMS root force in flight [N]").split()[-2:] == ["-", "-"]
    assert MISSING_LEGEND in text.splitlines()
    assert MISSING_LEGEND not in summary_table(metrics(), metrics(), solution())


def test_no_negative_zero_anywhere():
    plain = metrics(max_hyperextension_deg=-0.0, keyframe_error=-0.0)
    opt = metrics(max_hyperextension_deg=-1e-9, rms_root_torque_flight_Nm=-0.004)
    text = summary_table(plain, opt, solution())
    assert "-0.0" not in text and "-0.00" not in text, text
    assert _row(text, "max hyperextension [deg]").split()[-3:-1] == ["0.00", "0.00"]  # then the target
    assert cell("{:.1e}", -0.0) == "0.0e+00" and cell("{:.2f}", -0.004) == "0.00"
    assert cell("{:.2f}", -0.006) == "-0.01" and cell("{:.1f}", None) == "-" and cell("{:.1f}", float("inf")) == "-"


def test_the_summary_says_which_rows_the_constraints_bound():
    """Without the force bounds the dynamics rows that come out worse are rows no constraint bounds."""
    plain = metrics()
    opt = metrics(max_penetration_mm=0.0, penetration_mm_by_site={"l_toe": 0.0, "r_toe": 0.0},
                  rms_joint_torque_Nm=195.6, peak_joint_torque_Nm=553.1, rms_root_force_flight_N=2197.9,
                  peak_root_force_flight_N=3840.1, rms_root_torque_flight_Nm=282.3, peak_root_torque_flight_Nm=667.1)
    text = summary_table(plain, opt, solution())
    assert TARGET_LEGEND in text.splitlines()
    for label in ("RMS joint torque [N m]", "peak joint torque [N m]", "RMS root force in flight [N]",
                  "peak root force in flight [N]", "RMS root torque in flight [N m]",
                  "peak root torque in flight [N m]"):
        assert label in marked(text)
        assert _target(text, label) == "", label
    assert _target(text, "max penetration [mm] (1000 Hz)") == "penetration"
    assert _target(text, "  l_toe [mm]") == "penetration"
    assert _target(text, "max |1 - |q||") == "unit"
    assert _target(text, "max hyperextension [deg]") == "hyperextension"
    assert _target(text, "  penetration: worst / tolerance") == "penetration"
    assert _target(text, "flight (all feet clear) [s]") == "flight,ground"
    assert _target(text, "peak pelvis acceleration [m/s^2]") == "acceleration"
    assert _target(text, "keyframe error (fixed comps)") == ""  # met exactly: no constraint
    with_forces = summary_table(plain, opt, solution(CONSTRAINTS + FORCE_CONSTRAINTS))
    assert _target(with_forces, "peak root torque in flight [N m]") == "flight wrench"
    assert _target(with_forces, "RMS joint torque [N m]") == ""


def _motion(path_over=None):
    block = {"penetration_mm": {"mean": 0.0, "max": 0.0}, "float_contact_mm": 2.4, "float_physdiff_mm": 5.7,
             "skate_mm": 2.77, "skate_contact_mm": 1.81, "phys_err_mm": 8.5, "skating_ratio": 0.265,
             "skating_ratio_contacts": 0.034, "flight_time_s": 0.0, "jerk_root_m_s3": 1250.0,
             "jerk_sites_m_s3": 1925.0, "float_stance_mm": 2.5, "flight_in_stance_s": 0.0,
             "off_hinge_knee_deg": 0.0, "off_hinge_elbow_deg": 30.0, "rom_excess_deg": 1.0}
    err = {"joint_orientation_deg": {"hip": {"mean": 1.0, "max": 2.0}}, "site_position_cm": {"toe": {"mean": 1.0,
           "max": 2.0}}, "root_position_cm": {"mean": -0.0, "max": 1.0}, "accel_error_root_m_s2": float("nan"),
           "accel_error_sites_m_s2": 3.0}
    return {"reference": block, "path": {**block, **(path_over or {})}, "error": err, "frames": 10, "fps": 120.0}


def test_the_motion_metrics_table_prints_no_nan_and_no_negative_zero():
    text = motion_metrics_table(_motion({"float_contact_mm": float("nan"), "skate_mm": -0.0}), _motion())
    assert "nan" not in text.lower() and "-0.0" not in text, text


# --- the motion rows: feet rows of the summary and the motion-metrics table against the capture ---

@pytest.mark.parametrize("key, plain, ok, bad", [
    ("float_contact_mm", 5.0, 5.0 * 1.01 + 0.1 - 1e-6, 5.0 * 1.01 + 0.1 + 1e-3),  # 1 % and 0.1 mm
    ("float_contact_mm", 0.0, 0.099, 0.101),  # the floor rules near zero
    ("skate_contact_mm", 2.0, 2.02 + 0.049, 2.02 + 0.051),
    ("skating_ratio_contacts", 0.1, 0.111 - 1e-6, 0.111 + 1e-3),
    ("joint_orientation_deg", 24.0, 24.24 + 0.049, 73.5),  # the ledge clip's max: 24 -> 73.5 deg
    ("cone_peak", 100.0, 101.09, 101.11),
])
def test_motion_rows_are_worse_beyond_one_percent_and_their_floor(key, plain, ok, bad):
    assert not motion_worse(key, plain, ok)
    assert motion_worse(key, plain, bad)
    assert not motion_worse(key, plain, plain * 0.5)  # lower is never worse
    assert MOTION_MARGINS[key][1]  # every floor states its reason


def test_flight_time_is_worse_when_further_from_the_capture_by_more_than_a_frame():
    frame = 1 / 120
    # the jog: capture 0.450 s, plain 0.342 s, optimized 0.750 s
    assert motion_worse("flight_time_s", 0.342, 0.750, frame, capture=0.450)
    assert not motion_worse("flight_time_s", 0.342, 0.450 + 0.100, frame, capture=0.450)  # 0.100 s off, not 0.108
    assert motion_worse("flight_time_s", 0.440, 0.440 - 0.02, frame, capture=0.450)  # shorter and further away
    assert not motion_worse("flight_time_s", 0.440, 0.450 + 0.01 * 1.01 + frame - 1e-6, frame, capture=0.450)
    assert not motion_worse("flight_time_s", 0.342, 0.9, frame, capture=None)  # no capture: not judged
    # flight-phase error (extra + missed): higher is worse beyond one frame
    assert motion_worse("flight_phase_error_s", 0.05, 0.05 * 1.01 + frame + 1e-4, frame)
    assert not motion_worse("flight_phase_error_s", 0.05, 0.05 * 1.01 + frame - 1e-4, frame)


def test_jerk_is_worse_only_above_the_captures_own():
    assert not motion_worse("jerk_root_m_s3", 36.0, 477.0, capture=4126.0)
    assert motion_worse("jerk_root_m_s3", 36.0, 4126.0 * 1.02, capture=4126.0)
    assert not motion_worse("unknown_key", 1.0, 100.0)  # a row without a margin is never marked


def _motion_pair():
    """metrics["motion"] of run-and-step-like figures: the optimized path's feet better, its flight longer
    than the capture's and its joint angles further off."""
    plain = _motion({"float_contact_mm": 5.7, "float_stance_mm": 5.9, "skate_contact_mm": 5.30, "skate_mm": 21.58,
                     "skating_ratio_contacts": 0.404, "flight_time_s": 0.342, "flight_in_stance_s": 0.0})
    # a foot floating in a gap of the schedule: the capture-stance float worse, the schedule's not
    opt = _motion({"float_contact_mm": 3.5, "float_stance_mm": 6.2, "skate_contact_mm": 0.07, "skate_mm": 6.95,
                   "skating_ratio_contacts": 0.0, "flight_time_s": 0.750, "flight_in_stance_s": 0.05})
    for m in (plain, opt):
        m["reference"]["flight_time_s"] = 0.450
    plain["error"].update(flight_extra_s=0.0, flight_missed_s=0.108)
    opt["error"].update(flight_extra_s=0.300, flight_missed_s=0.0)
    opt["error"]["joint_orientation_deg"] = {"hip": {"mean": 1.0, "max": 5.0}}  # max 2 -> 5 deg
    return {"plain": plain, "optimized": opt}


def test_the_feet_rows_of_the_summary_are_marked_with_their_legend():
    from runner.run import contact_summary_rows

    rows = contact_summary_rows(_motion_pair())
    worse = {r[0].split(" (capture")[0]: r[4] for r in rows}
    assert worse == {"float in contact [mm]": False, "float in capture stance [mm]": True,
                     "flight in capture stance [s]": True, "skate in contact [mm/frame]": False,
                     "skate, PhysDiff [mm/frame]": False, "skating ratio (contacts)": False,
                     "flight time [s]": True, "flight phase error vs capture [s]": True,
                     "knee rotation off the hinge [deg]": False, "elbow rotation off the hinge [deg]": False,
                     "beyond range of motion [deg]": False}
    text = summary_table(metrics(), metrics(), solution(), contact_rows=rows)
    assert {"flight time [s] (capture 0.450)", "flight phase error vs capture [s]"} <= marked(text)
    assert LEGEND in text.splitlines()
    assert _target(text, "flight time [s] (capture 0.450)") == "flight,ground"
    assert _target(text, "skate in contact [mm/frame] (capture 1.81)") == "slide"
    assert _target(text, "float in contact [mm] (capture 2.40)") == "planted"


def test_the_anatomy_rows_are_marked_beyond_their_bounds():
    from runner.run import anatomy_summary_rows

    m = _motion_pair()
    for p, (knee, rom) in {"plain": (0.0, 2.0), "optimized": (3.2, 2.4)}.items():
        m[p]["path"].update(off_hinge_knee_deg=knee, off_hinge_elbow_deg=40.0, rom_excess_deg=rom)
        m[p]["reference"].update(off_hinge_knee_deg=0.0, off_hinge_elbow_deg=41.0, rom_excess_deg=3.0)
    worse = {r[0].split(" (capture")[0]: r[4] for r in anatomy_summary_rows(m)}
    # knees 3.2 deg off the hinge where the plain spline has 0: beyond the 3 deg bound; elbows unchanged;
    # 0.4 deg further beyond the range of motion: inside the half degree
    assert worse == {"knee rotation off the hinge [deg]": True, "elbow rotation off the hinge [deg]": False,
                     "beyond range of motion [deg]": False}
    def rom_mark():
        return {r[0].split(" (capture")[0]: r[4] for r in anatomy_summary_rows(m)}["beyond range of motion [deg]"]

    m["optimized"]["path"]["rom_excess_deg"] = 2.0 * 1.01 + 0.51  # past the half degree, short of the capture's 3.0
    assert rom_mark() == TOWARD
    m["optimized"]["path"]["rom_excess_deg"] = 3.0 * 1.01 + 0.51  # past the capture's too
    assert rom_mark() is True


def test_the_motion_metrics_table_has_a_worse_column():
    m = _motion_pair()
    text = motion_metrics_table(m["plain"], m["optimized"])
    rows = {line.split("  ")[0]: line.endswith(f"  {WORSE}") for line in text.splitlines()[3:] if "  " in line}
    assert rows["flight time [s]"] and rows["joint angle error [deg] mean / max"]  # the max: 2 -> 5 deg
    assert not rows["float, ref. contacts [mm]"] and not rows["skate, ref. contacts [mm]"]
    assert not rows["contact-site error [cm] mean / max"] and not rows["jerk root [m/s^3]"]
    assert text.splitlines()[-1] == MOTION_LEGEND
    same = motion_metrics_table(m["plain"], m["plain"])
    assert not any(line.endswith(f"  {WORSE}") for line in same.splitlines())


def test_every_constraint_bounds_rows_the_summary_prints():
    """The target column is complete: every constraint the least change builds on run-and-step with the
    force bounds names the rows it bounds, and each of those rows is printed with it as its target."""
    import solver
    from runner.console import TERM_ROWS
    from runner.run import contact_summary_rows
    from solver.least_change import build_least_change

    model = solver.load_model(solver.shipped("run_and_step.xml"))
    kf, info = solver.read_keyframes(solver.shipped("run_and_step.keyframes.json"), model)
    lc = build_least_change(model, kf, contacts=tuple(info.contacts), forces=True)
    names = {c.name for c in lc.al.constraints}
    assert names <= set(TERM_ROWS), f"a constraint without summary rows: add it to TERM_ROWS: {names - set(TERM_ROWS)}"
    from solver.peak_bounds import PeakBounds

    text = summary_table(metrics(), metrics(), solution(tuple(TERM_ROWS)), contact_rows=contact_summary_rows(_motion_pair()),
                         force_bounds=PeakBounds(3.0, 30.0, 2.5, 20.0))
    labels = [line.split("  ")[0] for line in text.splitlines()]
    for name, prefixes in TERM_ROWS.items():
        for prefix in prefixes:
            label = next((lab for lab in labels if lab.strip().startswith(prefix)), None)
            assert label is not None, (name, prefix)
            assert name in _target(text, label).split(","), (name, label)


def test_a_lost_turn_marks_the_joint_angle_row_and_a_root_that_strays_marks_the_root_row():
    plain, opt = _motion(), _motion()
    for m in (plain, opt):   # a full turn joined the short way by both paths: 174 deg off at the root
        m["error"]["joint_orientation_deg"] = {"root": {"mean": 40.0, "max": 174.0}, "hip": {"mean": 1.0, "max": 2.0}}
    rows = {line.split("  ")[0].strip(): line for line in motion_metrics_table(plain, opt).splitlines()}
    assert rows["joint angle error [deg] mean / max"].endswith(f"  {WORSE}")
    assert not rows["root position error [cm] mean / max"].endswith(f"  {WORSE}")
    opt["error"]["root_position_cm"] = {"mean": 3.0, "max": 9.0}   # the optimizer moved the root off
    rows = {line.split("  ")[0].strip(): line for line in motion_metrics_table(plain, opt).splitlines()}
    assert rows["root position error [cm] mean / max"].endswith(f"  {WORSE}")
    for m in (plain, opt):   # a quarter turn off or less: only the comparison with the plain spline
        m["error"]["joint_orientation_deg"] = {"root": {"mean": 40.0, "max": 89.0}}
    rows = {line.split("  ")[0].strip(): line for line in motion_metrics_table(plain, opt).splitlines()}
    assert not rows["joint angle error [deg] mean / max"].endswith(f"  {WORSE}")


def test_the_no_jolt_rows_are_marked_over_the_corpus_bound():
    from runner.console import JOLT_LEGEND, OVER

    def jolts(pelvis, knee, hip, torque):
        return {"peak_pelvis_acceleration_m_s2": pelvis, "rms_joint_torque_Nm": torque,
                "peak_angular_acceleration_rad_s2": {"l_knee": knee, "r_hip": hip},
                "peak_angular_acceleration_max_rad_s2": max(knee, hip)}

    plain, opt = _motion(jolts(10.0, 100.0, 40.0, 90.0)), _motion(jolts(15.0, 150.0, 90.0, 112.5))
    for m in (plain, opt):
        m["reference"].update(jolts(8.0, 80.0, 60.0, 80.0))  # the filtered capture

    def marks():
        rows = {line.split("  ")[0]: line for line in motion_metrics_table(plain, opt).splitlines()}
        return {k: rows[k].endswith(f"  {OVER}") for k in ("peak pelvis acceleration [m/s^2]",
                                                            "peak joint ang. acceleration [rad/s^2]",
                                                            "RMS joint torque [N m]")}

    # at 1.5x the plain spline's pelvis peak, each joint at 1.5x its larger reference, torque at 1.25x: held
    assert marks() == dict.fromkeys(marks(), False)
    assert JOLT_LEGEND not in motion_metrics_table(plain, opt).splitlines()  # a legend only for a mark printed
    # the hip 91 rad/s^2 against its larger reference, the capture's 60: over 1.5x, though the largest peak
    # (the knee's 150) is not
    opt["path"].update(jolts(15.1, 150.0, 91.0, 112.6))
    assert marks() == dict.fromkeys(marks(), True)
    assert JOLT_LEGEND in motion_metrics_table(plain, opt).splitlines()
    # blocks without jolt figures (an older report): no rows, no legend
    assert "peak pelvis acceleration [m/s^2]" not in motion_metrics_table(_motion(), _motion())


# --- toward the capture, and the verdict above the table (hand-built figures with known answers) ---

def test_a_row_that_moves_toward_the_capture_is_not_worse():
    # run-and-step's pelvis: plain 5.9, capture 16.5: up to the capture's level (and its 1 %) is toward it
    assert motion_mark("skate_contact_mm", 1.0, 1.8, capture=2.0) == TOWARD
    assert motion_mark("skate_contact_mm", 1.0, 2.0 * 1.01 + 0.05 + 1e-3, capture=2.0) is True  # past the capture
    assert motion_mark("skate_contact_mm", 3.0, 2.5, capture=2.0) is False  # lower is never worse
    assert motion_mark("skate_contact_mm", 1.0, 1.04, capture=2.0) is False  # inside the floor: unmarked
    pelvis = "peak pelvis acceleration [m/s^2]"
    for opt, mark in [(11.8, TOWARD), (16.5 * 1.01 + 0.1 - 1e-3, TOWARD), (16.5 * 1.01 + 0.1 + 0.05, True),
                      (5.9, False), (3.0, False)]:
        rows = {r[0].split(" (capture")[0]: r[4] for r in comparison_rows(
            metrics(peak_pelvis_acceleration_ms2=5.9), metrics(peak_pelvis_acceleration_ms2=opt),
            capture={"peak_pelvis_acceleration_ms2": 16.5})}
        assert rows[pelvis] == mark, opt
    # the feet rows' flight time: run-and-step's 0.233 -> 0.142 s against the capture's 0.133 at 120 Hz
    assert motion_mark("flight_time_s", 0.233, 0.142, 1 / 120, capture=0.133) == TOWARD
    assert motion_mark("flight_time_s", 0.142, 0.233, 1 / 120, capture=0.133) is True
    # without a capture the same rise is worse
    assert {r[0]: r[4] for r in comparison_rows(metrics(peak_pelvis_acceleration_ms2=5.9),
                                                metrics(peak_pelvis_acceleration_ms2=11.8))}[pelvis] is True


def test_flight_rows_compare_with_the_captures_flight():
    flight = "flight (all feet clear) [s]"

    def mark(plain, opt, capture):
        rows = comparison_rows(metrics(flight_s=plain), metrics(flight_s=opt), capture={"flight_s": capture})
        return {r[0].split(" (capture")[0]: r[4] for r in rows}[flight]

    # run-and-step: plain 0.252, optimized 0.169, capture 0.133: a change of a third, toward the capture
    assert mark(0.252, 0.169, 0.133) == TOWARD
    assert mark(0.252, 0.100, 0.133) == TOWARD  # past it: 0.033 s off the capture against the plain spline's 0.119
    assert mark(0.140, 0.300, 0.133) is True  # longer, further off
    assert mark(0.140, 0.125, 0.133) is False  # 8 ms off against 7 ms: inside 1 % and 0.01 s
    assert mark(0.252, 0.140, 0.133) == TOWARD
    assert "flight (all feet clear) [s] (capture 0.133)" in [r[0] for r in comparison_rows(
        metrics(), metrics(), capture={"flight_s": 0.133})]


def test_a_jolt_row_says_its_capture_figure_is_filtered():
    """The capture's jolts are of the capture filtered at 6 Hz (`runner.motion_metrics`); a clean's first column is
    the capture itself, so the label says which."""
    labels = [r[0] for r in comparison_rows(metrics(), metrics(), capture={"peak_pelvis_acceleration_ms2": 16.5,
                                                                           "rms_joint_torque_Nm": 120.0})]
    assert "peak pelvis acceleration [m/s^2] (capture at 6 Hz 16.5)" in labels
    assert "RMS joint torque [N m] (capture at 6 Hz 120.0)" in labels


def _motion_with_capture(plain_over, opt_over, capture_over):
    m = {"plain": _motion(plain_over), "optimized": _motion(opt_over)}
    for p in m.values():
        p["reference"].update(capture_over)
    return m


def _verdict(text):
    """The lines above the table's header, continuation lines joined to theirs."""
    lines = text.splitlines()
    head = next(i for i, line in enumerate(lines) if line.rstrip().endswith("target"))
    out = []
    for line in lines[:head]:
        if line.startswith("    ") and out:
            out[-1] += " " + line.strip()
        else:
            out.append(line)
    return out


def test_the_verdict_comes_first_with_the_feet_the_jolts_and_the_worse_rows():
    plain = metrics(max_penetration_mm=12.0, peak_pelvis_acceleration_ms2=6.0, rms_joint_torque_Nm=100.0)
    opt = metrics(max_penetration_mm=0.5, peak_pelvis_acceleration_ms2=12.0, rms_joint_torque_Nm=104.0,
                  penetration_mm_by_site={"l_toe": 0.5, "r_toe": 0.0},
                  peak_joint_torque_Nm=250.0, peak_root_torque_flight_Nm=140.0)  # two rows no constraint bounds
    jolt = {"peak_angular_acceleration_max_rad_s2": 100.0}
    motion = _motion_with_capture({"float_contact_mm": 7.0, "skate_contact_mm": 9.0, **jolt},
                                  {"float_contact_mm": 2.0, "skate_contact_mm": 1.0,
                                   "peak_angular_acceleration_max_rad_s2": 240.0},
                                  {"float_contact_mm": 2.5, "skate_contact_mm": 1.8, "peak_pelvis_acceleration_m_s2": 16.0,
                                   "rms_joint_torque_Nm": 120.0, "peak_angular_acceleration_max_rad_s2": 250.0,
                                   "penetration_mm": {"mean": 0.0, "max": 0.0}})
    motion["optimized"]["error"]["root_position_cm"] = {"mean": 3.0, "max": 9.0}  # against the capture's 1.0 / 1.0
    sol = solution()
    sol.integrals_initial = {**dict.fromkeys(CONSTRAINTS, 0.5), "penetration": 12.0, "slide": 4.0}
    text = summary_table(plain, opt, sol, motion=motion, tol=0.01)
    verdict = _verdict(text)
    assert verdict[0].startswith("verdict: every constraint met")
    assert verdict[1] == ("  feet: penetration 12.00 -> 0.50 mm, float 7.00 -> 2.00 mm, skate 9.00 -> 1.00 mm/frame "
                          "(capture 0.00, 2.50, 1.80)")
    assert verdict[2] == ("  jolts: peak pelvis 6.0 -> 12.0 m/s^2, peak joint 100 -> 240 rad/s^2, RMS torque 100.0 -> "
                          "104.0 N m (capture at 6 Hz 16.0, 250, 120.0)")
    # a clean's: the first column is the capture, whose figures are not repeated after it
    captured = {"float_contact_mm": 2.5, "skate_contact_mm": 1.8, "penetration_mm": {"mean": 0.0, "max": 0.0}}
    clean = _motion_with_capture(captured, {"float_contact_mm": 2.0, "skate_contact_mm": 1.0}, captured)
    feet = _verdict(summary_table(metrics(max_penetration_mm=0.0), opt, sol, motion=clean, tol=0.01))[1]
    assert feet == "  feet: penetration 0.00 -> 0.50 mm, float 2.50 -> 2.00 mm, skate 1.80 -> 1.00 mm/frame"
    worse = verdict[3]
    assert worse.startswith("  worse: 2 of ")
    # the two rows no constraint bounds, traded for what the plain spline breaks; the two that rose toward
    # the capture are not worse
    assert "peak joint torque, peak root torque in flight (bounded by no constraint: traded for penetration, slide," in worse
    assert "2 moved toward the capture: peak pelvis acceleration, RMS joint torque" in worse
    # the motion metrics under the summary: the root strayed from the capture's
    assert worse.endswith("; motion metrics worse: root position error (no constraint tracks the capture's path)")
    assert len(verdict) == 4


def test_the_verdict_without_a_capture_and_with_limits_raised():
    sol = solution()
    sol.unmet = {"penetration": 0.0416, "hinge": np.radians(2.0), "acceleration": 1050.0}
    sol.integrals_final = {**sol.integrals_final, "flight": 3.0}
    # bounded by the hyperextension constraint, inside its limit; by the penetration constraint, whose limit rose
    # and by the flight constraint, still over its tolerance
    opt = metrics(max_hyperextension_deg=0.5, max_penetration_mm=120.0, flight_s=0.425)
    verdict = _verdict(summary_table(metrics(), opt, sol))
    assert verdict[0] == ("verdict: limits raised (the solve found no path that meets them): penetration by 41.6 mm, "
                          "hinge by 2 deg, acceleration by 1.05e+03 m/s^2 | rad/s^2; over tolerance: flight 3 x tol; "
                          "every other constraint met")
    assert verdict[1] == "  feet: penetration 101.43 -> 120.00 mm"  # no capture: no float, no skate
    assert "capture" not in verdict[2] and "peak joint" not in verdict[2]
    # 14 rows judged: penetration and its two sites in a surface, 3 of geometry, 8 of dynamics
    assert verdict[3] == ("  worse: 3 of 14 rows: max penetration (limit of penetration raised); max hyperextension "
                          "(inside the limit of hyperextension); flight (all feet clear) (flight over tolerance)")


def test_a_certified_raise_prints_in_its_columns_unit():
    """The no-jolt bound bounds the pelvis [m/s^2] and the joints [rad/s^2]: the verdict prints the largest
    certified raise of a constraint with its column's unit and name, not the constraint's two units."""
    from runner.verdict import constraint_verdict
    from solver.feasibility import Raise

    unmet = {"acceleration": 3083.0, "penetration": 0.0049}
    certificate = (Raise("acceleration", "root (linear)", 12.5, 1.2, 1.1, 1.3, 2, "m/s^2", 1.0),
                   Raise("acceleration", "r_elbow", 3083.0, 1.9, 1.89, 1.94, 12, "rad/s^2", 1.0),
                   Raise("penetration", "r_toe", 0.0049, 0.7, 0.7, 0.75, 3, "mm", 1e-3))
    head = constraint_verdict({"acceleration": 1.0, "penetration": 1.0, "slide": 0.5}, unmet, certificate)
    assert head == ("limits raised (the solve found no path that meets them): acceleration by 3.08e+03 rad/s^2 at "
                    "r_elbow, penetration by 4.9 mm at r_toe; every other constraint met")
    assert "m/s^2 | rad/s^2" in constraint_verdict({"acceleration": 1.0}, {"acceleration": 3083.0})  # no certificate


def test_the_refinement_says_one_thing():
    from runner.verdict import refinement_text

    sol = solution()
    for estimate, tol, words in [(0.0029, 0.01, "refinement converged (estimate 0.0029 <= tol 0.01)"),
                                 (0.03, 0.01, "refinement not converged (estimate 0.03 > tol 0.01)"),
                                 (0.0029, None, "refinement estimate 0.0029")]:
        sol.final_estimate = estimate
        assert refinement_text(sol, tol) == words
    sol.final_estimate = float("nan")
    assert refinement_text(sol, 0.01) == "no refinement estimate (the solve stopped before one)"
    assert refinement_text(sol, None) == ""
    # an estimate on coarser frames than the path's says so
    sol.final_estimate, sol.segment_decreases = 0.03, ((np.zeros(20), np.zeros(19)),)
    sol.frames = SimpleNamespace(n_variable=22, count=30)
    assert refinement_text(sol, 0.01) == ("no refinement estimate on the final frames (the last: 0.03 on 20 frames, "
                                          "before more were added)")
    # a clean's (a frame at every capture frame): the last subproblem's progress, not a refinement
    sol.estimate_kind, sol.segment_decreases, sol.final_estimate = "progress", (), 0.002
    assert refinement_text(sol, 0.01) == "converged (the last subproblem lowered Phi by 0.002 of it, tol 0.01)"
    sol.final_estimate = 0.05
    assert refinement_text(sol, 0.01) == "not converged (the last subproblem lowered Phi by 0.05 of it, tol 0.01)"
    # the reference motion returned as it is (it met every constraint): nothing was refined
    sol.estimate_kind, sol.final_estimate = "reference", 0.0
    assert refinement_text(sol, 0.01) == ("nothing to change: the reference motion already meets every constraint "
                                          "within its tolerance")


def test_only_the_constraints_a_path_breaks_get_a_row():
    sol = solution()
    sol.integrals_initial = {**dict.fromkeys(CONSTRAINTS, 0.5), "penetration": 3.0}
    sol.integrals_final = {**dict.fromkeys(CONSTRAINTS, 0.5), "rom": 1.5}
    sol.unmet = {"hinge": 0.01}
    text = summary_table(metrics(), metrics(), sol)
    shown = {line.split(":")[0].strip() for line in text.splitlines() if "worst / tolerance" in line
             and line.startswith("  ")}
    assert shown == {"penetration", "rom", "hinge"}
    note = next(line for line in text.splitlines() if line.startswith("NAME: worst / tolerance"))
    assert note.endswith("met by both paths, not shown: planted, slide, flight, ground, hyperextension, unit, "
                         "acceleration")


def test_the_constraint_units_are_the_constraints_own():
    """`CONSTRAINT_UNITS` (how a raised limit prints) agrees with the unit and scale of every constraint the
    least change builds on run-and-step with the force bounds."""
    import solver
    from runner.verdict import CONSTRAINT_UNITS
    from solver.least_change import build_least_change

    model = solver.load_model(solver.shipped("run_and_step.xml"))
    kf, info = solver.read_keyframes(solver.shipped("run_and_step.keyframes.json"), model)
    lc = build_least_change(model, kf, contacts=tuple(info.contacts), forces=True)
    for c in lc.al.constraints:
        assert CONSTRAINT_UNITS[c.name] == (c.unit, pytest.approx(c.scale)), c.name


def test_a_raised_limit_is_placed_among_the_keyframes_and_a_clean_s_frames_are_counted_as_they_are():
    from runner.certificate_text import certificate_lines
    from solver.feasibility import Raise

    raises = (Raise("slide", "r_toe", 0.408, 0.7, 0.6, 0.8, 3, "mm", 1e-3), Raise("planted", "right", 0.002, 0.5004, 0.5, 0.5, 1, "mm", 1e-3))
    keyed = SimpleNamespace(certificate=raises, frames=SimpleNamespace(
        times=np.array([0.0, 0.25, 0.5, 0.75, 1.0]), is_keyframe=np.array([True, False, True, False, True])))
    lines = certificate_lines(keyed)
    assert lines[1] == "  slide at r_toe 408 mm at 0.700 s (0.6-0.8 s), between keyframes 1 and 2"
    assert lines[2] == "  planted at right 2 mm at 0.500 s (0.5-0.5 s), at keyframe 1"
    # a clean: a frame at every capture frame, the clip's ends its only keyframes; the time alone places a raise
    frames = np.linspace(0.0, 1.0, 11)
    clean = SimpleNamespace(certificate=raises[:1], frames=SimpleNamespace(times=frames, is_keyframe=np.isin(frames, [0.0, 1.0])))
    assert certificate_lines(clean)[1] == "  slide at r_toe 408 mm at 0.700 s (0.6-0.8 s)"
    # checked at a finer spacing: the coarse answer stands (the finer search raised more), or the finer path
    # is kept and met everything (then the line is the only one, and names what the coarse solve raised)
    stands = SimpleNamespace(certificate=raises[:1], frames=keyed.frames, finer=(400.0, False, raises))
    assert certificate_lines(stands)[-1].startswith("checked at a finer spacing: at 400 points/s the search raised no "
                                                    "less (slide at r_toe 408 mm")
    kept = SimpleNamespace(certificate=(), frames=keyed.frames, finer=(400.0, True, raises[:1]))
    assert certificate_lines(kept) == ["checked at a finer spacing: the path is the solve's at 400 points/s, which raised "
                                       "less than the solve at 200 (slide at r_toe 408 mm at 0.700 s (0.6-0.8 s))"]
    assert certificate_lines(SimpleNamespace(certificate=(), frames=keyed.frames)) == []  # nothing raised, no check
    sol = solution()
    sol.frames = SimpleNamespace(count=11, n_variable=9, times=frames, is_keyframe=clean.frames.is_keyframe)
    assert "frames: 2 keyframes + 9 variable; " in summary_table(metrics(), metrics(), sol)
