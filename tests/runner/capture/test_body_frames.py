"""The frames in which a foot is taken to be flat (runner/capture/body_frames.py, the foot's up axis), on
hand-built ankle and ball-of-the-foot paths whose flat frames are known: a stair climber whose only
frames on the floor are a push-off, a dancer who holds a kicked foot still in the air, a runner whose
first stance is on the forefoot, and a kneel that is the clip's only stillness."""
import numpy as np

from runner.capture.body_frames import FLAT_FRACTION, _flat


def _still(n, at):
    return np.tile(np.asarray(at, float), (n, 1))


def _move(n, a, b):
    return np.linspace(np.asarray(a, float), np.asarray(b, float), n)


def _count(n):
    return max(1, round(FLAT_FRACTION * n))


def test_a_push_off_from_the_floor_is_not_flat_the_still_foot_on_the_step_is():
    # 10 frames of push-off: the ball stays on the floor, the ankle rises 12 cm (the heel lifts); a swing;
    # then the foot stands flat and still on a 20 cm step
    ankle = np.r_[_move(10, [0, 0, 0.08], [0.02, 0, 0.20]), _move(20, [0.05, 0, 0.25], [0.4, 0, 0.30]),
                  _still(50, [0.45, 0, 0.28])]
    ball = np.r_[_still(10, [0.12, 0, 0.02]), _move(20, [0.15, 0, 0.10], [0.5, 0, 0.25]), _still(50, [0.57, 0, 0.22])]
    flat = _flat(ankle, ball)
    assert len(flat) == _count(80) and flat.min() >= 30
    assert np.argsort(ankle[:, 2])[0] < 10  # the lowest ankle alone would be the push-off


def test_a_foot_held_still_in_the_air_is_not_flat():
    # standing (sliding slowly, both joints together), a kick, the kicked foot held still at 1.1 m
    ankle = np.r_[_move(40, [0, 0, 0.08], [0.1, 0, 0.08]), _move(40, [0.1, 0, 0.1], [0.3, 0, 1.1]),
                  _still(20, [0.3, 0, 1.1])]
    ball = ankle + [0.12, 0, -0.06]
    flat = _flat(ankle, ball)
    assert len(flat) == _count(100) and flat.max() < 40


def test_a_forefoot_stance_is_not_flat_the_heel_down_stance_is():
    # a runner's first stance on the forefoot (ankle 14 cm up, still), a swing, then a stance heel down
    ankle = np.r_[_still(20, [0, 0, 0.137]), _move(40, [0.05, 0, 0.2], [1.0, 0, 0.15]), _still(20, [1.1, 0, 0.092])]
    ball = np.r_[_still(20, [0.11, 0, 0.06]), _move(40, [0.15, 0, 0.1], [1.1, 0, 0.08]), _still(20, [1.21, 0, 0.046])]
    flat = _flat(ankle, ball)
    assert len(flat) == _count(80) and flat.min() >= 60


def test_a_kneel_is_not_flat_even_where_only_the_kneel_is_still():
    # standing flat while stepping about (the ankle 6 cm up, the knee 45 cm above it), then kneeling still (the
    # foot on its top, the ankle 5 cm up, the shin along the floor): the still frames are all kneeling ones, and
    # the flat frames are taken where the shin stands
    ankle = np.r_[_move(30, [0, 0, 0.06], [0.6, 0, 0.06]), _still(70, [0.6, 0, 0.05])]
    ball = np.r_[_move(30, [0.12, 0, 0.0], [0.72, 0, 0.0]), _still(70, [0.48, 0, 0.02])]
    knee = np.r_[ankle[:30] + [0, 0, 0.45], _still(70, [1.05, 0, 0.05])]
    flat = _flat(ankle, ball, knee)
    assert len(flat) == _count(100) and flat.max() < 30
    assert _flat(ankle, ball).min() >= 30  # without the shin, the kneel is taken for flat


def test_a_frame_two_parallel_directions_cannot_fix_is_named():
    """TRIAD needs two directions that are not parallel: where a skeleton gives two, the error names the file and the
    body, and the fix, in one line; two that are not parallel give the rotation taking the first exactly."""
    import pytest

    from runner.capture.body_frames import triad
    from runner.capture.bvh_kinematics import rotate
    from solver.errors import InputError

    with pytest.raises(InputError) as e:
        triad([0, 1, 0], [0, 0, 1], [1.0, 0, 0], [2.0, 0, 0], "x.bvh: the pelvis's frame")
    assert str(e.value).startswith("x.bvh: the pelvis's frame: the two directions") and "--skeleton-map" in str(e.value)
    assert "\n" not in str(e.value)
    q = triad([0, 1, 0], [0, 0, 1], [1.0, 0, 0], [0.0, 0.3, 1.0])
    np.testing.assert_allclose(rotate(q, np.array([0.0, 1.0, 0.0])), [1.0, 0.0, 0.0], atol=1e-12)
