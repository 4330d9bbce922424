"""runner.mocap.stance: the capture's own stance on hand-built foot paths (exact masks from the definition),
on the toy figure through MuJoCo (heights known in closed form), and the agreement scores."""
from pathlib import Path

import numpy as np
import pytest

from runner.mocap.stance import (
    StanceAgreement,
    capture_stance,
    schedule_stance,
    stance_agreement,
    stance_mask,
)
from solver.contacts import Contact
from solver.errors import InputError

ROOT = Path(__file__).resolve().parents[3]
FPS = 100.0
ONE_FOOT = {"left": ("l_heel", "l_toe")}
SITES = ("l_heel", "l_toe")


def foot(heel_z, toe_z, heel_x=None, toe_x=None):
    """times (n,), positions (n, 2, 3) and heights (n, 2) of one foot's heel and toe over a flat floor."""
    heel_z, toe_z = np.asarray(heel_z, float), np.asarray(toe_z, float)
    n = len(heel_z)
    pos = np.zeros((n, 2, 3))
    pos[:, 0, 2], pos[:, 1, 2] = heel_z, toe_z
    pos[:, 1, 0] = 0.2
    if heel_x is not None:
        pos[:, 0, 0] += heel_x
    if toe_x is not None:
        pos[:, 1, 0] += toe_x
    return np.arange(n) / FPS, pos, pos[..., 2].copy()


def test_a_short_touch_down_is_a_stance():
    """A hopscotch touch-down of 3 frames (30 ms, under the schedule's former 50 ms minimum) between two
    still, high frames: the foot is on the floor and still there, so it is in stance there."""
    z = np.full(40, 0.20)
    z[20:23] = 0.0  # three frames on the floor; the steps in height are fast at 19/20 and 22/23
    times, pos, h = foot(z + 0.08, z)  # heel 8 cm above the toe (a forefoot touch)
    m = stance_mask(times, pos, h, ONE_FOOT, SITES)
    # frames 20 and 22 see the jump in central differences (0.2 m / 0.02 s = 10 m/s): only 21 is still
    assert np.flatnonzero(m[:, 0]).tolist() == [21]
    m = stance_mask(times, pos, h, ONE_FOOT, SITES, speed_on=1e9, speed_off=1e9)  # height alone
    assert np.flatnonzero(m[:, 0]).tolist() == [20, 21, 22]


def test_the_lowest_site_decides():
    """A forefoot stance: the toe planted, the heel 8 cm up and still (it would pass the speed test)."""
    n = 30
    times, pos, h = foot(np.full(n, 0.08), np.zeros(n))
    assert stance_mask(times, pos, h, ONE_FOOT, SITES)[:, 0].all()
    # the toe (lowest) sliding at 2 m/s while the heel hovers still: not resting
    times, pos, h = foot(np.full(n, 0.08), np.zeros(n), toe_x=2.0 * np.arange(n) / FPS)
    assert not stance_mask(times, pos, h, ONE_FOOT, SITES).any()
    # a heel still at 2 cm but the toe lower and fast (a foot sweeping the floor with its toe): not resting
    times, pos, h = foot(np.full(n, 0.02), np.full(n, 0.01), toe_x=2.0 * np.arange(n) / FPS)
    assert not stance_mask(times, pos, h, ONE_FOOT, SITES).any()


def test_hysteresis_in_height_and_speed():
    n = 60
    wobble = 0.04 + 0.005 * np.sin(np.arange(n) / 5)  # 3.5..4.5 cm, slow: between the heights 3 and 5 cm
    z = np.concatenate([np.zeros(10), np.linspace(0.0, 0.04, 21)[1:], wobble[: n - 30]])  # rises at 0.2 m/s
    times, pos, h = foot(z + 0.1, z)
    assert stance_mask(times, pos, h, ONE_FOOT, SITES)[:, 0].all()  # stays: never above 5 cm or 1 m/s
    times, pos, h = foot(wobble + 0.1, wobble)
    assert not stance_mask(times, pos, h, ONE_FOOT, SITES).any()  # never enters above 3 cm
    t = np.arange(n) / FPS
    x = np.where(t < 0.3, 0.0, 0.7 * (t - 0.3))  # planted, then sliding at 0.7 m/s: stays (0.5 < 0.7 < 1.0)
    times, pos, h = foot(np.full(n, 0.1), np.zeros(n), toe_x=x)
    assert stance_mask(times, pos, h, ONE_FOOT, SITES)[:, 0].all()
    x = np.where(t < 0.3, 0.0, 1.2 * (t - 0.3))  # ... at 1.2 m/s: leaves once faster than 1.0 m/s
    times, pos, h = foot(np.full(n, 0.1), np.zeros(n), toe_x=x)
    m = stance_mask(times, pos, h, ONE_FOOT, SITES)[:, 0]
    assert m[:30].all() and not m[31:].any()  # frame 30: central difference 0.6 m/s, still in


