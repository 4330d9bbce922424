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


def angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The geodesic angle 2 acos |<a, b>| [rad] between the rotations of quaternions a and b.

    Args:
        a, b: (..., 4) quaternions (w, x, y, z), each normalized here (q and -q are one rotation).
    Returns:
        (...,) angles in [0, pi].
    """
    d = np.abs(np.sum(normalize(np.asarray(a, float)) * normalize(np.asarray(b, float)), axis=-1))
    return 2.0 * np.arccos(np.clip(d, 0.0, 1.0))


def left_matrix(q: np.ndarray) -> np.ndarray:
    """(..., 4, 4) L(q) with q (x) p = L(q) p (Hamilton product, w first)."""
    w, x, y, z = np.moveaxis(np.asarray(q, float), -1, 0)
    return np.stack([np.stack([w, -x, -y, -z], -1), np.stack([x, w, -z, y], -1),
                     np.stack([y, z, w, -x], -1), np.stack([z, -y, x, w], -1)], -2)


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
        axis: (3,) unit axis in the joint's parent frame (or (..., 3), broadcast against q's vector part).
    Returns:
        (...,) angles in (-2 pi, 2 pi]; in (-pi, pi] for w >= 0.
    """
    return 2.0 * np.arctan2(np.sum(q[..., 1:] * axis, axis=-1), q[..., 0])


