"""runner.motion_metrics on hand-built motions of the figure with known answers, and the reference's
own figures on 127_33."""
import json
from pathlib import Path

import mujoco
import numpy as np
import pytest
from shipped_sites import SITES

from runner.capture.contact_detection import reference_contacts
from runner.capture.scene_fit import FittedScene, scene_mjcf
from runner.motion_metrics import FLIGHT_HEIGHT, flight_mismatch, motion_metrics
from solver.contact_schedule import ContactSchedule
from solver.contacts import Contact
from solver.errors import InputError

ROOT = Path(__file__).resolve().parents[2]
FPS = 120.0
N = 61


@pytest.fixture(scope="module")
def floor_model():
    return mujoco.MjModel.from_xml_string(scene_mjcf(FittedScene(0.0), ROOT / "models" / "humanoid39.xml"))


def standing(model, n=N):
    """(n, nq): the identity pose with the pelvis at 1 m: every contact site at z = 0."""
    q = np.tile(model.qpos0, (n, 1))
    q[:, :3] = (0.0, 0.0, 1.0)
    return q


def planted(n=N):
    return [Contact(s, 0.0, (n - 1) / FPS) for s in SITES]


def test_same_motion_has_zero_error_and_is_json(floor_model):
    q = standing(floor_model)
    m = motion_metrics(floor_model, q, FPS, q, planted())
    json.dumps(m)
    assert m["error"]["root_position_cm"] == {"mean": 0.0, "max": 0.0}
    assert all(v["max"] == 0 for v in m["error"]["joint_orientation_deg"].values())
    assert m["path"] == m["reference"]
    assert m["path"]["penetration_mm"]["max"] == 0 and m["path"]["flight_time_s"] == 0


def test_lifted_figure_floats_by_the_lift(floor_model):
    ref = standing(floor_model)
    q = ref.copy()
    q[:, 2] += 0.04
    m = motion_metrics(floor_model, q, FPS, ref, planted())
    p = m["path"]
    assert p["float_contact_mm"] == pytest.approx(40.0)
    assert p["float_physdiff_mm"] == pytest.approx(40.0)
    assert p["penetration_mm"]["max"] == 0
    assert p["flight_time_s"] == pytest.approx(N / FPS)          # every site 4 cm up: all clear
    assert m["error"]["root_position_cm"]["mean"] == pytest.approx(4.0)
    assert all(v["mean"] == pytest.approx(4.0) for v in m["error"]["site_position_cm"].values())
    assert m["reference"]["float_contact_mm"] == pytest.approx(0, abs=1e-9)
    # the reference has no contacts: no frames to count an animator's float over
    assert motion_metrics(floor_model, q, FPS, ref, [])["path"]["float_contact_mm"] == 0.0


def test_flight_mismatch_counts_frames_by_hand():
    """Reference in flight on frames 10-19, the path on 13-25 except frame 22, where one site is down:
    extra 20, 21, 23, 24, 25 (5 frames), missed 10, 11, 12 (3); extra - missed is the flight-time
    difference, 12 - 10 frames."""
    up, down = FLIGHT_HEIGHT + 0.01, FLIGHT_HEIGHT - 0.001
    ref = np.full((40, 4), down)
    ref[10:20] = up
    path = np.full((40, 4), down)
    path[13:26] = up
    path[22, 2] = down
    extra, missed = flight_mismatch(path, ref, 120.0)
    assert (extra, missed) == (5 / 120.0, 3 / 120.0)
    assert extra - missed == pytest.approx((path > FLIGHT_HEIGHT).all(1).sum() / 120 - 10 / 120)
    with pytest.raises(InputError, match="must both be"):
        flight_mismatch(path[:, :3], ref, 120.0)


def test_shifted_flight_has_the_same_flight_time_and_a_mismatch(floor_model):
    """The path flies frames 20-39, the reference frames 30-49 (every site 4 cm up): equal flight
    times, 10 frames extra and 10 missed - what the flight time alone cannot see."""
    ref = standing(floor_model)
    q = ref.copy()
    q[20:40, 2] += 0.04
    ref[30:50, 2] += 0.04
    m = motion_metrics(floor_model, q, FPS, ref, planted())
    assert m["path"]["flight_time_s"] == m["reference"]["flight_time_s"] == pytest.approx(20 / FPS)
    assert m["error"]["flight_extra_s"] == pytest.approx(10 / FPS)
    assert m["error"]["flight_missed_s"] == pytest.approx(10 / FPS)
    same = motion_metrics(floor_model, ref, FPS, ref, planted())["error"]
    assert same["flight_extra_s"] == same["flight_missed_s"] == 0.0


