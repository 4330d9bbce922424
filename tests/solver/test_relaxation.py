"""What a keyframe forces: a height limit around a keyframe that breaks it is raised by the plain spline's
values there, but never beyond the keyframe's own excess (solver.constraint_set._relax_run)."""
from types import SimpleNamespace

import numpy as np

from solver.constraint_set import _relax_run


def test_the_run_around_a_key_is_raised_at_most_by_the_keys_own_excess():
    """Seven pairs of one series at 0, 0.01, ... 0.06 s; the plain spline breaks the bound by v [m] on the run
    0.01-0.05 s around the key at 0.02 s, dipping 8 mm beside a key that is 5 mm in: the limits rise by v
    capped at 5 mm on the run, and nothing outside it."""
    c = SimpleNamespace(rows=np.arange(7), limit=np.zeros(7))
    v = np.array([0.0, 0.003, 0.005, 0.008, 0.004, 0.0, 0.002])
    ptimes = 0.01 * np.arange(7)
    span = _relax_run(c, v.copy(), ptimes, np.arange(7), 0.02, 0.005)
    np.testing.assert_allclose(c.limit, [0.0, 0.003, 0.005, 0.005, 0.004, 0.0, 0.0], rtol=0, atol=1e-15)
    assert span == (0.01, 0.04)
