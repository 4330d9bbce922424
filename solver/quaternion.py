"""Quaternion helpers on arrays, scalar-first (w, x, y, z) as in MuJoCo.

All functions broadcast over leading axes: a quaternion array has shape (..., 4).
Quaternions in the spline are *not* unit (docs/design.md, "State = MuJoCo qpos"); the functions say
whether they expect unit input.
"""
from __future__ import annotations

import numpy as np


def mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a * b.

    Args:
        a, b: (..., 4) quaternions (w, x, y, z); broadcast against each other.
    Returns:
        (..., 4) product.
    """
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def conj(q: np.ndarray) -> np.ndarray:
    """Conjugate (w, -x, -y, -z) of (..., 4) quaternions."""
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def normalize(q: np.ndarray) -> np.ndarray:
    """q / |q| for (..., 4) quaternions. Raises nothing; a zero quaternion gives NaN."""
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def vec_of_conj_product(q: np.ndarray) -> np.ndarray:
    """The 3x4 matrix G(q) with G(q) p = vec(conj(q) p) for any quaternion p.

    For unit q and a derivative p = q', 2 G(q) q' is the body-frame angular velocity (MuJoCo's
    ball-joint `qvel`); 2 G(q) q'' - with q' . q' terms dropped - the angular acceleration. G(q) q = 0,
    so G(q) already removes the radial (scale) component.

    Args:
        q: (..., 4) quaternions.
    Returns:
        (..., 3, 4) matrices [ -v | w I - [v]x ], v = (x, y, z).
    """
    w, x, y, z = np.moveaxis(q, -1, 0)
    rows = [
        [-x, w, z, -y],
        [-y, -z, w, x],
        [-z, y, -x, w],
    ]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def align_hemispheres(quats: np.ndarray) -> np.ndarray:
    """Flip quaternions so that each is in the hemisphere of the previous one (q or -q).

    q and -q are the same rotation; interpolating between q_i and q_{i+1} with q_i . q_{i+1} < 0
    takes the long way round (docs/design.md). The first quaternion is kept.

    Args:
        quats: (k, 4) quaternions in time order.
    Returns:
        (k, 4) copy with signs chosen so that consecutive dot products are >= 0.
    """
    out = np.array(quats, dtype=float, copy=True)
    for i in range(1, len(out)):
        if np.dot(out[i], out[i - 1]) < 0.0:
            out[i] = -out[i]
    return out


def twist_angle(q: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Signed rotation angle about a unit `axis` (swing-twist decomposition), in radians.

    theta = 2 atan2(v . axis, w). Scale-invariant, so unnormalized q is fine.

    Args:
        q: (..., 4) quaternions.
        axis: (3,) unit axis in the joint's parent frame.
    Returns:
        (...,) angles in (-2 pi, 2 pi]; in (-pi, pi] for w >= 0.
    """
    return 2.0 * np.arctan2(q[..., 1:] @ axis, q[..., 0])


def twist_angle_grad(q: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Gradient of `twist_angle(q, axis)` with respect to the 4 components of q.

    Args:
        q: (..., 4) quaternions; axis: (3,) unit vector.
    Returns:
        (..., 4) d theta / d q.
    """
    s = q[..., 1:] @ axis
    w = q[..., 0]
    den = w * w + s * s
    # where w and the twist component both vanish (a half turn about an axis normal to `axis`, or
    # components so small that their squares underflow) the twist angle is undefined: gradient 0 there
    ok = den > 1e-24 * np.sum(q * q, axis=-1)
    safe = np.where(ok, den, 1.0)
    g = np.zeros(q.shape)
    g[..., 0] = np.where(ok, -2.0 * s / safe, 0.0)
    g[..., 1:] = np.where(ok, 2.0 * w / safe, 0.0)[..., None] * axis
    return g
