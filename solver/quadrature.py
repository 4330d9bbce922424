"""Quadrature rules on a spline's time span: the paper's uniform midpoint rule, Simpson's rule and
Gauss-Legendre per spline segment. Each returns the points t [s] and their weights [s]; an integral is sum(w * f(t))."""
from __future__ import annotations

import numpy as np

#: [nodes per segment] Default Gauss quadrature (`Objective.points`, `solver.paper.orient`): Gauss-Legendre
#: with GAUSS_POINTS nodes on every spline segment. The integrand is smooth inside a segment (the spline is
#: one cubic there), so 4 nodes per segment integrate it to ~1e-6 relative on the default frames of the
#: test sets (1e-9 with 5 frames per keyframe interval), where the paper's uniform rule needed 80-120
#: points per second for a gap of 1e-4; 3 nodes change the default result (docs/orient.md). Every
#: segment, however short, has its own nodes.
GAUSS_POINTS = 4

#: [points] Largest quadrature (points on the keyframe interval) a problem accepts: the spline matrices are
#: points x frames, so a clip minutes long at the default rate, or keyframe times in frames instead of
#: seconds, would exhaust memory instead of failing clearly.
MAX_QUADRATURE_POINTS = 100_000


def check_points(t0: float, t1: float, rate: float) -> None:
    """Raise InputError when [t0, t1] at `rate` points per second needs more than MAX_QUADRATURE_POINTS.

    Args:
        t0, t1: the keyframe interval [s]. rate: quadrature points per second [1/s].
    Raises:
        InputError: too many points (names the span, the rate and the fix).
    """
    from solver.errors import InputError

    n = (t1 - t0) * rate
    if n > MAX_QUADRATURE_POINTS:
        raise InputError(
            f"the keyframes span {t1 - t0:g} s; at {rate:g} quadrature points per second that is {n:.3g} "
            f"points (at most {MAX_QUADRATURE_POINTS}); check the keyframe times (seconds, not frames) or "
            "lower the rate (--rate)")


def quadrature_times(t0: float, t1: float, rate: float) -> tuple[np.ndarray, float]:
    """Uniform midpoint quadrature on [t0, t1] (paper, after eq. 7: "summing the values of the
    integrand at uniformly distributed points and multiplying by the time interval each represents").

    Args:
        t0, t1: interval [s]. rate: points per second [1/s].
    Returns:
        t: (n,) points [s], n = ceil((t1 - t0) * rate); h: weight of each point [s].
    """
    n = max(2, int(np.ceil((t1 - t0) * rate)))
    h = (t1 - t0) / n
    return t0 + h * (np.arange(n) + 0.5), h


def quadrature_points(t0: float, t1: float, rate: float, knots=()) -> tuple[np.ndarray, np.ndarray]:
    """The uniform midpoint rule (`quadrature_times`, weight h each) with the spline's fixed knots added as
    points of weight 0: every integral is the midpoint rule's, and every pointwise bound is also checked
    at the knots.

    A cubic spline's acceleration is linear in time on each segment, so its extremes are at the knots,
    which the midpoint rule never samples (they sit half an interval off its points): a bound on
    acceleration (no jolts) holds between the points of a segment only if it holds at the segment's ends.
    The knots known when a problem is built (keyframes, pins, the span's ends) are points here; variable
    frames added later are put on points (`solver.feasibility.on_points`).

    Args:
        t0, t1: interval [s]. rate: points per second [1/s]. knots: (k,) [s] times in [t0, t1].
    Returns:
        t: (n + k',) points [s], increasing; w: same shape, weights [s] (h, or 0 at a knot). A knot within
        round-off (1e-9 s) of a midpoint is that point.
    """
    t, h = quadrature_times(t0, t1, rate)
    k = np.asarray(knots, float).ravel()
    k = k[(k >= t0) & (k <= t1)]
    # [s] a knot within round-off of a midpoint (times are sums of float steps) is that midpoint
    if k.size and t.size:
        i = np.clip(np.searchsorted(t, k), 1, len(t) - 1)
        k = k[np.minimum(np.abs(t[i - 1] - k), np.abs(t[i] - k)) > 1e-9]
    k = np.unique(k)
    allt = np.concatenate([t, k])
    order = np.argsort(allt, kind="stable")
    return allt[order], np.concatenate([np.full(len(t), h), np.zeros(len(k))])[order]


