"""runner.capture.keyframe_selection: keys at contact events, ends and the root's extremes."""
from pathlib import Path

import mujoco
import numpy as np
import pytest
from shipped_sites import FEET

from runner.capture.contact_detection import reference_contacts
from runner.capture.keyframe_selection import KEY_MIN_GAP, CaptureError, add_keys_to_tolerance, contact_keyframes
from solver.contacts import Contact, touchdowns_liftoffs
from solver.errors import InputError

ROOT = Path(__file__).resolve().parents[3]
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
    keys = contact_keyframes(t, cs, z, FEET)
    assert keys.tolist() == [0, 15, 30, 50, 70, 85, 100]


def test_close_events_merge_and_ends_stay():
    t = np.arange(101) / FPS
    cs = [Contact("l_toe", 0.02, 0.40), Contact("r_toe", 0.42, 0.98)]   # lift-off 2 frames before touch-down
    keys = contact_keyframes(t, cs, np.full(101, 0.9), FEET)
    assert keys.tolist() == [0, 41, 100]


def test_every_fills_long_gaps_only():
    t, cs, z = broad_jump()
    keys = contact_keyframes(t, cs, z, FEET, every=0.1)
    assert np.all(np.diff(t[keys]) <= 0.1 + 1e-9)
    assert {0, 15, 30, 50, 70, 85, 100} <= set(keys.tolist())
    assert len(keys) == 13      # each of the six gaps (0.15 or 0.2 s) split in two
    with pytest.raises(InputError, match="every"):
        contact_keyframes(t, cs, z, FEET, every=0)
    with pytest.raises(InputError, match="root_z"):
        contact_keyframes(t, cs, z[:-1], FEET)


def test_127_33_keys_at_the_landings():
    from runner.capture.reference_motion import load_bvh_reference
    model = mujoco.MjModel.from_xml_path(str(ROOT / "models" / "run_and_step.xml"))
    ref = load_bvh_reference(ROOT / "models" / "cmu" / "127_33.bvh", model)
    cs = reference_contacts(model, ref.qpos, ref.frame_time)
    keys = contact_keyframes(ref.times, cs, ref.qpos[:, 2], FEET)
    print("keys", keys.tolist(), "times", np.round(ref.times[keys], 3).tolist())
    td, lo = touchdowns_liftoffs(cs, FEET)
    for time, _ in td + lo:     # every contact event has a key within the merge distance
        assert np.min(np.abs(ref.times[keys] - time)) <= 4 * ref.frame_time
    assert keys[0] == 0 and keys[-1] == ref.count - 1
    assert np.all(np.diff(keys) > 0)


# --- keys added where the plain spline strays from the capture ------------------------------------


def _linear_error(t, f, tol):
    """error(keys) = |f - piecewise-linear interpolation of f at the keys| / tol: a hand-built stand-in
    for `CaptureError` whose worst frame is known in closed form."""
    def error(keys):
        k = np.asarray(keys)
        return np.abs(f - np.interp(t, t[k], f[k])) / tol
    return error


def test_added_keys_bring_every_eligible_frame_within_tolerance():
    t = np.arange(201) / FPS                      # 2 s
    f = np.sin(2 * np.pi * t)                     # one period: the chord 0-2 s misses by 1 at 0.25 s
    error = _linear_error(t, f, 0.05)
    keys = add_keys_to_tolerance([0, 200], error, t, min_gap=0.1)
    assert keys[0] == 0 and keys[-1] == 200 and keys == sorted(set(keys))
    gaps = np.diff(t[keys])
    assert gaps.min() >= 0.1 - 1e-9
    e = error(keys)
    # a frame still above tolerance is within min_gap of a key (it could not become one)
    for i in np.flatnonzero(e > 1.0):
        assert np.min(np.abs(t[keys] - t[i])) < 0.1
    # the first key added is the frame furthest from the chord: a peak of the sine (0.25 or 1.25 s)
    first = add_keys_to_tolerance([0, 200], error, t, min_gap=0.1, max_keys=3)
    assert len(first) == 3 and first[1] in (25, 125)


def test_no_key_added_where_the_spline_is_within_tolerance():
    t = np.arange(101) / FPS
    f = 0.3 * t                                    # a straight line: the chord is exact
    assert add_keys_to_tolerance([0, 100], _linear_error(t, f, 1e-3), t) == [0, 100]


