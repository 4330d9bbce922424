"""The real roots of many quadratics and cubics at once, in closed form (Press et al., Numerical Recipes, 3rd ed.,
2007, sec. 5.6), for the deepest point of a curve in a surface (`solver.constraints.penetration`).

A root is returned where it is real; NaN stands for a missing one. The callers use the roots as candidate points
that they evaluate and compare, so a candidate that is no root costs an evaluation and nothing else; a missed
root would cost a wrong answer, so a cubic with one real root also returns the real part of its complex pair (a
near-double root) and every cubic root is polished by Newton's method on the cubic as given.
"""
from __future__ import annotations

import numpy as np

__all__ = ["cubic_roots", "quadratic_roots"]

#: [1] a cubic whose leading coefficient is below this share of its largest one is solved as the quadratic of its other
#: three (then polished on the whole cubic): dividing by the leading coefficient would scale the rest by over 1e8 and
#: lose the roots near [0, 1] to cancellation; the quadratic's roots are within 1e-8 / |p'| of the cubic's there
QUADRATIC_SHARE = 1e-8
#: [steps] Newton steps that polish each cubic root: closed forms lose digits to cancellation (a root computed as a
#: difference of terms 1e4 times larger keeps 12 digits); two steps from there restore full precision
POLISH_STEPS = 2


def quadratic_roots(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(..., 2) the real roots of a u^2 + b u + c (NaN where there are none; one, -c/b, where a = 0) in the form
    that stays exact as a -> 0 (Numerical Recipes sec. 5.6): q = -(b + sgn(b) sqrt(b^2 - 4ac)) / 2, roots q/a, c/q.

    Args:
        a, b, c: arrays of one shape (...).
    """
    a, b, c = np.broadcast_arrays(*(np.asarray(x, float) for x in (a, b, c)))
    disc = b * b - 4 * a * c
    q = -0.5 * (b + np.where(b >= 0, 1.0, -1.0) * np.sqrt(np.maximum(disc, 0.0)))
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.stack([q / a, c / q], axis=-1)
    r[~np.isfinite(r)] = np.nan
    r[disc < 0] = np.nan
    return r


def cubic_roots(c3: np.ndarray, c2: np.ndarray, c1: np.ndarray, c0: np.ndarray) -> np.ndarray:
    """(..., 3) the real roots of c3 u^3 + c2 u^2 + c1 u + c0, NaN for missing ones (module docstring).

    Three real roots by the trigonometric form, one by Cardano's (Numerical Recipes sec. 5.6), where the second and
    third are the real part of the complex pair; a cubic with c3 below `QUADRATIC_SHARE` of its largest coefficient by
    `quadratic_roots` of the rest. Every root (not the real part of a pair) is then polished by `POLISH_STEPS` Newton
    steps on the cubic as given, a step kept only where it lowers |p|.

    Args:
        c3, c2, c1, c0: arrays of one shape (...).
    """
    c3, c2, c1, c0 = np.broadcast_arrays(*(np.asarray(x, float) for x in (c3, c2, c1, c0)))
    scale = np.maximum(np.maximum(abs(c3), abs(c2)), np.maximum(abs(c1), abs(c0)))
    cubic = abs(c3) > QUADRATIC_SHARE * scale
    lead = np.where(cubic, c3, 1.0)
    a, b, c = c2 / lead, c1 / lead, c0 / lead
    Q, R = (a * a - 3 * b) / 9, (2 * a**3 - 9 * a * b + 27 * c) / 54
    three = R * R < Q**3
    sq = np.sqrt(np.maximum(Q, 0.0))
    theta = np.arccos(np.clip(R / np.where(three, sq**3, 1.0), -1.0, 1.0))
    trig = -2 * sq[..., None] * np.cos((theta[..., None] + np.array([0.0, 2 * np.pi, -2 * np.pi])) / 3)
    A = -np.where(R >= 0, 1.0, -1.0) * np.cbrt(abs(R) + np.sqrt(np.maximum(R * R - Q**3, 0.0)))
    B = np.where(A != 0, Q / np.where(A != 0, A, 1.0), 0.0)
    one = np.stack([A + B, -0.5 * (A + B), -0.5 * (A + B)], axis=-1)
    r = np.where(three[..., None], trig, one) - a[..., None] / 3
    quad = quadratic_roots(c2, c1, c0)
    r = np.where(cubic[..., None], r, np.concatenate([quad, np.full(quad.shape[:-1] + (1,), np.nan)], axis=-1))
    # a complex pair's real part is no root: Newton's method would walk it to the real one
    polish = ~cubic[..., None] | three[..., None] | (np.arange(3) == 0)
    p = [x[..., None] for x in (c3, c2, c1, c0)]
    for _ in range(POLISH_STEPS):
        f = ((p[0] * r + p[1]) * r + p[2]) * r + p[3]
        df = (3 * p[0] * r + 2 * p[1]) * r + p[2]
        with np.errstate(divide="ignore", invalid="ignore"):
            step = r - f / df
            better = abs(((p[0] * step + p[1]) * step + p[2]) * step + p[3]) < abs(f)
        r = np.where(polish & better & np.isfinite(step), step, r)
    return r