def test_sunk_figure_penetrates_by_the_depth(floor_model):
    ref = standing(floor_model)
    q = ref.copy()
    q[: N // 2, 2] -= 0.01        # 30 of 61 frames 1 cm down
    p = motion_metrics(floor_model, q, FPS, ref, planted())["path"]
    assert p["penetration_mm"]["max"] == pytest.approx(10.0)
    assert p["penetration_mm"]["mean"] == pytest.approx(10.0 * (N // 2) / N)
    assert p["float_contact_mm"] == pytest.approx(0, abs=1e-9)


@pytest.mark.parametrize("speed, skating", [(0.6, 1.0), (0.3, 0.0)])
def test_sliding_feet_skate_at_the_known_speed(floor_model, speed, skating):
    ref = standing(floor_model)
    q = ref.copy()
    q[:, 0] += speed * np.arange(N) / FPS
    p = motion_metrics(floor_model, q, FPS, ref, planted())["path"]
    assert p["skate_contact_mm"] == pytest.approx(speed / FPS * 1e3)
    assert p["skate_contact_speed_m_s"] == pytest.approx(speed)
    assert p["skate_mm"] == pytest.approx(speed / FPS * 1e3)      # on the ground: PhysDiff's too
    assert p["skating_ratio_rate_hz"] == 20.0
    assert p["skating_ratio"] == skating and p["skating_ratio_contacts"] == skating


def test_rotated_joint_and_cubic_root(floor_model):
    ref = standing(floor_model)
    q = ref.copy()
    j = mujoco.mj_name2id(floor_model, mujoco.mjtObj.mjOBJ_JOINT, "torso")
    a = floor_model.jnt_qposadr[j]
    q[:, a:a + 4] = (np.cos(np.radians(5)), 0, 0, np.sin(np.radians(5)))   # 10 degrees about z
    t = np.arange(N) / FPS
    q[:, 2] += 0.1 * t**3      # jerk 0.6 m/s^3, also at the sites (they move with the root)
    m = motion_metrics(floor_model, q, FPS, ref, planted())
    jo = m["error"]["joint_orientation_deg"]
    assert jo["torso"]["mean"] == pytest.approx(10.0) and jo["torso"]["max"] == pytest.approx(10.0)
    assert jo["l_hip"]["max"] == 0 and jo["root"]["max"] == 0
    bo = m["error"]["body_orientation_deg"]
    assert bo["l_forearm"]["mean"] == pytest.approx(10.0) and bo["l_shin"]["max"] == pytest.approx(0, abs=1e-6)
    assert m["path"]["jerk_root_m_s3"] == pytest.approx(0.6, rel=1e-5)
    assert m["path"]["jerk_sites_m_s3"] == pytest.approx(0.6, rel=1e-4)
    assert m["error"]["accel_error_root_m_s2"] == pytest.approx(np.mean(0.6 * t[1:-1]), rel=1e-4)


def test_validation(floor_model):
    q = standing(floor_model)
    with pytest.raises(InputError, match="reference_qpos"):
        motion_metrics(floor_model, q, FPS, q[:-1], [])
    with pytest.raises(InputError, match="fps"):
        motion_metrics(floor_model, q, 0.0, q, [])
    figure_only = mujoco.MjModel.from_xml_path(str(ROOT / "models" / "humanoid39.xml"))
    with pytest.raises(InputError, match="floor"):
        motion_metrics(figure_only, q, FPS, q, [])


def test_127_33_reference_own_metrics():
    from runner.capture.reference_motion import load_bvh_reference
    model = mujoco.MjModel.from_xml_path(str(ROOT / "models" / "run_and_step.xml"))
    ref = load_bvh_reference(ROOT / "models" / "cmu" / "127_33.bvh", model)
    cs = reference_contacts(model, ref.qpos, ref.frame_time)
    m = motion_metrics(model, ref.qpos, 1 / ref.frame_time, ref.qpos, cs)
    r = m["reference"]
    print(json.dumps(r, indent=1))
    assert r["penetration_mm"]["max"] < 1e-6            # the retargeting keeps sites out of surfaces
    assert r["float_contact_mm"] < 5.0                   # planted toes sit 2 mm up
    # a run has short flights: every site 3 cm clear for part of the gaps between contacts, never longer
    gaps = sum(b - a for a, b in ContactSchedule.of(cs, SITES).flights())
    assert 0.0 < r["flight_time_s"] <= gaps + ref.frame_time
    assert r["skate_contact_speed_m_s"] < 0.5


def test_float_and_flight_on_the_capture_stance(floor_model):
    """A schedule with a gap (no contact in frames 20..39) cannot hide a foot floating there: the path
    is lifted 4 cm in those frames; the capture stands throughout (its stance: both feet, every frame)."""
    ref = standing(floor_model)
    q = ref.copy()
    q[20:40, 2] += 0.04
    gap = [Contact(s, 0.0, 19 / FPS) for s in SITES] + [Contact(s, 40 / FPS, (N - 1) / FPS) for s in SITES]
    stance = np.ones((N, 2), bool)
    m = motion_metrics(floor_model, q, FPS, ref, gap, stance=stance)
    p = m["path"]
    assert p["float_contact_mm"] == pytest.approx(0.0, abs=1e-9)  # the schedule's frames: on the floor
    assert p["float_stance_mm"] == pytest.approx(40.0 * 20 / N)  # 20 of N frames 40 mm up, both feet
    assert p["float_stance_max_mm"] == pytest.approx(40.0)
    assert p["flight_in_stance_s"] == pytest.approx(20 / FPS)  # airborne where the capture stood
    assert m["reference"]["float_stance_mm"] == pytest.approx(0.0, abs=1e-9)
    assert m["reference"]["flight_in_stance_s"] == 0.0
    # only the right foot in stance in the lifted frames: the left foot's float there is not counted
    stance[20:40, 0] = False
    p = motion_metrics(floor_model, q, FPS, ref, gap, stance=stance)["path"]
    assert p["float_stance_mm"] == pytest.approx(40.0 * 20 / (2 * N - 20))
    assert "float_stance_mm" not in motion_metrics(floor_model, q, FPS, ref, gap)["path"]
    with pytest.raises(InputError, match="stance"):
        motion_metrics(floor_model, q, FPS, ref, gap, stance=np.ones((N, 4), bool))


def _slid(model, xs):
    """(len(xs), nq) the standing figure with the pelvis moved to x = xs [m]: every site slides with it."""
    q = standing(model, len(xs))
    q[:, 0] = xs
    return q


def test_forced_skate_is_the_keyed_slide_over_the_contact_steps(floor_model):
    from runner.motion_metrics import forced_skate_mm

    keys = np.array([0, 30, 60])
    xk = np.array([0.0, 0.06, 0.06])  # 6 cm between the first two keys, none after
    forced = forced_skate_mm(floor_model, keys / FPS, _slid(floor_model, xk), FPS, planted(), N)
    # by hand: each of the 4 sites slides at least 60 mm in the 60 steps it is in contact
    assert forced == pytest.approx(1.0, rel=1e-9)
    # the path that slides at constant speed between the keys attains it (motion_metrics' own skate)
    line = np.interp(np.arange(N), keys, xk)
    m = motion_metrics(floor_model, _slid(floor_model, line), FPS, standing(floor_model), planted())
    assert m["path"]["skate_contact_mm"] == pytest.approx(forced, rel=1e-9)
    # any other path through the keys slides more
    rng = np.random.default_rng(3)
    for _ in range(5):
        wiggle = line + rng.normal(0, 0.004, N)
        wiggle[keys] = xk
        m = motion_metrics(floor_model, _slid(floor_model, wiggle), FPS, standing(floor_model), planted())
        assert m["path"]["skate_contact_mm"] >= forced - 1e-9


def test_forced_skate_links_keys_only_inside_one_contact(floor_model):
    from runner.motion_metrics import forced_skate_mm

    # two contacts, frames 0-20 and 40-60; keys at 0, 20, 40, 60 move 1, 5 and 2 cm: the 5 cm between frames
    # 20 and 40 lie in a gap of every site (a swing), where sliding is not skating
    contacts = [Contact(s, a / FPS, b / FPS) for s in SITES for a, b in ((0, 20), (40, 60))]
    keys = np.array([0, 20, 40, 60])
    xk = np.array([0.0, 0.01, 0.06, 0.08])
    forced = forced_skate_mm(floor_model, keys / FPS, _slid(floor_model, xk), FPS, contacts, N)
    assert forced == pytest.approx((10.0 + 20.0) / 40, rel=1e-9)  # 40 contact steps per site
    # a key off the frame grid (1 ms late) is left out; the bound can only fall
    late = forced_skate_mm(floor_model, (keys + np.r_[0, 0, 0, 0.12]) / FPS, _slid(floor_model, xk), FPS,
                           contacts, N)
    assert late == pytest.approx(10.0 / 40, rel=1e-9)
    assert forced_skate_mm(floor_model, keys[:1] / FPS, _slid(floor_model, xk[:1]), FPS, contacts, N) == 0.0
