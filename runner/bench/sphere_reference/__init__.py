"""Independent reference for the single-body orientation problem (paper sec. 3): the exact optimum E*.

Shared by the tests and the benchmark (runner/bench/). It shares no code with `solver/` (nor
with B-splines): the exact-unit limit of the paper's covariant-interpolation problem (eq. 9 with
lambda -> infinity, or the "normalized" objective) is the *natural Riemannian cubic spline on S^3*
(Noakes, Heinzinger & Paden 1989, "Cubic splines on curved spaces", IMA J. Math. Control Inf. 6;
Crouch & Silva Leite 1995): the path u(t) on the unit sphere S^3 in R^4 that passes through the
keyframes and minimizes

    E(u) = integral_{t_0}^{t_{K-1}} |D u'/dt|^2 dt,      D u'/dt = u'' - u (u''.u) = u'' + |u'|^2 u

(the covariant acceleration: the tangential part of u''). Its Euler-Lagrange equation on each
keyframe interval is D^3 V/dt^3 + R(DV/dt, V) V = 0 with V = u' and, on the unit sphere,
R(X, Y) Z = <Y, Z> X - <X, Z> Y (curvature convention R(X,Y) = [nabla_X, nabla_Y] - nabla_[X,Y]).
At interior keyframes the path is C2 (u, V, A = DV/dt continuous; the covariant jerk jumps, as the
third derivative of a cubic spline does); at both ends A = 0 (natural end conditions).

Two independent computations of E*:

1. `riemannian_cubic_reference` (default): `scipy.integrate.solve_bvp` on that ODE, embedded in R^4
   (see `_rhs` for the derivation), all intervals stacked into one boundary-value problem on s in [0, 1].
2. `discrete_sphere_reference`: a fine discretization - N points per keyframe interval on the sphere,
   minimize sum_g w_g |P(u_g) D2 u_g|^2 (projected second differences, trapezoid weights), free points
   moved by the exponential map so the unit constraint holds exactly (Gauss-Newton/Levenberg-Marquardt
   on a banded system), then Richardson extrapolation in N (the error is O(h^2)).

They agree to ~1e-9 relative on the test sets (measured 5e-10 to 3e-9; tests/runner/bench/test_sphere_reference.py
asserts 1e-6), and both reproduce the exact 1-D answer for keyframes on one great circle.

`covariant_energy` measures E for any densely sampled path, without any of the project's code.

Units: times in seconds, quaternions (w, x, y, z) dimensionless, E in 1/s^3 (rad^2/s^3).
"""

from .bvp import Reference, euler_lagrange_residual, riemannian_cubic_reference
from .discrete import DiscreteReference, discrete_sphere_reference
from .geometry import align, covariant_energy, rotation_angles_deg
from .keyframe_sets import (
    KeyframeSet,
    great_circle_set,
    large_rotation_sets,
    moderate_rotation_set,
    natural_spline_energy_1d,
)

__all__ = [
    "KeyframeSet",
    "Reference",
    "DiscreteReference",
    "align",
    "riemannian_cubic_reference",
    "discrete_sphere_reference",
    "covariant_energy",
    "euler_lagrange_residual",
    "great_circle_set",
    "natural_spline_energy_1d",
    "large_rotation_sets",
    "moderate_rotation_set",
    "rotation_angles_deg",
]
