"""runner.capture.stance: the capture's own stance on hand-built foot paths (exact masks from the definition),
on the toy figure through MuJoCo (heights known in closed form), and the agreement scores."""
from pathlib import Path

import numpy as np
import pytest

from runner.capture.stance import (
    StanceAgreement,
    capture_stance,
    lowest_sites,
    resting,
    schedule_stance,
    stance_agreement,
    stance_mask,
)
from solver.contacts import Contact
from solver.errors import InputError

ROOT = Path(__file__).resolve().parents[3]
FPS = 100.0
ONE_FOOT = {"left": ("l_heel", "l_toe")}
FEET = {"left": ("l_heel", "l_toe"), "right": ("r_heel", "r_toe")}  # the shipped figure's
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
    s = schedule_stance(contacts, times, FEET)
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

    from runner.capture.contact_detection import reference_contacts
    from runner.capture.reference_motion import load_bvh_reference

    model = mujoco.MjModel.from_xml_path(str(ROOT / "models" / "run_and_step.xml"))
    ref = load_bvh_reference(ROOT / "models" / "cmu" / "127_33.bvh", model)
    cap = capture_stance(model, ref.qpos, ref.frame_time)
    sched = schedule_stance(reference_contacts(model, ref.qpos, ref.frame_time), ref.times, FEET)
    a = stance_agreement(sched, cap)
    assert a.stance_frames > 0.4 * 2 * ref.count * 0.5  # both feet stand a good part of the clip
    assert a.recall >= 0.97 and a.precision >= 0.97, a


def test_a_foot_hovering_40_mm_at_touch_down_does_not_rest():
    """A flat foot lowered slowly (0.1 m/s, under every speed threshold) that stops 40 mm up for 0.2 s
    before it lands: no frame above the 3 cm entry height is in stance or rests; after landing every
    frame rests (heights and speeds known by construction)."""
    z = np.r_[np.linspace(0.10, 0.04, 61), np.full(20, 0.04), np.linspace(0.04, 0.0, 41), np.zeros(30)]
    times, pos, h = foot(z, z)
    stance = stance_mask(times, pos, h, ONE_FOOT, SITES)
    low, speed = lowest_sites(times, pos, h, ONE_FOOT, SITES)
    rest = resting(stance, low, speed)
    assert not stance[z >= 0.03].any() and not rest[z >= 0.03].any()
    assert rest[-30:, 0].all()
    np.testing.assert_allclose(speed[-30:-1, 0], 0.0, atol=1e-12)


def test_rolling_off_the_toes_is_stance_but_not_rest():
    """The stance's hysteresis keeps a lifting toe (0.8 m/s, up to 5 cm) in stance so detection does not
    flicker; it is the stance's way out, not a foot resting: the resting frames end where the toe passes
    0.5 m/s (the entry speed) - here, where it starts to lift."""
    z = np.r_[np.zeros(30), 0.008 * np.arange(1, 11)]  # 8 mm per frame at 100 fps: 0.8 m/s
    times, pos, h = foot(z + 0.05, z)
    stance = stance_mask(times, pos, h, ONE_FOOT, SITES)
    low, speed = lowest_sites(times, pos, h, ONE_FOOT, SITES)
    rest = resting(stance, low, speed)
    assert stance[:35, 0].all()  # lifting at 0.8 m/s, up to 40 mm: still in stance
    assert rest[:29, 0].all() and not rest[30:, 0].any()


def test_a_foot_resting_on_a_tilted_floor_rests():
    """A foot standing still at four places on a floor tilted 1 degree (heights from the fitted scene's
    surfaces, not from z): every frame rests, and its lowest site is on the floor."""
    from runner.capture.scene_fit import FittedScene

    slope = np.tan(np.radians(1.0))
    floor = FittedScene(0.01, (), (slope, 0.0)).surfaces()
    pos = np.zeros((80, 2, 3))
    for i, x in enumerate((-1.5, -0.5, 0.5, 1.5)):
        rows = slice(20 * i + 5, 20 * i + 20)  # 5 frames of step between the places (fast: not resting)
        pos[rows, 0, 0], pos[rows, 1, 0] = x, x + 0.2
        pos[rows, :, 2] = 0.01 + slope * pos[rows, :, 0]
    for i in range(4):  # the steps: the foot lifted 10 cm and moved 1 m
        a = 20 * i
        pos[a:a + 5] = pos[a + 5] if i == 0 else np.linspace(pos[a - 1], pos[a + 5], 7)[1:-1] + [0, 0, 0.1]
    times = np.arange(80) / FPS
    h = floor.height_above(pos)
    stance = stance_mask(times, pos, h, ONE_FOOT, SITES)
    low, speed = lowest_sites(times, pos, h, ONE_FOOT, SITES)
    rest = resting(stance, low, speed)
    still = np.zeros(80, bool)
    for i in range(4):
        still[20 * i + 6:20 * i + 19] = True  # away from the steps' central differences
    assert rest[still, 0].all()
    np.testing.assert_allclose(low[still, 0], 0.0, atol=1e-12)


def test_a_site_enters_contact_with_its_foots_lowest_site():
    """Detection judged against the stance: a toe held still 26 mm up while the heel under it still
    sweeps in at 1 m/s does not enter contact until the heel (the foot's lowest site) is slow; the heel
    sweeping alone never enters. With feet=None the toe enters alone (the old per-site rule)."""
    from runner.capture.contact_detection import detect_contacts

    n = 40
    heel_x = np.r_[1.0 * np.arange(20) / FPS, np.full(n - 20, 0.19)]  # 1 m/s until frame 19, then still
    times, pos, h = foot(np.full(n, 0.005), np.full(n, 0.026), heel_x=heel_x, toe_x=np.full(n, 0.0))
    found = detect_contacts(times, pos, h, SITES, min_duration=0.0, feet=dict(ONE_FOOT))
    starts = {c.site: c.start for c in found}
    assert starts["l_heel"] == pytest.approx(times[20]) and starts["l_toe"] == pytest.approx(times[20])
    alone = detect_contacts(times, pos, h, SITES, min_duration=0.0, feet=None)
    assert min(c.start for c in alone if c.site == "l_toe") == pytest.approx(0.0)
    mask = schedule_stance(found, times, ONE_FOOT)
    assert stance_agreement(mask, stance_mask(times, pos, h, ONE_FOOT, SITES)).precision == 1.0
