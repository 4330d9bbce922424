"""The summary says where the optimized path is worse than the plain spline (issue 15 item 4), and the
figures that come with the dynamics terms: pelvis acceleration peak and root force on the ground."""
from pathlib import Path
from types import SimpleNamespace

import mujoco
import numpy as np
import pytest

from runner.console import FLIGHT_CHANGE, LEGEND, WORSE, comparison_rows, summary_table
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


def solution():
    return SimpleNamespace(E_initial=11.05, E_final=0.06,
                           integrals_initial={"smooth": 3613.0, "torque": 1.0, "root": 1.0},
                           integrals_final={"smooth": 4150.0, "torque": 0.5, "root": 0.1},
                           initial=SimpleNamespace(count=8),
                           frames=SimpleNamespace(n_variable=22), rounds=[1, 2], n_evals=450, wall_time_s=8.9)


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
    text = summary_table(plain, opt, solution(), {"smooth": 0.05})
    assert marked(text) == {"RMS joint torque [N m]", "flight (all feet clear) [s]", "RMS root force in flight [N]",
                            "peak root force in flight [N]", "RMS root torque in flight [N m]",
                            "max hyperextension [deg]"}
    assert LEGEND in text.splitlines()
    # an objective integral that grows by design is not an acceptance figure
    assert not any(line.endswith(WORSE) for line in text.splitlines() if "integral" in line)


def test_flight_is_worse_when_it_changes_either_way():
    for flight, worse in [(0.252, False), (0.227, False), (0.252 * (1 - FLIGHT_CHANGE) - 0.02, True), (0.425, True)]:
        rows = {r[0]: r[4] for r in comparison_rows(metrics(), metrics(flight_s=flight))}
        assert rows["flight (all feet clear) [s]"] is worse, flight


def test_dynamics_terms_add_pelvis_acceleration_and_root_force_on_the_ground():
    plain, opt = metrics(), metrics(peak_pelvis_acceleration_ms2=45.0, peak_root_force_ground_bw=4.2)
    geometric = summary_table(plain, opt, solution(), {"smooth": 0.05})
    assert "pelvis" not in geometric and "on ground" not in geometric
    text = summary_table(plain, opt, solution(), {"smooth": 0.05, "torque": 1.0, "root": 1.0})
    assert {"peak pelvis acceleration [m/s^2]", "peak root force on ground [body wt]"} <= marked(text)
    assert "RMS root force on ground [body wt]" in text


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
