"""solver.keyframe_selection: keys at contact events, ends and the root's extremes."""
from pathlib import Path

import mujoco
import numpy as np
import pytest

from solver.contacts import Contact, reference_contacts, touchdowns_liftoffs
from solver.errors import InputError
from solver.keyframe_selection import contact_keyframes

ROOT = Path(__file__).resolve().parents[2]
FPS = 100.0


def broad_jump():
    """Both feet planted 0-0.3 s, flight with the apex at 0.5 s, landing 0.7-1.0 s; the root dips
    to its lowest at 0.15 s (the crouch before take-off) and at 0.85 s (the landing)."""
    t = np.arange(101) / FPS
    z = np.where(t < 0.3, 0.9 - 0.4 * t * (0.3 - t),            # dips, lowest at 0.15
                 np.where(t <= 0.7, 0.9 + 1.25 * (0.04 - (t - 0.5) ** 2),   # apex 0.95 at 0.5
                          0.9 - 0.4 * (t - 0.7) * (1.0 - t)))    # dips, lowest at 0.85
    cs = [Contact(s, 0.0, 0.3) for s in ("l_heel", "l_toe", "r_heel", "r_toe")]
    cs += [Contact(s, 0.7, 1.0) for s in ("l_heel", "l_toe", "r_heel", "r_toe")]
    return t, cs, z


def test_broad_jump_keys_contacts_apex_and_crouches():
    t, cs, z = broad_jump()
    keys = contact_keyframes(t, cs, z)
    assert keys.tolist() == [0, 15, 30, 50, 70, 85, 100]


def test_close_events_merge_and_ends_stay():
    t = np.arange(101) / FPS
    cs = [Contact("l_toe", 0.02, 0.40), Contact("r_toe", 0.42, 0.98)]   # lift-off 2 frames before touch-down
    keys = contact_keyframes(t, cs, np.full(101, 0.9))
    assert keys.tolist() == [0, 41, 100]


def test_every_fills_long_gaps_only():
    t, cs, z = broad_jump()
    keys = contact_keyframes(t, cs, z, every=0.1)
    assert np.all(np.diff(t[keys]) <= 0.1 + 1e-9)
    assert {0, 15, 30, 50, 70, 85, 100} <= set(keys.tolist())
    assert len(keys) == 13      # each of the six gaps (0.15 or 0.2 s) split in two
    with pytest.raises(InputError, match="every"):
        contact_keyframes(t, cs, z, every=0)
    with pytest.raises(InputError, match="root_z"):
        contact_keyframes(t, cs, z[:-1])


def test_127_33_keys_at_the_landings():
    from runner.mocap.reference import load_bvh_reference
    model = mujoco.MjModel.from_xml_path(str(ROOT / "models" / "run_and_step.xml"))
    ref = load_bvh_reference(ROOT / "models" / "cmu" / "127_33.bvh", model)
    cs = reference_contacts(model, ref.qpos, ref.frame_time)
    keys = contact_keyframes(ref.times, cs, ref.qpos[:, 2])
    print("keys", keys.tolist(), "times", np.round(ref.times[keys], 3).tolist())
    td, lo = touchdowns_liftoffs(cs)
    for time, _ in td + lo:     # every contact event has a key within the merge distance
        assert np.min(np.abs(ref.times[keys] - time)) <= 4 * ref.frame_time
    assert keys[0] == 0 and keys[-1] == ref.count - 1
    assert np.all(np.diff(keys) > 0)
