"""Site Jacobians with respect to the spline's path: d p / d Y, d v / d Y and d v / d Y' of the contact
sites at the quadrature points, from a `solver.kinematic_tree.KinematicTree` engine's forward pass.

What the Gauss-Newton back end needs of the site terms (penetration, planted, clearance): their
residuals are functions of site positions p and velocities v (`solver.terms.base.SiteRows`), so their
Jacobian rows are (d r / d p) (d p / d Y) + (d r / d v) (d v / d Y), without one reverse pass per
residual. The columns are the geometric Jacobian of the tree (as MuJoCo's `mj_jacSite`): a rotation of
body b's joint by omega (its local frame, MuJoCo's ball and free joint convention) moves a site of its
subtree by (R_b omega) x (p - A_b), A_b the joint's anchor; the free joint's translation moves it by
the same amount. The spline's qpos reaches the tangent space through B(Y) = 2 G(q) / |q|^2 per
quaternion (`solver.kinematics`), so d p / d Y = J_v B.

The velocity is v = (d p / d Y) Y' at every point, so d v / d Y' = d p / d Y, and d v / d Y is the
second derivative of p contracted with Y', which (second derivatives being symmetric) is the time
derivative of d p / d Y along the path: d/dt [J_v B] = (d J_v / dt) B + J_v (d B / dt), with
d/dt (R_b e) x r = (omega_b x R_b e) x r + R_b e x (v_p - v_A), v_A = nu_b + omega_b x A_b the anchor's
velocity, and d B / dt = 2 G(q') / |q|^2 - 4 (q . q') G(q) / |q|^4.
"""
from __future__ import annotations

import numpy as np

from solver.quaternion import vec_of_conj_product


def supports(engine) -> bool:
    """True if `site_jacobians` can read this engine's forward pass (a `KinematicTree`)."""
    from solver.kinematic_tree import KinematicTree

    return isinstance(engine, KinematicTree)


def site_jacobians(engine, res, Y: np.ndarray, Y1: np.ndarray | None = None) -> list[tuple]:
    """Per tracked site (engine order): (comps (c,), Jp (n, 3, c), Jv (n, 3, c) or None).

    Args:
        engine: a `KinematicTree` engine (`supports`). res: its `forward` result at Y (and qvel from
            Y1, when the term reads velocities). Y: (n, nq) qpos. Y1: (n, nq) its time derivative, or
            None (positions only).
    Returns:
        comps: the qpos indices that move the site (the root's translation and every ancestor joint's
        quaternion); Jp = d p / d Y [m per unit qpos] (also d v / d Y'); Jv = d v / d Y [m/s per unit
        qpos] (None without Y1).
    """
    sv = res.saved
    R, A = sv["R"], sv["A"]  # (3, 3, B, n), (3, B, n)
    vel = Y1 is not None and "om" in sv
    rot = list(np.atleast_1d(np.arange(len(engine.bodies))[engine._rs]))
    slot_of = {int(b): i for i, b in enumerate(rot)}
    free_of = {int(b): i for i, b in enumerate(engine._free)}
    ys = sv.get("ys")
    if ys is None:  # a positions-only pass keeps no ys
        ys = res.sites.transpose(2, 1, 0)
    n = ys.shape[-1]
    # every (site, rotating ancestor) pair at once: the per-pair arrays are small, one pass over all
    pk, pb, layout = [], [], []
    for k, sb in enumerate(engine._site_body):
        cols, spans = [], []
        for b in np.flatnonzero(engine._anc[sb]):  # the site's body and its ancestors
            if b in free_of:
                spans.append(("lin", len(cols)))
                cols.append(engine._lin_q[free_of[b]])
            if b in slot_of:
                spans.append(("rot", len(pk)))
                cols.append(engine._quat_q[slot_of[b]])
                pk.append(k), pb.append(b)
        layout.append((np.concatenate(cols), spans))
    pk, pb = np.array(pk, int), np.array(pb, int)
    qi = np.stack([engine._quat_q[slot_of[int(b)]] for b in pb])  # (P, 4)
    q = Y[:, qi]  # (n, P, 4)
    s2 = (q * q).sum(-1)  # (n, P)
    G = vec_of_conj_product(q)  # (n, P, 3, 4)
    Bq = 2.0 * G / s2[..., None, None]
    r = ys[:, pk] - A[:, pb]  # (3, P, n)
    Rb = R[:, :, pb]  # (3, 3, P, n): columns the joint's local axes in the world
    Jw = _cross0(Rb, r[:, None])  # (3, 3, P, n): column a = R_b e_a x r
    Jp = np.einsum("iapn,npaj->ijpn", Jw, Bq)  # (3, 4, P, n)
    Jv = None
    if vel:
        q1 = Y1[:, qi]
        om, nu = sv["om"][:, pb], sv["nu"][:, pb]  # (3, P, n)
        vA = nu + _cross0(om, A[:, pb])
        dRb = _cross0(om[:, None], Rb)  # omega x (R_b e_a)
        dJw = _cross0(dRb, r[:, None]) + _cross0(Rb, (sv["ysd"][:, pk] - vA)[:, None])
        dB = 2.0 * vec_of_conj_product(q1) / s2[..., None, None] \
            - (4.0 * (q * q1).sum(-1) / (s2 * s2))[..., None, None] * G
        Jv = np.einsum("iapn,npaj->ijpn", dJw, Bq) + np.einsum("iapn,npaj->ijpn", Jw, dB)
    out = []
    eye = np.broadcast_to(np.eye(3)[:, :, None], (3, 3, n))
    for comps, spans in layout:
        Jp_k = np.concatenate([eye if kind == "lin" else Jp[:, :, i] for kind, i in spans], axis=1)
        Jv_k = None
        if vel:
            Jv_k = np.concatenate([np.zeros((3, 3, n)) if kind == "lin" else Jv[:, :, i] for kind, i in spans], axis=1)
            Jv_k = Jv_k.transpose(2, 0, 1)
        out.append((comps, Jp_k.transpose(2, 0, 1), Jv_k))
    return out


def _cross0(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b over axis 0 (3 components), broadcasting the other axes (np.cross without its axis moves)."""
    return np.stack([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def cached_site_jacobians(ctx, engine, res) -> list[tuple]:
    """`site_jacobians` of one engine on a `PathContext`'s path, computed once per context (the terms
    sharing the engine share them)."""
    cache = ctx.__dict__.setdefault("_site_jacobians", {})
    key = id(engine)
    if key not in cache:
        Y1 = ctx.Y1 if (ctx.Y1 is not None and 1 in engine.needs) else None
        cache[key] = site_jacobians(engine, res, ctx.Y, Y1)
    return cache[key]
