"""solver.contacts and the capture's contact detection (runner.capture.contact_detection): hysteresis,
minimum duration, masks and events on hand-built site paths, and the
shipped clip 127_33 (touch-downs where the foot-height trace lands)."""
from pathlib import Path

import mujoco
import numpy as np
import pytest
from shipped_sites import FEET, SITES

from runner.capture.contact_detection import detect_contacts, reference_contacts
from solver.contacts import (
    Contact,
    contact_mask,
    foot_contacts,
    site_heights,
    site_positions,
    touchdowns_liftoffs,
)
from solver.errors import InputError

ROOT = Path(__file__).resolve().parents[2]
FPS = 100.0


def one_site(z, x=None):
    """(n,) times, (n, 1, 3) positions of one site with height z (and x), and heights (n, 1)."""
    z = np.asarray(z, float)
    n = len(z)
    pos = np.zeros((n, 1, 3))
    pos[:, 0, 2] = z
    if x is not None:
        pos[:, 0, 0] = x
    return np.arange(n) / FPS, pos, z[:, None]


def test_down_then_up_gives_one_contact_over_the_down_part():
    t = np.arange(101) / FPS
    z = np.where(t <= 0.3, 0.0, 2.0 * (t - 0.3))  # planted 0.3 s, then lifts at 2 m/s
    times, pos, h = one_site(z)
    cs = detect_contacts(times, pos, h, sites=("l_toe",))
    assert cs == [Contact("l_toe", 0.0, pytest.approx(0.30))]


def test_hysteresis_stays_in_between_thresholds_but_does_not_enter_there():
    n = 60
    wobble = 0.04 + 0.005 * np.sin(np.arange(n))  # 3.5..4.5 cm: between height_on 3 and height_off 5
    z = np.concatenate([np.zeros(20), wobble[:n - 20]])
    times, pos, h = one_site(z)
    fast = dict(speed_on=1e9, speed_off=1e9)  # height alone decides (the 0 -> 4 cm step is fast)
    cs = detect_contacts(times, pos, h, sites=("l_toe",), **fast)
    assert len(cs) == 1 and cs[0].start == 0.0 and cs[0].end == pytest.approx(times[-1])
    times, pos, h = one_site(wobble)
    assert detect_contacts(times, pos, h, sites=("l_toe",), **fast) == []


def test_speed_hysteresis_and_sliding_foot():
    t = np.arange(100) / FPS
    for v, expect in ((0.3, 1), (0.7, 0), (1.5, 0)):
        times, pos, h = one_site(np.zeros(100), x=v * t)  # sliding on the ground at v m/s
        assert len(detect_contacts(times, pos, h, sites=("l_toe",))) == expect, v
    # planted, then sliding at 0.7 m/s (between speed_on 0.5 and speed_off 1.0): stays in contact
    x = np.where(t < 0.5, 0.0, 0.7 * (t - 0.5))
    times, pos, h = one_site(np.zeros(100), x=x)
    cs = detect_contacts(times, pos, h, sites=("l_toe",))
    assert len(cs) == 1 and cs[0].end == pytest.approx(t[-1])


def test_minimum_duration_drops_a_brush():
    z = np.full(100, 0.2)
    z[40:44] = 0.0  # 4 frames = 0.03 s (start to end) on the ground
    times, pos, h = one_site(z)
    pos[:, 0, 2] = z
    # the step in height makes the site fast at 39/40 and 43/44; keep speed out of it
    assert detect_contacts(times, pos, h, sites=("l_toe",), speed_on=1e9, speed_off=1e9) == []
    assert len(detect_contacts(times, pos, h, sites=("l_toe",), speed_on=1e9, speed_off=1e9,
                               min_duration=0.02)) == 1


def test_validation():
    times, pos, h = one_site(np.zeros(10))
    with pytest.raises(InputError, match="site_pos"):
        detect_contacts(times, pos, h, SITES)  # 4 sites, 1 given
    with pytest.raises(InputError, match="height_on"):
        detect_contacts(times, pos, h, sites=("l_toe",), height_on=0.1, height_off=0.05)
    with pytest.raises(InputError, match="increasing"):
        detect_contacts(times[::-1], pos, h, sites=("l_toe",))


