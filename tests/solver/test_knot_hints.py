"""Knot hints (`solver.subdivide.knot_hint_times`): the least change's first variable frames at the
contacts' touch-downs and lift-offs, kept apart from other frames."""
import numpy as np

from solver.frames import FrameSet
from solver.keyframes import Keyframes
from solver.subdivide import knot_hint_times


def frames_at(times, nq=4):
    times = np.asarray(times, float)
    vals = np.tile([1.0, 0, 0, 0], (len(times), 1))[:, :nq]
    return FrameSet.from_keyframes(Keyframes(times, vals, np.ones_like(vals, bool)), np.array([[0, 1, 2, 3]]))


def test_hints_keep_their_distance_from_frames_and_each_other():
    fs = frames_at([0.0, 0.25, 0.5])
    got = knot_hint_times(fs, [0.6, 0.26, 0.2, 0.11, 0.1, 0.01, 0.5, -1.0], 0.03)
    # 0.01 is 10 ms from the first keyframe, 0.11 10 ms from the hint 0.1 (the earlier wins), 0.26 10 ms
    # from a keyframe, 0.5 on the last, 0.6 and -1 outside
    np.testing.assert_array_equal(got, [0.1, 0.2])
    np.testing.assert_array_equal(knot_hint_times(fs, [0.2, 0.21], 0.0), [0.2, 0.21])
    assert knot_hint_times(fs, [], 0.03).size == 0
