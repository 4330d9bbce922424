"""The rotation variables' chain rule (`solver.manifold.exp_rotation_vjp`) against central differences of
`exp_rotation`, on both sides of the series' switch at |delta| = 1e-4 rad."""
import numpy as np
import pytest

from solver.manifold import exp_rotation, exp_rotation_vjp


@pytest.mark.parametrize("scale", [1e-7, 5e-5, 2e-4, 0.3, 2.5])
def test_vjp_matches_central_differences(scale):
    rng = np.random.default_rng(11)
    delta = rng.normal(size=(40, 3)) * scale
    h = rng.normal(size=(40, 4))
    eps = 1e-6
    fd = np.stack([(exp_rotation(delta + eps * e) - exp_rotation(delta - eps * e)) / (2 * eps) for e in np.eye(3)], -1)
    expected = np.einsum("ri,rik->rk", h, fd)  # (r, 3): the (4, 3) Jacobian's columns weighted by h
    # central differences' error: eps^2 |exp'''| / 6 ~ 1e-13, and rounding 1e-16 / eps ~ 1e-10
    np.testing.assert_allclose(exp_rotation_vjp(delta, h), expected, atol=1e-9)
