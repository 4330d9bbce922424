"""runner/bench/random_sets.py: the seeded keyframe-set generator of the orientation benchmarks (docs/orient.md)."""
import numpy as np

from runner.bench.random_sets import (
    ACCEPTANCE_SEEDS,
    ANGLE_DEG,
    KEYFRAMES,
    MAX_INTERVAL_RATIO,
    TUNING_SEEDS,
    random_set,
)


def angles_deg(q):
    d = np.clip(np.abs(np.sum(q[1:] * q[:-1], axis=1)), 0.0, 1.0)
    return np.degrees(2.0 * np.arccos(d))


def test_sets_follow_the_specification():
    sizes = set()
    for seed in list(TUNING_SEEDS) + list(ACCEPTANCE_SEEDS):
        s = random_set(seed)
        k = len(s.times)
        sizes.add(k)
        assert KEYFRAMES[0] <= k <= KEYFRAMES[1] and s.quats.shape == (k, 4)
        np.testing.assert_allclose(np.linalg.norm(s.quats, axis=1), 1.0, atol=1e-12)
        ang = angles_deg(s.quats)  # measured from the quaternions, not the generator's draw
        np.testing.assert_allclose(ang, s.angles_deg, atol=1e-6)
        assert np.all(ang >= ANGLE_DEG[0] - 1e-9) and np.all(ang <= ANGLE_DEG[1] + 1e-9)
        dt = np.diff(s.times)
        assert s.times[0] == 0.0 and np.all(dt > 0)
        ratio = np.maximum(dt[1:] / dt[:-1], dt[:-1] / dt[1:])
        assert np.all(ratio <= MAX_INTERVAL_RATIO * (1 + 1e-12))
    assert sizes == set(range(KEYFRAMES[0], KEYFRAMES[1] + 1))


def test_seeded_and_distinct():
    a, b = random_set(7), random_set(7)
    np.testing.assert_array_equal(a.times, b.times)
    np.testing.assert_array_equal(a.quats, b.quats)
    assert not np.array_equal(random_set(8).quats[:2], a.quats[:2])
    assert not set(TUNING_SEEDS) & set(ACCEPTANCE_SEEDS)