def simpson_points(frames: np.ndarray, panels: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Simpson's rule on every interval between consecutive frames, composite over `panels` equal panels: each
    panel's ends and midpoint, weights h/6 at each end (a point between two panels gathers both) and 4h/6 at the
    midpoint, h the panel's length.

    Exact for a cubic on each interval (Burden & Faires, Numerical Analysis, 9th ed., sec. 4.3-4.4); a natural
    cubic spline through the frames has its acceleration linear there, so the integral of a squared
    acceleration under a constant metric is exact, and the frames, where a spline's acceleration peaks,
    are points (a pointwise bound on acceleration checked there holds between them). The rule of a clean
    (`solver.displacement`), whose path is such a spline with a knot at every capture frame; more panels where
    the cubic between two points does not follow a contact site there (`solver.displacement.frame_panels`).

    Args:
        frames: (m,) strictly increasing frame times [s], m >= 2. panels: (m - 1,) panels of each interval,
            each >= 1 (None: one each).
    Returns:
        t: (2 sum(panels) + 1,) points [s], the frames among them (at 2 cumsum(panels) from 0); w: same shape,
        weights [s] summing to the span.
    Raises:
        InputError: more than MAX_QUADRATURE_POINTS points (names the frames and the fix).
    """
    from solver.errors import InputError

    x = np.asarray(frames, float)
    k = np.ones(len(x) - 1, int) if panels is None else np.asarray(panels, int)
    n = 2 * int(k.sum()) + 1
    if n > MAX_QUADRATURE_POINTS:
        raise InputError(f"{len(x)} frames need {n} quadrature points by Simpson's rule (at most "
                         f"{MAX_QUADRATURE_POINTS}); split the clip and clean it in parts")
    seg = np.repeat(np.arange(len(k)), 2 * k)  # the interval of each point but the last
    step = np.arange(len(seg)) - np.repeat(2 * np.r_[0, np.cumsum(k)[:-1]], 2 * k)  # its half-panel within it
    h = np.diff(x)[seg] / (2 * k[seg])  # [s] half a panel
    t = np.r_[x[seg] + step * h, x[-1]]
    t[np.r_[0, 2 * np.cumsum(k)]] = x  # the frames exactly, not sums of steps
    w = np.zeros(n)
    mid = step % 2 == 1
    w[:-1][mid] = 4.0 * 2.0 * h[mid] / 6.0
    ends = np.flatnonzero(~mid)  # a panel starts at each even half-step
    w[ends] += 2.0 * h[ends] / 6.0
    w[ends + 2] += 2.0 * h[ends] / 6.0
    return t, w


def gauss_times(knots: np.ndarray, points: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre quadrature with `points` nodes on every spline segment.

    Inside a segment the spline is one cubic, so an integrand that is a smooth function of Y, Y', Y''
    is smooth there and the rule converges fast (error ~ h^(2 points)); the knots, where the third
    derivative jumps, are segment ends, not nodes. Used by `Objective(quadrature="gauss")`.

    Args:
        knots: (m,) frame times [s], strictly increasing. points: nodes per segment, >= 1.
    Returns:
        t: ((m-1) * points,) nodes [s], increasing; w: same shape, weights [s] (they sum to the span).
    """
    x = np.asarray(knots, dtype=float)
    xg, wg = gauss_nodes(points)
    h = np.diff(x)
    t = (x[:-1, None] + h[:, None] * xg[None, :]).ravel()
    return t, (h[:, None] * wg[None, :]).ravel()


_GAUSS_NODES: dict[int, tuple[np.ndarray, np.ndarray]] = {}


def gauss_nodes(points: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights on [0, 1], each (points,) (cached: numpy's leggauss costs
    ~0.2 ms a call)."""
    r = _GAUSS_NODES.get(points)
    if r is None:
        xg, wg = np.polynomial.legendre.leggauss(points)
        r = _GAUSS_NODES[points] = (0.5 * (xg + 1.0), 0.5 * wg)
    return r


for _p in (4, 8):  # the rules orient uses (objective, summary energy): a table built at import
    gauss_nodes(_p)
del _p