def test_mask_events_and_feet():
    cs = [Contact("l_heel", 0.0, 0.2), Contact("l_toe", 0.1, 0.4), Contact("r_toe", 0.5, 0.7)]
    times = np.arange(11) / 10
    m = contact_mask(cs, SITES, times)
    assert m.shape == (11, 4)
    assert m[:, 0].tolist() == [True, True, True] + [False] * 8
    assert m[:, 1].tolist() == [False, True, True, True, True] + [False] * 6
    assert m[:, 3].tolist() == [False] * 5 + [True] * 3 + [False] * 3
    assert foot_contacts(cs, FEET) == [Contact("left", 0.0, 0.4), Contact("right", 0.5, 0.7)]
    td, lo = touchdowns_liftoffs(cs, FEET)
    assert td == [(0.0, "left"), (0.5, "right")] and lo == [(0.4, "left"), (0.7, "right")]
    td, lo = touchdowns_liftoffs(cs, None)
    assert len(td) == 3 and lo[0] == (0.2, "l_heel")
    with pytest.raises(InputError, match="nose"):
        contact_mask([Contact("nose", 0, 1)], SITES, times)


def load_clip(name, model):
    from runner.capture.reference_motion import load_bvh_reference
    return load_bvh_reference(ROOT / "models" / "cmu" / f"{name}.bvh", model)


def test_127_33_touchdowns_where_the_feet_land():
    model = mujoco.MjModel.from_xml_path(str(ROOT / "models" / "run_and_step.xml"))
    ref = load_clip("127_33", model)
    cs = reference_contacts(model, ref.qpos, ref.frame_time)
    pos = site_positions(model, ref.qpos)
    h = site_heights(model, pos)
    td, lo = touchdowns_liftoffs(cs, FEET)
    for c in cs:
        print(f"{c.site:7s} {c.start:.3f}-{c.end:.3f} s")
    print("touch-downs", td, "\nlift-offs", lo)
    # the run: six stances alternating feet, two of them on the box (0.85-1.37 s)
    assert [f for _, f in td] == ["left", "right"] * 3
    for (t0, foot), (t1, _) in zip(td, lo):
        ks = [SITES.index(s) for s in FEET[foot]]
        i0, i1 = int(round(t0 / ref.frame_time)), int(round(t1 / ref.frame_time))
        low = h[:, ks].min(axis=1)
        assert low[i0:i1 + 1].max() < 0.05          # down throughout the stance
        assert 0.1 <= t1 - t0 <= 0.3                  # a running stance
        mean = h[:, ks].mean(axis=1)                  # heel and toe together: the whole foot
        if i0 >= 6:                                   # landing: the foot was coming down (a heel
            assert mean[i0 - 6] > mean[i0] + 0.01, (foot, t0, mean[i0 - 6:i0 + 1])  # may skim in low)
        if i1 + 6 < len(low):                         # lift-off: the foot goes up after
            assert low[i1 + 6] > low[i1] + 0.01, (foot, t1, low[i1:i1 + 7])
    on_box = [c for c in foot_contacts(cs, FEET) if 0.8 < c.start < 1.4]
    assert len(on_box) == 2


# ---------------------------------------------------------------------------------------------------
# ContactSchedule


def test_schedule_is_checked_once_sorted_and_answers_queries():
    from solver.contact_schedule import ContactSchedule

    run = ContactSchedule.of([Contact("l_toe", 0.8, 1.1), Contact("r_toe", 0.4, 0.7), Contact("l_toe", 0.0, 0.3)], SITES)
    assert [c.start for c in run] == [0.0, 0.4, 0.8] and len(run) == 3 and run[0].site == "l_toe"
    assert run.flights() == [(0.3, 0.4), (0.7, 0.8)]  # no site in contact, between the first and last
    assert run.swings("l_toe") == [(0.3, 0.8)] and run.swings("r_toe") == []
    assert run.span == (0.0, 1.1)
    assert run.events(FEET) == ([(0.0, "left"), (0.4, "right"), (0.8, "left")], [(0.3, "left"), (0.7, "right"), (1.1, "left")])
    mask = run.mask(np.array([0.3, 0.35, 0.5]))
    np.testing.assert_array_equal(mask[:, SITES.index("l_toe")], [True, False, False])
    np.testing.assert_array_equal(mask[:, SITES.index("r_toe")], [False, False, True])
    assert ContactSchedule.of(run, SITES) is run  # already checked: the same value
    with pytest.raises(AttributeError):
        run.contacts = ()  # frozen
    empty = ContactSchedule.empty()
    assert not empty and len(empty) == 0 and empty.flights() == [] and empty.span is None
    assert ContactSchedule.of([], ()) == empty


