"""D's preconditioner on a grid in banded form (solver.grid_preconditioner), against references built another way:

* S S^T is the inverse of D/D0's time-averaged Gauss-Newton Hessian over the free frame values, that Hessian
  built directly from the spline's dense Gram matrices (`SplineBasis.gram`) and Kronecker products, with and
  without fixed frames (a clean's pins), and so equals `solver.lagrangian.Preconditioner`'s R^-1 R^-T;
* `apply_transpose` is `apply`'s transpose;
* the coefficients' Gram band is the frame values' Gram matrix through the map from values to coefficients;
* the null space of the spline's constraints is one (B N = 0, N of full rank) with an identity on the rest.
"""
import numpy as np
import pytest

from solver.displacement import build_displacement
from solver.frames import FrameSet
from solver.grid_preconditioner import BandedPreconditioner, grid_maps, null_space
from solver.lagrangian import Preconditioner, _variable_dofs, frame_maps
from solver.least_change import _start_frames
from solver.manifold import FrameVariables
from solver.quadrature import simpson_points
from solver.spline_basis import SplineBasis
from solver.spline_coefficients import SplineCoefficients
from tests.solver.test_displacement import _capture

#: [s] the hand-made capture's frame times kept: a short clip, so that the dense Hessian is small
SHORT = 0.4


def _clean(model, pins=(), pin_ends=False):
    """(LeastChange, its start frames: a frame at every capture frame) of the toy's capture cut to SHORT s."""
    t, q = _capture(model)
    keep = t <= SHORT + 1e-9
    lc = build_displacement(model, t[keep], q[keep], pins=pins, pin_ends=pin_ends).lc
    return lc, _start_frames(lc, 1.0 / 48.0)


def _hessian(lc, frames, var):
    """D/D0's time-averaged Gauss-Newton Hessian over the free values, in x's order, built directly:
    (2 / D0) (W2^T diag(w) W2 (x) Mbar + omega^4 W^T diag(w) W (x) Pbar) on the free frames and the dofs."""
    ch, basis = lc.al.change, SplineBasis(frames.times, lc.al.t)
    w = ch.ref.weights
    K2, K0 = basis.gram(2, w) * (2.0 / lc.al.d0), ch.omega ** 4 * basis.gram(0, w) * (2.0 / lc.al.d0)
    fr, dof = _variable_dofs(var, lc.al.tmap)
    H = np.zeros((var.size, var.size))
    for i in range(var.size):  # entry by entry: K (x) M in x's own order
        H[i] = K2[fr[i], fr] * ch.mbar[dof[i], dof] + K0[fr[i], fr] * ch.pbar[dof[i], dof]
    return H


def _product(pre, n):
    """(n, n) S S^T, column by column."""
    return np.stack([pre.apply(pre.apply_transpose(e)) for e in np.eye(n)], axis=1)


@pytest.mark.parametrize("pins, pin_ends", [((), False), ((0.2,), True)])
def test_s_s_transpose_is_the_inverse_hessian(toy_model, pins, pin_ends):
    lc, frames = _clean(toy_model, pins, pin_ends)
    var = FrameVariables(frames, lc.layout.quat_slots)
    H = _hessian(lc, frames, var)
    basis, pre = grid_maps(lc.al, frames, lc.layout.quat_slots)
    assert pre.size == var.size and (frames.is_keyframe.sum() == 3 if pins else not frames.is_keyframe.any())
    SS = _product(pre, var.size)
    np.testing.assert_allclose(SS @ H, np.eye(var.size), atol=1e-7)
    dense = Preconditioner(var, basis, lc.al.change, lc.al.tmap, lc.al.d0)
    np.testing.assert_allclose(SS, _product(dense, var.size), rtol=1e-7, atol=1e-9 * np.abs(SS).max())


def test_apply_transpose_is_apply_s_transpose(toy_model):
    lc, frames = _clean(toy_model, (0.1,))
    _, pre = grid_maps(lc.al, frames, lc.layout.quat_slots)
    rng = np.random.default_rng(3)
    u, v = rng.normal(size=pre.size), rng.normal(size=pre.size)
    assert pre.apply(u) @ v == pytest.approx(u @ pre.apply_transpose(v), rel=1e-12)


def test_a_partial_keyframe_is_refused(toy_model):
    lc, frames = _clean(toy_model)
    fixed = frames.fixed.copy()
    fixed[3, :3] = True  # the root's position held at one frame, its orientation and the joints free
    partial = FrameSet(frames.times, frames.values, fixed, frames.is_keyframe)
    var = FrameVariables(partial, lc.layout.quat_slots)
    basis = SplineBasis(partial.times, lc.al.t)
    with pytest.raises(ValueError, match="not all free at the same frames"):
        BandedPreconditioner(var, basis, lc.al.change, lc.al.tmap, lc.al.d0)
    frame_maps(lc.al, partial, lc.layout.quat_slots)  # the dense preconditioner takes it


@pytest.mark.parametrize("r", [0, 2])
def test_the_gram_band_is_the_frame_values_gram_through_the_coefficients(r):
    rng = np.random.default_rng(r)
    x = np.cumsum(rng.uniform(0.005, 0.02, 30))
    t, w = simpson_points(x)
    co = SplineCoefficients(x, t)
    band = co.gram_band(r, w)
    G = np.zeros((co.size, co.size))
    for d in range(4):
        idx = np.arange(co.size - d)
        G[idx + d, idx] = G[idx, idx + d] = band[d, : co.size - d]
    T = np.linalg.solve(np.vstack([co.at_frames.toarray(), co.ends]), np.vstack([np.eye(len(x)), np.zeros((2, len(x)))]))
    K = SplineBasis(x, t).gram(r, w)
    np.testing.assert_allclose(T.T @ G @ T, K, rtol=1e-10, atol=1e-12 * np.abs(K).max())


def test_null_space_of_the_ends_and_fixed_frames():
    x = np.linspace(0.0, 1.0, 12)
    co = SplineCoefficients(x, np.linspace(0.0, 1.0, 50))
    B = np.vstack([co.ends, co.at_frames[[0, 5, 6, 11]].toarray()])  # adjacent fixed frames and both ends
    N = null_space(B).toarray()
    assert N.shape == (co.size, co.size - len(B)) and np.linalg.matrix_rank(N) == N.shape[1]
    np.testing.assert_allclose(B @ N, 0.0, atol=1e-12)
    with pytest.raises(ValueError, match="not independent"):
        null_space(np.vstack([B, B[2]]))
