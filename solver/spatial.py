"""Small products on component-first arrays (a vector array is (3, ...), a matrix array (3, 3, ...)) for
the vectorized Newton-Euler passes (`solver.inverse_dynamics`): cross
products, rotation matrices times vectors, quaternion products and the quaternion's left-product
matrix, each over a leading batch axis (n, ...)."""
from __future__ import annotations

import numpy as np


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b for (3, ...) arrays (written into one output array: fewer temporaries than np.stack)."""
    o = np.empty(np.broadcast_shapes(a.shape, b.shape))
    np.multiply(a[1], b[2], out=o[0])
    o[0] -= a[2] * b[1]
    np.multiply(a[2], b[0], out=o[1])
    o[1] -= a[0] * b[2]
    np.multiply(a[0], b[1], out=o[2])
    o[2] -= a[1] * b[0]
    return o


def mv(R: np.ndarray, x: np.ndarray) -> np.ndarray:
    """R x for (3, 3, ...) R and (3, ...) x."""
    return R[:, 0] * x[0] + R[:, 1] * x[1] + R[:, 2] * x[2]


def mtv(R: np.ndarray, x: np.ndarray) -> np.ndarray:
    """R^T x for (3, 3, ...) R and (3, ...) x."""
    return R[0] * x[0] + R[1] * x[1] + R[2] * x[2]


def qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (4, ...) quaternions (w, x, y, z)."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ]
    )


def qmat(q: np.ndarray) -> np.ndarray:
    """(3, 3, ...) rotation matrices of (4, ...) unit quaternions."""
    w, x, y, z = q
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz, wx, wy, wz = x * y, x * z, y * z, w * x, w * y, w * z
    return np.stack(
        [
            np.stack([1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy)]),
            np.stack([2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx)]),
            np.stack([2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy)]),
        ]
    )
