"""SupportSurfaces with rounded edges: the clearance height is continuous across a box's edge."""
import mujoco
import numpy as np

from solver.support import SupportSurfaces
from solver.surfaces import StaticSurfaces

LEDGE = """<mujoco><worldbody>
  <geom name="floor" type="plane" size="5 5 0.1"/>
  <geom name="ledge" type="box" pos="1.5 0 0.22" size="0.5 0.5 0.22"/>
</worldbody></mujoco>"""


def _support(rounded):
    return SupportSurfaces(StaticSurfaces.from_model(mujoco.MjModel.from_xml_string(LEDGE)), rounded)


def test_height_is_continuous_across_the_edge_and_matches_the_distance_to_the_top():
    """A point 2 mm above the 44 cm ledge's top, moved across its edge (x = 1.0): without rounding the
    height jumps from 2 mm to 442 mm; rounded it is the distance to the edge line, by hand."""
    x = np.linspace(0.95, 1.05, 2001)
    p = np.stack([x, 0 * x, np.full_like(x, 0.442)], axis=1)
    h_old, _ = _support(False).height(p)
    h, _ = _support(True).height(p)
    assert np.max(np.abs(np.diff(h_old))) > 0.4                 # the jump this fixes
    expected = np.where(x >= 1.0, 0.002, np.hypot(1.0 - x, 0.002))
    np.testing.assert_allclose(h, expected, atol=1e-12)
    assert np.max(np.abs(np.diff(h))) < 1e-4                   # continuous: steps of the sampling only


def test_rounded_gradient_is_the_finite_difference_and_unit():
    rng = np.random.default_rng(3)
    pts = np.column_stack([rng.uniform(0.9, 1.1, 300), rng.uniform(-0.6, 0.6, 300), rng.uniform(0.0, 0.5, 300)])
    s = _support(True)
    h, n = s.height(pts)
    eps = 1e-6
    for axis in range(3):
        dp = np.zeros(3)
        dp[axis] = eps
        fd = (s.height(pts + dp)[0] - s.height(pts - dp)[0]) / (2 * eps)
        ok = np.abs(fd - n[:, axis]) < 1e-5
        assert ok.mean() > 0.98                                 # but for points within eps of a switch
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)


def test_floor_level_beside_the_wall_is_the_floor():
    """A toe on the floor beside the ledge's wall is at its height above the floor (not pushed off the
    wall): the top's edge is 44 cm away."""
    p = np.array([[0.99, 0.0, 0.01]])
    h, n = _support(True).height(p)
    np.testing.assert_allclose(h, [0.01], atol=1e-12)
    np.testing.assert_allclose(n, [[0.0, 0.0, 1.0]], atol=1e-12)
