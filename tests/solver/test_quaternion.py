"""solver/quaternion.py: the swing-twist angle and its gradient."""
import numpy as np


def test_twist_angle_gradient_against_finite_differences_and_at_its_singularity():
    """d theta / d q of the swing-twist angle (solver.quaternion) by central differences at random
    quaternions; where w and the twist component vanish (theta undefined) the gradient is 0, not NaN."""
    from solver.quaternion import twist_angle, twist_angle_grad

    rng = np.random.default_rng(7)
    axis = np.array([1.0, 0.0, 0.0])
    for q in rng.normal(size=(20, 4)):
        g = twist_angle_grad(q, axis)
        fd = np.array([(twist_angle(q + 1e-6 * e, axis) - twist_angle(q - 1e-6 * e, axis)) / 2e-6 for e in np.eye(4)])
        np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-8)
    for q in ([0.0, 0.0, 0.0, 1.0], [-2.2855872811881898e-167, 0.0, 8.0795528188009805e-174, 1.0]):
        g = twist_angle_grad(np.array(q), axis)
        assert np.all(np.isfinite(g)) and np.all(g == 0.0)