@pytest.mark.parametrize("contacts, message", [
    ([Contact("l_toe", 0, 1), Contact("nose", 0, 1)],
     r"^contact 1: 'site' is 'nose'; the figure's contact sites are l_heel, l_toe, r_heel, r_toe$"),
    ([Contact("l_toe", 1, 0.5)], r"^contact 0: 'end' 0.5 is not after 'start' 1; swap them$"),
    ([Contact("l_toe", 1, 1)], r"^contact 0: 'end' 1 is not after 'start' 1; give the contact a duration$"),
    ([Contact("l_toe", 0, float("nan"))], r"^contact 0: 'end' is nan; give a finite number of seconds$"),
    ([Contact("l_toe", 0, 1, "moon")], r"^contact 0: 'surface' is 'moon', which the scene does not have; its "
                                       r"surfaces are floor, step \(or leave 'surface' out"),
])
def test_schedule_errors_are_one_line_naming_the_contact_field_and_value(contacts, message):
    from solver.contact_schedule import ContactSchedule

    with pytest.raises(InputError, match=message):
        ContactSchedule.of(contacts, SITES, ("floor", "step"))


def test_schedule_checks_surfaces_when_a_scene_is_given_naming_its_source():
    from solver.contact_schedule import ContactSchedule

    sched = ContactSchedule.of([Contact("l_toe", 0, 1, "stpe")], SITES, source="k.json", labels=["contacts[4]"])
    assert sched.surfaces is None  # no scene yet: the name is only a string
    with pytest.raises(InputError, match=r"^k\.json: contacts\[4\]: 'surface' is 'stpe', which the scene does not"):
        sched.for_scene(("floor", "step"))
    assert ContactSchedule.of([Contact("l_toe", 0, 1, "step")], SITES).for_scene(("floor", "step")).surfaces == ("floor",
                                                                                                          "step")


def test_a_one_frame_contact_spans_half_a_frame_either_side():
    z = np.full(30, 0.2)
    z[10] = 0.0  # one frame on the ground (height alone decides)
    times, pos, h = one_site(z)
    cs = detect_contacts(times, pos, h, sites=("l_toe",), speed_on=1e9, speed_off=1e9, min_duration=0.0)
    assert cs == [Contact("l_toe", pytest.approx(0.095), pytest.approx(0.105))]
    assert contact_mask(cs, ("l_toe",), times)[:, 0].tolist() == [i == 10 for i in range(30)]
    z = np.full(30, 0.2)
    z[0] = z[-1] = 0.0  # at the ends: from / to the end frame
    times, pos, h = one_site(z)
    cs = detect_contacts(times, pos, h, sites=("l_toe",), speed_on=1e9, speed_off=1e9, min_duration=0.0)
    assert [(c.start, c.end) for c in cs] == [(0.0, pytest.approx(0.005)), (pytest.approx(0.285), pytest.approx(0.29))]


def test_reference_contacts_keep_a_short_touch_down(toy_model):
    """The toy figure (soles 0.95 m under the root) hops: standing, a 42 ms touch-down between two
    flights, standing. The schedule keeps the touch-down (it was dropped under a 50 ms minimum) and
    so has two flights, not one."""
    n, ft = 110, 1 / 120
    qpos = np.zeros((n, toy_model.nq))
    qpos[:, 3] = 1.0
    qpos[:, 7::4] = 1.0
    t = np.arange(n) * ft
    lift = np.zeros(n)
    for a, b in ((20, 50), (55, 85)):  # flights of 0.25 s (7.7 cm high); frames 50..55 on the ground
        s = t[a:b + 1] - t[a]
        lift[a:b + 1] = 9.81 / 2 * s * (t[b] - t[a] - s)  # ballistic: up and down in (b - a) frames
    qpos[:, 2] = 0.952 + lift
    cs = reference_contacts(toy_model, qpos, ft)
    from solver.contact_schedule import ContactSchedule

    flights = ContactSchedule.of(cs, SITES).flights()
    assert len(flights) == 2, flights
    assert any(c.start <= t[52] <= c.end and c.duration < 0.05 for c in cs)  # in contact mid touch-down
    assert flights[0][1] - flights[0][0] > 0.2 and flights[1][1] - flights[1][0] > 0.2
