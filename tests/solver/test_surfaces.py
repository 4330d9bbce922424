"""StaticSurfaces.penetration with a margin per point equals the scalar margin point by point."""
import mujoco
import numpy as np

from solver.surfaces import StaticSurfaces

from conftest import TOY_SCENE


def test_margin_per_point_matches_a_scalar_margin_point_by_point():
    s = StaticSurfaces.from_model(mujoco.MjModel.from_xml_string(TOY_SCENE))  # the floor and a 20 cm step
    rng = np.random.default_rng(2)
    p = np.column_stack([rng.uniform(0.9, 2.1, 40), rng.uniform(-1.2, 1.2, 40), rng.uniform(-0.02, 0.3, 40)])
    p = p.reshape(10, 4, 3)
    margin = rng.uniform(0.0, 0.05, (10, 4))
    d, g = s.penetration(p, margin)
    assert d.shape == (10, 4, s.count) and g.shape == (10, 4, s.count, 3)
    for i in range(10):
        for k in range(4):
            di, gi = s.penetration(p[i, k], float(margin[i, k]))
            np.testing.assert_array_equal(d[i, k], di)
            np.testing.assert_array_equal(g[i, k], gi)
    # by hand: 1 cm above the floor away from the step, a 3 cm margin -> 2 cm deep into the floor's band
    d1, _ = s.penetration(np.array([[0.0, 0.0, 0.01]]), np.array([0.03]))
    np.testing.assert_allclose(d1[0], [0.02, 0.0], atol=1e-15)
    assert (d > 0).any() and (d == 0).any()
