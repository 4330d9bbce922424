"""The frame set (solver/frames.py): which components are free, the flat variable vector, and inserting
variable frames (the path must not change; paper sec. 2, "Variable points")."""
import numpy as np
import pytest

from solver.frames import FrameSet
from solver.keyframes import Keyframes


def line_frames(times, a=(0.5, -1.0), b=(2.0, 0.25)):
    """Frames on the line a + b t (the natural spline through them is that line)."""
    return np.asarray(a) + np.outer(times, b)


def test_from_keyframes_fixes_the_masked_components_only():
    values = np.array([[0.0, 1.0], [np.nan, 3.0], [2.0, 5.0]])
    mask = np.array([[True, True], [False, True], [True, True]])
    fs = FrameSet.from_keyframes(Keyframes(np.array([0.0, 1.0, 2.0]), values, mask), np.zeros((0, 4), int))
    np.testing.assert_array_equal(fs.fixed, mask)
    assert fs.is_keyframe.all() and fs.count == 3 and fs.n_variable == 0 and fs.n_free == 1
    np.testing.assert_array_equal(fs.values[mask], values[mask])
    assert fs.values[1, 0] == pytest.approx(1.0)  # free component: the line through its keyframes (0 -> 2)


def test_x_is_the_free_components_row_major_and_with_x_keeps_the_fixed_ones():
    values = np.arange(12.0).reshape(4, 3)
    fixed = np.array([[1, 1, 1], [0, 1, 0], [0, 0, 0], [1, 1, 1]], bool)
    fs = FrameSet(np.array([0.0, 1.0, 2.0, 3.0]), values, fixed, np.array([1, 1, 0, 1], bool))
    np.testing.assert_array_equal(fs.x(), [3.0, 5.0, 6.0, 7.0, 8.0])
    new = fs.with_x(np.array([-1.0, -2.0, -3.0, -4.0, -5.0]))
    expected = values.copy()
    expected[1, 0], expected[1, 2], expected[2] = -1.0, -2.0, [-3.0, -4.0, -5.0]
    np.testing.assert_array_equal(new.values, expected)
    np.testing.assert_array_equal(fs.values, np.arange(12.0).reshape(4, 3))  # the original is untouched
    np.testing.assert_array_equal(fs.values_from_x(new.x()), expected)


def test_variable_frames_inserted_on_a_line_lie_on_it():
    times = np.array([0.0, 0.7, 2.0])
    fs = FrameSet(times, line_frames(times), np.ones((3, 2), bool), np.ones(3, bool))
    new = fs.with_variable_frames(np.array([1.5, 0.2]))
    np.testing.assert_array_equal(new.times, [0.0, 0.2, 0.7, 1.5, 2.0])
    np.testing.assert_array_equal(new.is_keyframe, [True, False, True, False, True])
    np.testing.assert_array_equal(new.fixed, np.repeat(new.is_keyframe[:, None], 2, axis=1))
    np.testing.assert_allclose(new.values, line_frames(new.times), atol=1e-14)
    t = np.linspace(0.0, 2.0, 41)
    np.testing.assert_allclose(new.path(t, 1), np.tile([2.0, 0.25], (41, 1)), atol=1e-13)  # the slope


def test_inserting_variable_frames_leaves_a_curved_path_unchanged():
    rng = np.random.default_rng(7)
    times = np.array([0.0, 0.4, 0.9, 1.7, 2.0])
    fs = FrameSet(times, rng.normal(size=(5, 3)), np.ones((5, 3), bool), np.ones(5, bool))
    new = fs.with_variable_frames(np.array([0.1, 1.2, 1.9]))
    t = np.linspace(0.0, 2.0, 201)
    for nu in (0, 1, 2):
        np.testing.assert_allclose(new.path(t, nu), fs.path(t, nu), atol=1e-10)
    assert new.n_variable == 3 and new.n_free == 9


@pytest.mark.parametrize("bad", [[0.0], [2.0], [-0.5], [0.4], [0.3, 0.3]])
def test_variable_frames_outside_or_on_a_frame_are_refused(bad):
    times = np.array([0.0, 0.4, 2.0])
    fs = FrameSet(times, line_frames(times), np.ones((3, 2), bool), np.ones(3, bool))
    with pytest.raises(ValueError):
        fs.with_variable_frames(np.array(bad))


def test_with_midpoints_is_inserting_every_segment_midpoint():
    """`with_midpoints` (the subdivision candidates) equals `with_variable_frames` of the midpoints,
    including a partial keyframe's free component."""
    values = np.array([[0.0, 1.0], [np.nan, 3.0], [2.0, -5.0], [1.0, 0.5]])
    mask = np.array([[True, True], [False, True], [True, True], [True, True]])
    fs = FrameSet.from_keyframes(Keyframes(np.array([0.0, 0.7, 2.0, 2.4]), values, mask), np.zeros((0, 4), int))
    fs = fs.with_variable_frames([1.1])
    a, b = fs.with_midpoints(), fs.with_variable_frames(0.5 * (fs.times[:-1] + fs.times[1:]))
    np.testing.assert_array_equal(a.times, b.times)
    np.testing.assert_allclose(a.values, b.values, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(a.fixed, b.fixed)
    np.testing.assert_array_equal(a.is_keyframe, b.is_keyframe)