def test_contact_keyframes_key_a_long_gap_the_events_leave():
    """One contact from 0 to 0.2 s, then 1.8 s with no event and a flat root: events and extremes key
    nothing in it; a capture that bends there gets keys from the error."""
    t = np.arange(201) / FPS
    cs = [Contact("l_toe", 0.0, 0.2)]
    z = np.full(201, 0.9)
    f = np.where(t > 0.2, np.sin(np.pi * (t - 0.2) / 1.8), 0.0)
    without = contact_keyframes(t, cs, z, FEET)
    assert without.tolist() == [0, 20, 200]
    keys = contact_keyframes(t, cs, z, FEET, error=_linear_error(t, f, 0.1))
    assert set(without) <= set(keys.tolist()) and len(keys) > 3
    miss = np.abs(f - np.interp(t, t[keys], f[keys])) / 0.1
    far = np.array([np.min(np.abs(t[keys] - x)) >= KEY_MIN_GAP for x in t])  # frames that could be keys
    assert np.all(miss[far] <= 1.0)


def _figure():
    return mujoco.MjModel.from_xml_path(str(ROOT / "models" / "floor.xml"))


def test_capture_error_joint_term_is_the_normalized_lerp_angle():
    """Keys at the ends of a knee turning at a constant rate: the plain spline is the straight line
    between the two quaternions (a natural spline through two knots), normalized; its angle is
    2 atan2(s sin(phi/2), 1 - s + s cos(phi/2)) at s = t / T, against the capture's phi s."""
    model = _figure()
    n, phi = 61, 1.4
    t = np.linspace(0.0, 0.6, n)
    s = t / t[-1]
    q = np.tile(model.qpos0, (n, 1))
    a = int(model.jnt_qposadr[model.joint("r_knee").id])
    q[:, a:a + 4] = np.stack([np.cos(phi * s / 2), np.sin(phi * s / 2), 0 * s, 0 * s], axis=1)
    err = CaptureError(model, t, q, joint_deg=1.0, site_cm=1e12)
    kinds = (int(mujoco.mjtJoint.mjJNT_BALL), int(mujoco.mjtJoint.mjJNT_FREE))
    slots = sum(int(model.jnt_type[j]) in kinds for j in range(model.njnt))
    nlerp = 2.0 * np.arctan2(s * np.sin(phi / 2), 1.0 - s + s * np.cos(phi / 2))
    expected = np.degrees(np.abs(nlerp - phi * s)) / slots
    np.testing.assert_allclose(err([0, n - 1]), expected, atol=1e-9)
    assert np.all(err(list(range(n))) < 1e-9)      # keyed everywhere: no error


def test_capture_error_site_term_is_the_mean_site_distance_by_mujoco():
    model = _figure()
    data = mujoco.MjData(model)
    n = 41
    t = np.linspace(0.0, 0.4, n)
    q = np.tile(model.qpos0, (n, 1))
    a = int(model.jnt_qposadr[model.joint("l_hip").id])
    ang = 0.8 * np.sin(np.pi * t / 0.4)            # a hip swing out and back: the chord of the ends is still
    q[:, a:a + 4] = np.stack([np.cos(ang / 2), 0 * t, np.sin(ang / 2), 0 * t], axis=1)
    err = CaptureError(model, t, q, joint_deg=1e12, site_cm=2.0)
    Y = err.plain([0, n - 1])
    ids = [model.site(s).id for s in ("l_heel", "l_toe", "r_heel", "r_toe")]

    def sites(qpos):
        out = []
        for row in qpos:
            data.qpos[:] = row
            mujoco.mj_kinematics(model, data)
            out.append(data.site_xpos[ids].copy())
        return np.array(out)

    expected = 100.0 * np.linalg.norm(sites(Y) - sites(q), axis=-1).mean(axis=1) / 2.0
    np.testing.assert_allclose(err([0, n - 1]), expected, rtol=1e-9, atol=1e-9)
    assert expected.max() > 1.0                    # the test means something: the swing is missed


def test_capture_error_rejects_bad_input():
    model = _figure()
    t = np.linspace(0, 1, 5)
    with pytest.raises(InputError, match="qpos has shape"):
        CaptureError(model, t, np.zeros((4, model.nq)))
    with pytest.raises(InputError, match="joint_deg"):
        CaptureError(model, t, np.tile(model.qpos0, (5, 1)), joint_deg=0.0)


