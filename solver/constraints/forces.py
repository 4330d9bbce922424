"""The force bounds (`--terms all`): the external wrench a motion needs is one the ground or the air can give.

The contact-free inverse dynamics of the path (`solver.inverse_dynamics`, MuJoCo's `mj_inverse` without
contacts; paper appendix A eq. 18-21) gives at every point the free root's generalized force: the world
force F [N] and the torque T [N m] about the root body's origin, in its frame. That is the external
wrench besides gravity the motion needs, and only the contacts can supply it (Newton-Euler for the
whole body; Featherstone 2008, sec. 9.4 on floating bases). With W = m g the body weight [N]:

    in flight (every site clear)   |F| <= 0,  |T| <= 0          the body flies ballistically
    on the ground                  -F_z <= 0                     the ground pushes, never pulls
                                   |F_xy| - mu F_z <= 0          inside the Coulomb friction cone
                                   |F| <= B (with a capture)     no harder than the capture's filtered peak

Each norm is smoothed as sqrt(|v|^2 + delta^2) - delta with delta the constraint's own tolerance, so
the smoothing moves a bound by less than the tolerance and the constraint is differentiable at v = 0.
The cone is about the vertical: the supports are floors, steps and platforms (`runner.capture.scene_fit`).
B is the larger of the plain spline's and the filtered capture's peak ground force
(`solver.peak_bounds`); as with the no-jolt bounds, the plain spline's peak alone is no bound.
"""
from __future__ import annotations

import numpy as np

from solver.constraints.base import RELATIVE_TOLERANCE, Constraint

__all__ = ["FORCE_TOLERANCE", "FRICTION", "FlightWrench", "GroundForce", "figure_forces"]

#: [body weights] each force bound's tolerance: 1 %, 7 N for 70 kg, about the air drag on a body
#: running at 5 m/s (1/2 rho C_d A v^2 = 0.5 * 1.2 * 1.0 * 0.5 m^2 * 25 = 7.5 N)
FORCE_TOLERANCE = 0.01
#: [1] static friction coefficient of a shoe on a floor: 0.8, inside the 0.5-1.0 measured for footwear on
#: dry floors (Chang et al. 2001, "The role of friction in the measurement of slipperiness", Ergonomics 44)
FRICTION = 0.8


def _smooth_norm(v: np.ndarray, delta: float) -> tuple[np.ndarray, np.ndarray]:
    """sqrt(|v|^2 + delta^2) - delta (n,) and its gradient (n, d) for v (n, d)."""
    r = np.sqrt((v * v).sum(-1) + delta * delta)
    return r - delta, v / r[:, None]


class FlightWrench(Constraint):
    """In flight, no external wrench: |F| <= 0 [N] and |T| <= 0 [N m] at the flight's points.

    Args:
        rows: (p,) quadrature points in flight. root: the free root's first qvel index. weight: W [N].
        arm: l [m], the figure's radius of gyration: the torque's tolerance is W * FORCE_TOLERANCE * l.
    """

    name, unit, scale = "flight wrench", "N | N m", 1.0

    def __init__(self, rows: np.ndarray, root: int, weight: float, arm: float):
        p = len(rows)
        self.rows = np.repeat(np.asarray(rows, int), 2)
        self.labels = np.array(["root force", "root torque"] * p, object)
        tol = FORCE_TOLERANCE * weight
        self.tolerance = np.tile([tol, tol * arm], p)
        self.limit = np.zeros(2 * p)
        self.root = root

    def measure(self, state):
        tau = state.tau[self.rows[::2]]
        f, _ = _smooth_norm(tau[:, self.root:self.root + 3], self.tolerance[0])
        t, _ = _smooth_norm(tau[:, self.root + 3:self.root + 6], self.tolerance[1])
        return np.column_stack([f, t]).ravel()

    def pull(self, state, g):
        g = g.reshape(-1, 2)
        if not g.any():
            return
        rows = self.rows[::2]
        tau = state.tau[rows]
        _, df = _smooth_norm(tau[:, self.root:self.root + 3], self.tolerance[0])
        _, dt = _smooth_norm(tau[:, self.root + 3:self.root + 6], self.tolerance[1])
        gt = np.zeros(state.tau.shape)
        np.add.at(gt, (rows, slice(self.root, self.root + 3)), g[:, :1] * df)
        np.add.at(gt, (rows, slice(self.root + 3, self.root + 6)), g[:, 1:] * dt)
        state.add_tau(gt)


