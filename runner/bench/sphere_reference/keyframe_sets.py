"""The keyframe sets of the tests and the benchmark, and the exact 1-D answer for a great circle."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline

from .geometry import align, qmul

# ----------------------------------------------------------------------------------------------------
# keyframe sets


@dataclass(frozen=True)
class KeyframeSet:
    """A named test keyframe set: times (K,) [s], quats (K, 4) unit, hemisphere-aligned (w x y z)."""

    name: str
    times: np.ndarray
    quats: np.ndarray


def _random_walk(rng, K, lo_deg, hi_deg):
    q = [np.array([1.0, 0.0, 0.0, 0.0])]
    q0 = rng.normal(size=4)
    q[0] = q0 / np.linalg.norm(q0)
    for _ in range(K - 1):
        ax = rng.normal(size=3)
        ax /= np.linalg.norm(ax)
        ang = np.radians(rng.uniform(lo_deg, hi_deg))
        dq = np.concatenate([[np.cos(ang / 2)], np.sin(ang / 2) * ax])
        q.append(qmul(q[-1], dq))
    return align(np.array(q))


def large_rotation_sets() -> list[KeyframeSet]:
    """Three 7-keyframe sets with 30 to 150 degrees of rotation between consecutive keyframes.

    Rotation angle between keyframes = 2 arccos |q_i . q_{i+1}| (`rotation_angles_deg`). Deterministic
    (numpy default_rng seeds 1, 2, 3): 'large_uniform' (times 0..6 s, 1 s apart), 'large_nonuniform'
    (steps 0.4 to 1.6 s), 'large_nonuniform_b' (another seed, steps 0.5 to 2 s).
    """
    out = []
    rng = np.random.default_rng(1)
    out.append(KeyframeSet("large_uniform", np.arange(7, dtype=float), _random_walk(rng, 7, 30, 150)))
    rng = np.random.default_rng(2)
    q = _random_walk(rng, 7, 30, 150)
    times = np.concatenate([[0.0], np.cumsum(rng.uniform(0.4, 1.6, 6))])
    out.append(KeyframeSet("large_nonuniform", times, q))
    rng = np.random.default_rng(3)
    q = _random_walk(rng, 7, 30, 150)
    times = np.concatenate([[0.0], np.cumsum(rng.uniform(0.5, 2.0, 6))])
    out.append(KeyframeSet("large_nonuniform_b", times, q))
    return out


def moderate_rotation_set() -> KeyframeSet:
    """A 7-keyframe set with 15 to 60 degrees between consecutive keyframes, times 0.6 to 1.4 s apart
    (numpy default_rng seed 4)."""
    rng = np.random.default_rng(4)
    q = _random_walk(rng, 7, 15, 60)
    times = np.concatenate([[0.0], np.cumsum(rng.uniform(0.6, 1.4, 6))])
    return KeyframeSet("moderate", times, q)


def great_circle_set(times: np.ndarray, thetas: np.ndarray, seed: int = 5):
    """Keyframes on one great circle: q_i = cos(theta_i) a + sin(theta_i) b, a, b orthonormal in R^4.

    The great circle is flat (isometric to a line), so the optimum is the natural cubic spline in theta
    through (t_i, theta_i): E* = `natural_spline_energy_1d(times, thetas)`. theta steps must be < pi/2
    so that the hemisphere alignment keeps the keyframes as given.
    Returns (times (K,), quats (K, 4)).
    """
    rng = np.random.default_rng(seed)
    a, b = np.linalg.qr(rng.normal(size=(4, 2)))[0].T
    th = np.asarray(thetas, dtype=float)
    return np.asarray(times, dtype=float), np.cos(th)[:, None] * a + np.sin(th)[:, None] * b


def natural_spline_energy_1d(times: np.ndarray, values: np.ndarray) -> float:
    """integral theta''^2 dt of the natural cubic spline through (t_i, theta_i) - exact (theta'' linear).

    Per interval with end second derivatives m0, m1 and length h: h (m0^2 + m0 m1 + m1^2) / 3.
    """
    cs = CubicSpline(np.asarray(times, float), np.asarray(values, float), bc_type="natural")
    t = np.asarray(times, float)
    m = cs(t, 2)
    h = np.diff(t)
    return float(np.sum(h * (m[:-1] ** 2 + m[:-1] * m[1:] + m[1:] ** 2) / 3.0))
