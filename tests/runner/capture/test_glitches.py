"""runner.capture.glitches: tracking glitches (a joint turning faster than OMEGA_MAX between frames) replaced by
the slerp between the kept frames, on hand-built rotations about one axis whose angles are known exactly."""
import numpy as np
import pytest

import solver
from runner.capture.glitches import OMEGA_MAX, glitches_line, repair_glitches
from solver.layout import StateLayout

DT = 1.0 / 120.0


def _about_z(deg):
    h = np.radians(np.asarray(deg, float)) / 2
    return np.stack([np.cos(h), np.zeros_like(h), np.zeros_like(h), np.sin(h)], axis=-1)


def _angles(q):
    """Rotation angles [deg] about z of (n, 4) quaternions about z, unwrapped."""
    return np.degrees(np.unwrap(2 * np.arctan2(q[:, 3], q[:, 0])))


@pytest.fixture(scope="module")
def layout():
    return StateLayout.from_model(solver.load_model(solver.shipped("floor.xml")))


def _motion(layout, joint, deg):
    """(n, nq) qpos at rest but `joint` turned about z by deg (n,)."""
    qpos = np.zeros((len(deg), layout.nq))
    for slot in layout.quat_slots:
        qpos[:, slot] = [1.0, 0.0, 0.0, 0.0]
    qpos[:, layout.joint(joint).quat_index] = _about_z(deg)
    return qpos


def test_a_flip_and_back_is_replaced_by_the_slerp_between_its_neighbours(layout):
    deg = 1000.0 * DT * np.arange(40)  # 1000 deg/s, well under the bound
    deg[20:22] += 150.0  # two frames flipped 150 deg: 18,000 deg/s in and out
    out, found = repair_glitches(_motion(layout, "r_ankle", deg), layout, DT)
    got = _angles(out[:, layout.joint("r_ankle").quat_index])
    assert got == pytest.approx(1000.0 * DT * np.arange(40), abs=1e-9)  # the slerp of a uniform turn is it
    assert [(g.joint, round(g.start / DT), round(g.end / DT)) for g in found] == [("r_ankle", 20, 21)]
    assert found[0].turn_deg == pytest.approx(150.0 + 1000.0 * DT * 2, abs=1e-6)
    others = [s for s in layout.quat_slots if tuple(s) != tuple(layout.joint("r_ankle").quat_index)]
    assert all(np.array_equal(out[:, s], _motion(layout, "r_ankle", deg)[:, s]) for s in others)


def test_a_fast_real_turn_under_the_bound_is_kept(layout):
    deg = 0.95 * np.degrees(OMEGA_MAX) * DT * np.arange(30)  # 95 % of the bound, 190 deg in all
    qpos = _motion(layout, "l_shoulder", deg)
    out, found = repair_glitches(qpos, layout, DT)
    assert found == () and np.allclose(out, qpos, atol=1e-12)


def test_a_jump_that_stays_is_kept_once_the_allowance_covers_it(layout):
    deg = np.r_[np.zeros(10), np.full(10, 120.0)]  # one jump of 120 deg, then still
    out, found = repair_glitches(_motion(layout, "torso", deg), layout, DT)
    k = int(np.ceil(120.0 / (np.degrees(OMEGA_MAX) * DT)))  # frames until 7,000 deg/s covers 120 deg: 3
    got = _angles(out[:, layout.joint("torso").quat_index])
    assert got[:10] == pytest.approx(0.0, abs=1e-9) and got[9 + k:] == pytest.approx(120.0, abs=1e-9)
    assert got[10:9 + k] == pytest.approx(120.0 * np.arange(1, k) / k, abs=1e-9)  # the slerp over k steps
    assert len(found) == 1 and found[0].start == pytest.approx(10 * DT) and found[0].end == pytest.approx((8 + k) * DT)


def test_a_glitch_at_the_end_holds_the_last_kept_orientation(layout):
    deg = np.r_[np.zeros(10), 170.0]
    out, found = repair_glitches(_motion(layout, "r_knee", deg), layout, DT)
    assert _angles(out[:, layout.joint("r_knee").quat_index]) == pytest.approx(0.0, abs=1e-9)
    assert len(found) == 1 and "r_knee" in glitches_line(found)
    assert glitches_line(()) is None
