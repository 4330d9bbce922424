"""`solver.path_state.add_at` (the pulls' scatter-add) against numpy's np.add.at: repeated indices summed,
trailing axes, broadcast index arrays and values, and a non-contiguous target."""
import numpy as np
import pytest

from solver.path_state import add_at


@pytest.mark.parametrize("tail", [(), (3,)])
def test_add_at_sums_repeated_indices_as_np_add_at(tail):
    rng = np.random.default_rng(0)
    target = rng.normal(size=(7, 5) + tail)
    rows = rng.integers(0, 7, size=(40, 1))
    cols = rng.integers(0, 5, size=(40, 4))  # broadcast with rows; many (row, col) repeat
    values = rng.normal(size=(40, 4) + tail)
    want = target.copy()
    np.add.at(want, (rows, cols), values)
    add_at(target, (rows, cols), values)
    np.testing.assert_allclose(target, want, rtol=0, atol=1e-12)


def test_add_at_on_a_non_contiguous_target_changes_the_target():
    rng = np.random.default_rng(1)
    base = rng.normal(size=(6, 8))
    target = base[:, ::2]  # a view, not C-contiguous
    want = target.copy()
    rows, cols = np.array([0, 0, 5]), np.array([1, 1, 3])
    np.add.at(want, (rows, cols), 1.0)
    add_at(target, (rows, cols), 1.0)
    np.testing.assert_array_equal(base[:, ::2], want)
