"""The IK peer of `dynsplines clean` (runner/bench/clean_peer.py, mink): a sliding planted foot of the toy
figure is held at its contact's target at every frame of the contact, and frames without a contact are the
capture's own. Skips without mink (`pip install -e ".[peer]"`)."""
import numpy as np
import pytest

from solver.contacts import Contact, site_positions

pytest.importorskip("mink")


def test_a_sliding_planted_site_is_held_at_its_target(toy_model):
    from runner.bench.clean_peer import ik_clean

    n = 31
    t = np.arange(n) / 30.0
    q = np.zeros((n, toy_model.nq))
    q[:, 2] = 0.95  # straight legs: every site on the floor (0.95 m below the pelvis)
    q[:, 0] = np.linspace(0.0, 0.02, n)  # the whole figure slides 2 cm forward
    for a in (3, 7, 11, 15, 19):  # the free root's and the ball joints' quaternions
        q[:, a] = 1.0
    contact = Contact("l_heel", 0.2, 0.6, "floor")
    out, cpu = ik_clean(toy_model, t, q, [contact])
    on = (t >= 0.2 - 1e-9) & (t <= 0.6 + 1e-9)
    got = site_positions(toy_model, out[on], ["l_heel"])[:, 0]
    target = site_positions(toy_model, q[on], ["l_heel"])[:, 0].mean(axis=0)
    target[2] = 0.0  # a point site (radius 0) set on the floor
    assert np.abs(got - target).max() <= 5e-4  # within half a millimetre
    np.testing.assert_array_equal(out[~on], q[~on])
    assert cpu >= 0.0
