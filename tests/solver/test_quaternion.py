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


def test_angle_between_is_the_relative_rotations_angle_for_either_sign_and_any_norm():
    """angle_between(a, b) against scipy's magnitude of the relative rotation a^-1 b, at random rotations; q and -q
    are one rotation, and a quaternion's norm does not matter (both are normalized)."""
    from scipy.spatial.transform import Rotation

    from solver.quaternion import angle_between

    rng = np.random.default_rng(3)
    ra, rb = Rotation.random(50, random_state=4), Rotation.random(50, random_state=5)
    a, b = np.roll(ra.as_quat(), 1, axis=1), np.roll(rb.as_quat(), 1, axis=1)  # scipy's (x, y, z, w) -> (w, x, y, z)
    expected = (ra.inv() * rb).magnitude()
    np.testing.assert_allclose(angle_between(a, b), expected, atol=1e-7)  # acos near 0 loses half the digits
    scale = rng.uniform(0.5, 2.0, size=(50, 1))
    np.testing.assert_allclose(angle_between(-scale * a, b), expected, atol=1e-7)
    assert np.all(angle_between(a, -a) < 1e-7)
