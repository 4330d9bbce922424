"""The no-jolt bound's smooth form, and the excess it reports in the quantity's own unit."""
from types import SimpleNamespace

import numpy as np

from solver.constraints.acceleration import AccelerationBound


def _state(qacc):
    return SimpleNamespace(motion=SimpleNamespace(qacc=np.asarray(qacc, float)))


def test_met_exactly_at_the_limit_and_the_excess_is_the_magnitudes():
    """Two points, two columns (dofs 0-2 and 3-5) with limits 4 and 10: |a| = 5 and 3 at the first point,
    4 and 12 at the second. c = 0 where |a| = A; the excess beyond the limit is |a| - A (1 and 2), not the
    smooth form's (|a|^2 - A^2) / (2 A) (1.125 and 2.2)."""
    bound = AccelerationBound(2, [[0, 1, 2], [3, 4, 5]], [4.0, 10.0], [0.2, 0.5], ["pelvis", "hip"])
    state = _state([[3.0, 4.0, 0.0, 3.0, 0.0, 0.0], [0.0, 0.0, 4.0, 0.0, 12.0, 0.0]])
    c = bound.measure(state) - bound.limit
    np.testing.assert_allclose(c, [(25 - 16) / 8, (9 - 100) / 20, 0.0, (144 - 100) / 20])
    np.testing.assert_allclose(bound.excess(bound.measure(state), bound.limit, np.arange(4)), [1.0, -7.0, 0.0, 2.0])
    # against a raised limit (the smooth form's 2.2 at the hip: |a| 12 allowed): nothing beyond it
    raised = bound.limit + np.array([0.0, 0.0, 0.0, 2.2])
    assert abs(bound.excess(bound.measure(state), raised, np.array([3]))[0]) < 1e-12


def test_each_column_shows_its_own_unit():
    """A certificate names a joint's raise in rad/s^2 and the pelvis's in m/s^2 (`Raise.unit`), not both at once."""
    bound = AccelerationBound(2, [[0, 1, 2], [3, 4, 5]], [4.0, 10.0], [0.2, 0.5], ["pelvis", "hip"], linear=[True, False])
    assert (bound.column_unit("pelvis"), bound.column_unit("hip")) == ("m/s^2", "rad/s^2")
    angular = AccelerationBound(2, [[0, 1, 2], [3, 4, 5]], [4.0, 10.0], [0.2, 0.5], ["a", "b"])
    assert {angular.column_unit(x) for x in ("a", "b")} == {"rad/s^2"}