def hinge_angle(q: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The twist angle about `axis` of the rotation q stands for, in (-pi, pi] [rad]: `twist_angle` of q taken
    with w >= 0 (q and -q are one rotation; a hemisphere-continuous series of quaternions can reach w < 0, where
    `twist_angle` gives an angle beyond pi: a knee flexed 28 degrees read as -332).

    Args:
        q: (..., 4) quaternions. axis: (3,) unit axis (or (..., 3)).
    Returns:
        (...,) angles [rad]."""
    q = np.asarray(q, float)
    return twist_angle(q * np.where(q[..., :1] < 0, -1.0, 1.0), axis)


def twist_angle_grad(q: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Gradient of `twist_angle(q, axis)` with respect to the 4 components of q.

    Args:
        q: (..., 4) quaternions; axis: (3,) unit vector (or (..., 3), broadcast).
    Returns:
        (..., 4) d theta / d q.
    """
    s = np.sum(q[..., 1:] * axis, axis=-1)
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


def swing_twist(q: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Swing-twist decomposition q = s t about a unit `axis`: t rotates about `axis`, s about an axis
    normal to it (Dobrowolski, "Swing-twist decomposition in Clifford algebra", arXiv:1506.05481, 2015).

    With q = (w, v) and p = v . axis: t = (w, p axis) / sqrt(w^2 + p^2) (unit) and s = q conj(t) =
    (w^2 + p^2, w v_perp - p v x axis) / sqrt(w^2 + p^2), v_perp = v - p axis, so |s| = |q|.

    Args:
        q: (..., 4) quaternions (any norm). axis: (..., 3) unit axes (broadcast against q's vector
            part), in the frame of q's vector part.
    Returns:
        (swing (..., 4) with |swing| = |q|, twist (..., 4) unit). Where w = p = 0 (a half turn about an
        axis normal to `axis`) the twist is undefined: NaN there.
    """
    w, v = q[..., 0], q[..., 1:]
    p = np.sum(v * axis, axis=-1)
    n = np.sqrt(w * w + p * p)
    with np.errstate(invalid="ignore", divide="ignore"):
        twist = np.concatenate([(w / n)[..., None], (p / n)[..., None] * axis], axis=-1)
        v_perp = v - p[..., None] * axis
        sv = (w[..., None] * v_perp - p[..., None] * np.cross(v, axis)) / n[..., None]
    return np.concatenate([n[..., None], sv], axis=-1), twist


def swing_angle(q: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Angle [rad] of the swing of q about a unit `axis` (`swing_twist`): how far q turns `axis` itself.

    phi = 2 atan2(|v_perp|, sqrt(w^2 + p^2)) with p = v . axis, v_perp = v - p axis (|swing| = |q| and
    the swing's scalar part is sqrt(w^2 + p^2)). Scale- and sign-invariant (q and -q give the same).

    Args:
        q: (..., 4) quaternions. axis: (..., 3) unit vectors (broadcast).
    Returns:
        (...,) angles in [0, pi]; 0 for a rotation about `axis` alone.
    """
    w, v = q[..., 0], q[..., 1:]
    p = np.sum(v * axis, axis=-1)
    m = np.linalg.norm(v - p[..., None] * axis, axis=-1)
    return 2.0 * np.arctan2(m, np.sqrt(w * w + p * p))


def swing_angle_grad(q: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Gradient of `swing_angle(q, axis)` with respect to the 4 components of q.

    With m = |v_perp|, n = sqrt(w^2 + p^2), |q|^2 = m^2 + n^2: d phi = 2 (n dm - m dn) / |q|^2,
    dm/dv = v_perp / m, dn/dw = w / n, dn/dv = p axis / n.

    Args:
        q: (..., 4) quaternions; axis: (..., 3) unit vectors (broadcast).
    Returns:
        (..., 4) d phi / d q; 0 where phi is not differentiable (m = 0: no swing, the apex of the cone
        phi = |swing|; n = 0: a half-turn swing).
    """
    w, v = q[..., 0], q[..., 1:]
    p = np.sum(v * axis, axis=-1)
    v_perp = v - p[..., None] * axis
    m = np.linalg.norm(v_perp, axis=-1)
    n = np.sqrt(w * w + p * p)
    r2 = m * m + n * n
    ok = (m > 1e-12 * np.sqrt(r2)) & (n > 1e-12 * np.sqrt(r2))
    m_, n_, r2_ = (np.where(ok, x, 1.0) for x in (m, n, r2))
    g = np.zeros(q.shape)
    g[..., 0] = np.where(ok, -2.0 * m_ * w / (n_ * r2_), 0.0)
    g[..., 1:] = np.where(ok, 2.0 / r2_, 0.0)[..., None] * (
        (n_ / m_)[..., None] * v_perp - (m_ * p / n_)[..., None] * axis)
    return g


def swing_about(q: np.ndarray, axis: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Signed swing of q about a unit direction `e` normal to the twist `axis` [rad]: 2 atan2(s_v . e, s_w)
    of the swing s of `swing_twist` (a swing of angle a about e gives a; a swing about another direction
    u normal to `axis` gives about a (u . e) for small a, the component a clinical goniometer reads in
    the plane normal to e).

    2 atan2(N, D) with N = w (v . e) - (v . axis)(v . (axis x e)), D = w^2 + (v . axis)^2 (both
    quadratic in q, so scale- and sign-invariant).

    Args:
        q: (..., 4) quaternions. axis, e: (..., 3) unit vectors (broadcast), axis . e = 0.
    Returns:
        (...,) angles in [-pi, pi].
    """
    N, D = _swing_about_parts(q, axis, e)
    return 2.0 * np.arctan2(N, D)


def _swing_about_parts(q, axis, e):
    w, v = q[..., 0], q[..., 1:]
    p = np.sum(v * axis, axis=-1)
    return w * np.sum(v * e, axis=-1) - p * np.sum(v * np.cross(axis, e), axis=-1), w * w + p * p


def swing_about_grad(q: np.ndarray, axis: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Gradient of `swing_about(q, axis, e)` with respect to the 4 components of q.

    d alpha = 2 (D dN - N dD) / (N^2 + D^2); dN/dw = v . e, dN/dv = w e - (v . b) axis - (v . axis) b
    (b = axis x e), dD/dw = 2 w, dD/dv = 2 (v . axis) axis.

    Args:
        q: (..., 4) quaternions; axis, e: (..., 3) unit vectors (broadcast), axis . e = 0.
    Returns:
        (..., 4) d alpha / d q; 0 where N = D = 0 (a half-turn swing: alpha undefined).
    """
    w, v = q[..., 0], q[..., 1:]
    b = np.cross(axis, e)
    p, ve, vb = (np.sum(v * u, axis=-1) for u in (axis, e, b))
    N, D = w * ve - p * vb, w * w + p * p
    den = N * N + D * D
    ok = den > 1e-24 * np.sum(q * q, axis=-1) ** 2
    c = np.where(ok, 2.0 / np.where(ok, den, 1.0), 0.0)
    g = np.empty(q.shape)
    g[..., 0] = c * (D * ve - N * 2.0 * w)
    dN = w[..., None] * e - vb[..., None] * axis - p[..., None] * b
    g[..., 1:] = c[..., None] * (D[..., None] * dN - (N * 2.0 * p)[..., None] * axis)
    return g