# --- keys where the capture turns far between keys ------------------------------------------------


def _full_turn(fps=120.0, seconds=1.0):
    """A root that turns once about z (360 deg, smoothstep in time between 0.1 and 0.6 s, up to 1080
    deg/s, as a jump with a full turn) while a second joint stays still: (times (n,), yaw (n,) [rad],
    quats (n, 2, 4))."""
    t = np.arange(int(round(seconds * fps)) + 1) / fps
    s = np.clip((t - 0.1) / 0.5, 0.0, 1.0)
    yaw = 2.0 * np.pi * s * s * (3.0 - 2.0 * s)
    q = np.zeros((len(t), 2, 4))
    q[:, 0, 0], q[:, 0, 3] = np.cos(yaw / 2), np.sin(yaw / 2)
    q[:, 1, 0] = 1.0
    return t, yaw, q


def _plain_heading(t, q, keys):
    """[rad] yaw of the natural cubic spline through the quaternions at `keys`, hemisphere-aligned as the
    solver starts from (`Keyframes.initial_values`), normalized at every frame."""
    from solver.keyframes import Keyframes
    from solver.spline import interpolate

    k = np.asarray(keys)
    vals = q[k].reshape(len(k), -1)
    kf = Keyframes(t[k], vals, np.ones(vals.shape, bool))
    y = interpolate(t[k], kf.initial_values(np.array([[0, 1, 2, 3], [4, 5, 6, 7]])), t)[:, :4]
    return 2.0 * np.arctan2(y[:, 3], y[:, 0])


def _wrapped(a):
    return np.abs((a + np.pi) % (2 * np.pi) - np.pi)


def test_a_full_turn_keyed_every_quarter_second_is_kept():
    from runner.capture.keyframe_selection import KEY_TURN_DEG, turn_keys

    t, yaw, q = _full_turn()
    every = [0, 30, 60, 90, 120]                      # 0.25 s apart: 0, 78, 323, 360, 360 deg
    lost = _wrapped(_plain_heading(t, q, every) - yaw).max()
    assert np.degrees(lost) > 90.0                    # the short way round: the turn is lost without the rule
    keys = turn_keys(every, q)
    assert set(every) <= set(keys)
    for a, b in zip(keys[:-1], keys[1:]):             # every interval within 90 deg of its first key
        assert np.degrees(_wrapped(yaw[a:b + 1] - yaw[a])).max() <= KEY_TURN_DEG + 1e-9
    assert np.degrees(_wrapped(_plain_heading(t, q, keys) - yaw).max()) < 30.0
    assert len(keys) <= len(every) + 4                # 360 deg needs at most 4 more keys of <= 90 deg
    flipped = q * np.where(np.arange(len(t)) % 3 == 0, -1.0, 1.0)[:, None, None]
    assert turn_keys(every, flipped) == keys          # either sign of a quaternion is the same orientation


def test_turn_keys_leave_slow_turns_alone_and_reject_bad_input():
    from runner.capture.keyframe_selection import turn_keys

    t = np.arange(481) / 120.0                        # 4 s: one turn at 90 deg/s, 45 deg between keys 0.5 s apart
    q = np.zeros((len(t), 1, 4))
    q[:, 0, 0], q[:, 0, 3] = np.cos(np.pi * t / 4), np.sin(np.pi * t / 4)
    slow = list(range(0, 481, 60))
    assert turn_keys(slow, q) == slow
    loop = turn_keys([0, 480], q)                     # a whole turn between two keys of the same orientation
    assert loop[1] > 0 and 5 <= len(loop) <= 6        # split at its far point, then in halves again
    assert all(b - a <= 121 for a, b in zip(loop[:-1], loop[1:]))   # <= 90 deg (120 frames) apart
    half = np.array([[[1.0, 0, 0, 0]], [[0.0, 0, 0, 1]]])                       # 180 deg in one frame
    assert turn_keys([0, 1], half) == [0, 1]          # two adjacent frames are never split
    with pytest.raises(InputError, match="shape"):
        turn_keys([0, 10], q[:, 0])
    with pytest.raises(InputError, match="between 0 and 180"):
        turn_keys([0, 10], q, limit_deg=200.0)
    with pytest.raises(InputError, match="outside"):
        turn_keys([0, len(t)], q)