class GroundForce(Constraint):
    """On the ground, a force the ground can give: pushing, inside the friction cone, under the peak bound.

    Three rows per point: -F_z <= 0, |F_xy| - mu F_z <= 0, and (with a bound B) |F| - B <= 0 [N].

    Args:
        rows: (p,) quadrature points on the ground. root: the free root's first qvel index. weight: W [N].
        up: (3,) the unit vertical (against gravity). bound: B [N], or None: no peak bound.
    """

    name, unit, scale = "ground force", "N", 1.0

    def __init__(self, rows: np.ndarray, root: int, weight: float, up: np.ndarray, bound: float | None = None):
        self.kinds = ("pull", "friction") + (("peak",) if bound is not None else ())
        k = len(self.kinds)
        p = len(rows)
        self.rows = np.repeat(np.asarray(rows, int), k)
        self.labels = np.array(list(self.kinds) * p, object)
        self.delta = FORCE_TOLERANCE * weight
        tol = [self.delta, self.delta] + ([RELATIVE_TOLERANCE * bound] if bound is not None else [])
        self.tolerance = np.tile(tol, p)
        self.limit = np.tile([0.0, 0.0] + ([bound] if bound is not None else []), p)
        self.root, self.up = root, np.asarray(up, float)

    def _parts(self, state):
        F = state.tau[self.rows[::len(self.kinds)], self.root:self.root + 3]
        fz = F @ self.up
        Fxy = F - fz[:, None] * self.up
        return F, fz, Fxy

    def measure(self, state):
        F, fz, Fxy = self._parts(state)
        cols = [-fz, _smooth_norm(Fxy, self.delta)[0] - FRICTION * fz]
        if "peak" in self.kinds:
            cols.append(_smooth_norm(F, self.delta)[0])
        return np.column_stack(cols).ravel()

    def pull(self, state, g):
        k = len(self.kinds)
        g = g.reshape(-1, k)
        if not g.any():
            return
        F, fz, Fxy = self._parts(state)
        _, dxy = _smooth_norm(Fxy, self.delta)
        dxy = dxy - (dxy @ self.up)[:, None] * self.up  # d|F_xy| / dF
        gF = (-g[:, :1] - FRICTION * g[:, 1:2]) * self.up + g[:, 1:2] * dxy
        if "peak" in self.kinds:
            gF += g[:, 2:3] * _smooth_norm(F, self.delta)[1]
        gt = np.zeros(state.tau.shape)
        np.add.at(gt, (self.rows[::k], slice(self.root, self.root + 3)), gF)
        state.add_tau(gt)


def figure_forces(model, t: np.ndarray, flights, peak_bw: float | None = None) -> list[Constraint]:
    """The force bounds of a figure's problem (module docstring).

    Args:
        model: MjModel of the scene (the figure's root a free joint). t: (n,) quadrature times [s].
        flights: ((start, end), ...) [s]: points strictly inside one are in flight, the rest on the ground.
        peak_bw: the peak ground force bound [body weights] (`PeakBounds.ground_force_bw`), or None.
    Returns:
        [FlightWrench (if any point flies), GroundForce].
    Raises:
        InputError: the model has no free joint.
    """
    from solver.layout import StateLayout
    from solver.terms.dynamics import _free_joint, figure_radius_of_gyration

    layout = StateLayout.from_model(model)
    j = _free_joint(model, layout)
    root = int(model.jnt_dofadr[j])
    g = np.asarray(model.opt.gravity, float)
    weight = float(np.sum(model.body_mass)) * float(np.linalg.norm(g))
    air = np.zeros(len(t), bool)
    for a, b in flights:
        air |= (t > a) & (t < b)
    out: list[Constraint] = []
    if air.any():
        arm = figure_radius_of_gyration(model, int(model.jnt_bodyid[j]))
        out.append(FlightWrench(np.flatnonzero(air), root, weight, arm))
    bound = None if peak_bw is None else peak_bw * weight
    out.append(GroundForce(np.flatnonzero(~air), root, weight, -g / np.linalg.norm(g), bound))
    return out