def test_capture_stance_on_the_toy_figure(toy_model):
    """The toy figure's sites are 0.95 m under its root at the zero pose: standing with the soles 5 mm
    up, raised slowly (0.2, then 0.6 m/s: still enough) to 8.5 cm (too high above 5 cm), and the same
    motion on the 20 cm step."""
    n = 50
    qpos = np.zeros((n, toy_model.nq))
    qpos[:, 3] = 1.0
    qpos[:, 7::4] = 1.0  # ball joints: identity quaternions
    z = np.full(n, 0.955)
    z[10:20] = 0.955 + 0.002 * np.arange(1, 11)  # 0.2 m/s up to 2.5 cm
    z[20:30] = 0.975 + 0.006 * np.arange(1, 11)  # 0.6 m/s up to 8.5 cm
    z[30:] = z[29]
    qpos[:, 2] = z
    m = capture_stance(toy_model, qpos, 1 / FPS)
    heights = z - 0.95
    assert m.shape == (n, 2) and (m[:, 0] == m[:, 1]).all()  # both feet alike
    assert m[heights <= 0.05, 0].all()  # 5-49 mm up, at most 0.6 m/s
    assert not m[heights > 0.05, 0].any()
    # on the step: the same motion 1.5 m forward, 20 cm higher, is the same stance
    qpos[:, 0], qpos[:, 2] = 1.5, z + 0.2
    assert (capture_stance(toy_model, qpos, 1 / FPS) == m).all()


def test_schedule_stance_and_agreement():
    times = np.arange(10) / 10
    contacts = [Contact("l_heel", 0.0, 0.2), Contact("l_toe", 0.2, 0.4), Contact("r_toe", 0.6, 0.9)]
    s = schedule_stance(contacts, times)
    assert np.flatnonzero(s[:, 0]).tolist() == [0, 1, 2, 3, 4]
    assert np.flatnonzero(s[:, 1]).tolist() == [6, 7, 8, 9]
    c = np.zeros_like(s)
    c[1:6, 0] = True  # the capture: left 1..5 (schedule 0..4: 4 of 5 shared)
    c[6:8, 1] = True  # right 6..7 (schedule 6..9: both shared)
    a = stance_agreement(s, c)
    assert isinstance(a, StanceAgreement)
    assert a.recall == pytest.approx(6 / 7) and a.precision == pytest.approx(6 / 9)
    assert a.feet == (pytest.approx((4 / 5, 4 / 5)), pytest.approx((1.0, 2 / 4)))
    assert (a.stance_frames, a.schedule_frames) == (7, 9)
    empty = stance_agreement(np.zeros(5, bool), np.zeros(5, bool))
    assert (empty.recall, empty.precision) == (1.0, 1.0)


def test_errors_name_the_argument():
    times, pos, h = foot(np.zeros(5), np.zeros(5))
    with pytest.raises(InputError, match="site_pos"):
        stance_mask(times, pos[:, :1], h, ONE_FOOT, SITES)
    with pytest.raises(InputError, match="height_on"):
        stance_mask(times, pos, h, ONE_FOOT, SITES, height_on=0.1, height_off=0.05)
    with pytest.raises(InputError, match="'l_ankle'"):
        stance_mask(times, pos, h, {"left": ("l_ankle",)}, SITES)
    with pytest.raises(InputError, match="same"):
        stance_agreement(np.zeros((5, 2), bool), np.zeros((4, 2), bool))


def test_127_33_schedule_matches_the_capture_stance():
    """The shipped clip on its shipped scene: the detected schedule agrees with the capture's stance
    frame by frame (recall and precision at least 0.97; measured 1.00 / 1.00 on this clip)."""
    import mujoco

    from runner.mocap.reference import load_bvh_reference
    from solver.contacts import reference_contacts

    model = mujoco.MjModel.from_xml_path(str(ROOT / "models" / "run_and_step.xml"))
    ref = load_bvh_reference(ROOT / "models" / "cmu" / "127_33.bvh", model)
    cap = capture_stance(model, ref.qpos, ref.frame_time)
    sched = schedule_stance(reference_contacts(model, ref.qpos, ref.frame_time), ref.times)
    a = stance_agreement(sched, cap)
    assert a.stance_frames > 0.4 * 2 * ref.count * 0.5  # both feet stand a good part of the clip
    assert a.recall >= 0.97 and a.precision >= 0.97, a
