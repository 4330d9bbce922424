"""Moving a foot straight up or down with its own leg: analytic two-bone inverse kinematics on the figure.

The footplant clean-up of an imported capture (`runner.capture.foot_plant.plant_feet`) puts a resting foot
the capture holds above its surface onto it, and lifts a foot back out of a surface, without moving the
foot along the surface or turning it: the foot moves rigidly by dz along the vertical, in every frame
where dz is not 0 (Kovar, Schreiner & Gleicher, "Footskate cleanup for motion capture editing", SCA 2002,
enforce footplants by per-frame inverse kinematics of the legs; here only the height changes). With the
pelvis fixed, the hip joint stays where it is, and (`move_foot`):

1. the knee flexes about its own flexion axis (the figure's annotation, `Figure.flexion_axes`) by the
   angle that puts the ankle at the target's distance from the hip (the root of
   |K - H + R(theta) (A - K)| = |A' - H| nearest theta = 0 that leaves the knee flexed, in closed form),
   never past a straight knee (flexion >= 0): the knee's rotation off its hinge is unchanged;
2. the thigh swings about the hip by the shortest rotation that takes the ankle onto the target;
3. the ankle turns so that the foot keeps its world orientation.

A leg that cannot reach (the knee straight) moves the foot as far as the straight knee allows, exactly
vertically: the returned dz says how far each foot went.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from runner.capture.bvh_kinematics import between, rotate
from solver.errors import InputError
from solver.figure import Figure
from solver.quaternion import conj, hinge_angle, mul, normalize

__all__ = ["LegChain", "leg_chain", "move_foot"]

#: [m] a foot is moved where |dz| exceeds this (a micrometre: below any capture's resolution)
MOVE_TOL = 1e-6


@dataclass(frozen=True)
class LegChain:
    """One leg of the figure, hip to foot.

    Attributes:
        side: the foot's name in `Figure.feet` ("left", "right").
        pelvis, thigh, shin, foot: MuJoCo body ids (pelvis: the thigh's parent).
        hip, knee, ankle: qpos slices of the three ball joints (w x y z quaternions).
        knee_axis: (3,) the knee's unit flexion axis in the shin's (the joint's) frame.
        joints: the MuJoCo joint ids of the hip, the knee and the ankle.
    """

    side: str
    pelvis: int
    thigh: int
    shin: int
    foot: int
    hip: slice
    knee: slice
    ankle: slice
    knee_axis: np.ndarray
    joints: tuple[int, int, int]


def leg_chain(model, figure: Figure, side: str) -> LegChain:
    """The leg of foot `side` (the body of its heel site, its parent and grandparent).

    Raises:
        InputError: a body of the chain has no ball joint, or the knee has no flexion axis annotation.
    """
    import mujoco

    heel = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, figure.feet[side][0])
    foot = int(model.site_bodyid[heel])
    shin = int(model.body_parentid[foot])
    thigh = int(model.body_parentid[shin])
    slices, ids = [], []
    for body in (thigh, shin, foot):
        joints = [j for j in range(model.njnt) if model.jnt_bodyid[j] == body
                  and model.jnt_type[j] == mujoco.mjtJoint.mjJNT_BALL]
        if len(joints) != 1:
            name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, body)
            raise InputError(f"the figure's {side} leg: body {name!r} needs one ball joint for the footplant; "
                             "give the hip, knee and ankle a ball joint each (models/README.md)")
        adr = int(model.jnt_qposadr[joints[0]])
        slices.append(slice(adr, adr + 4))
        ids.append(int(joints[0]))
    knee = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, ids[1])
    if knee not in figure.flexion_axes:
        raise InputError(f'the figure has no flexion axis for its knee {knee!r}: add <numeric name="figure:flexion:'
                         f'{knee}" data="x y z"/> (models/README.md)')
    return LegChain(side, int(model.body_parentid[thigh]), thigh, shin, foot, *slices,
                    np.asarray(figure.flexion_axes[knee], float), tuple(ids))


def _axis_angle(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """(n, 4) unit quaternions of rotations by angle (n,) [rad] about unit axes (n, 3)."""
    half = 0.5 * np.asarray(angle, float)[:, None]
    return np.concatenate([np.cos(half), np.sin(half) * axis], axis=1)


def knee_angle(hip: np.ndarray, knee: np.ndarray, ankle: np.ndarray, axis: np.ndarray,
               distance: np.ndarray, flexion: np.ndarray | None = None) -> np.ndarray:
    """(n,) [rad] the rotation theta of the shin about the knee axis that puts the ankle `distance` from the hip.

    With v = A - K split along the unit axis a (world, (n, 3)) into v_par + v_perp,
    |K - H + R(theta) v|^2 = |K - H|^2 + |v|^2 + 2 (c0 + c1 cos(theta) + c2 sin(theta)), c0 = (K - H).v_par,
    c1 = (K - H).v_perp, c2 = (K - H).(a x v_perp): theta = phi +- acos(rhs / r), r = hypot(c1, c2),
    phi = atan2(c2, c1); the root nearest 0, and where no theta reaches the distance the one that comes
    nearest (acos clipped). Points hip, knee, ankle: (n, 3) [m]; distance: (n,) [m]. flexion: (n,) [rad] the
    knee's flexion now (None: any root): the root nearest 0 among those that leave it flexed, flexion +
    theta >= 0, where one does. A straight knee shortens its leg by the same |theta| either way, and which
    of the two roots is nearer 0 is then round-off: the one that hyperextends would be stopped at straight.
    """
    kh, v = knee - hip, ankle - knee
    v_par = np.sum(v * axis, axis=1, keepdims=True) * axis
    v_perp = v - v_par
    c0 = np.sum(kh * v_par, axis=1)
    c1 = np.sum(kh * v_perp, axis=1)
    c2 = np.sum(kh * np.cross(axis, v_perp), axis=1)
    rhs = 0.5 * (distance ** 2 - np.sum(kh * kh, axis=1) - np.sum(v * v, axis=1)) - c0
    r = np.hypot(c1, c2)
    phi = np.arctan2(c2, c1)
    delta = np.arccos(np.clip(rhs / np.maximum(r, np.finfo(float).tiny), -1.0, 1.0))
    roots = (np.stack([phi + delta, phi - delta]) + np.pi) % (2 * np.pi) - np.pi
    cost = np.abs(roots)
    if flexion is not None:
        bent = roots + np.asarray(flexion, float) >= 0.0
        cost = np.where(bent | ~bent.any(axis=0), cost, np.inf)
    return roots[np.argmin(cost, axis=0), np.arange(len(r))]


def move_foot(model, leg: LegChain, qpos: np.ndarray, dz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Move the foot of `leg` rigidly by dz along the vertical with its leg (module docstring).

    Args:
        model: the figure's MjModel. leg: `leg_chain`'s. qpos: (n, nq). dz: (n,) [m], + up; frames with
            |dz| <= MOVE_TOL are left as they are.
    Returns:
        (qpos (n, nq) with the hip, knee and ankle of the moved frames changed, dz reached (n,) [m]: dz
        where the leg reaches, less where the straight knee stops it, 0 where not moved).
    """
    import mujoco

    rows = np.flatnonzero(np.abs(dz) > MOVE_TOL)
    reached = np.zeros(len(qpos))
    if not rows.size:
        return qpos, reached
    data = mujoco.MjData(model)
    pts = np.empty((len(rows), 3, 3))  # hip, knee, ankle joint centres
    rot = np.empty((len(rows), 4, 4))  # pelvis, thigh, shin, foot world orientations
    for i, r in enumerate(rows):
        data.qpos[:] = qpos[r]
        mujoco.mj_kinematics(model, data)
        pts[i] = data.xanchor[list(leg.joints)]
        rot[i] = data.xquat[[leg.pelvis, leg.thigh, leg.shin, leg.foot]]
    H, K, A = pts[:, 0], pts[:, 1], pts[:, 2]
    up = np.array([0.0, 0.0, 1.0])
    axis = rotate(rot[:, 2], np.broadcast_to(leg.knee_axis, (len(rows), 3)))
    flexion = hinge_angle(qpos[rows, leg.knee], leg.knee_axis)
    theta = knee_angle(H, K, A, axis, np.linalg.norm(A + dz[rows, None] * up - H, axis=1), flexion)
    theta = np.maximum(theta, -flexion)  # never past a straight knee
    bend = _axis_angle(axis, theta)
    ankle = K + rotate(bend, A - K)
    # the height the bent leg reaches exactly: |A + z up - H| = |ankle - H|, the root nearest the wish
    w = A - H
    disc = np.sqrt(np.maximum(0.0, w[:, 2] ** 2 - np.sum(w * w, axis=1) + np.sum((ankle - H) ** 2, axis=1)))
    roots = np.stack([-w[:, 2] + disc, -w[:, 2] - disc])
    z = roots[np.argmin(np.abs(roots - dz[rows]), axis=0), np.arange(len(rows))]
    swing = between(ankle - H, A + z[:, None] * up - H)
    thigh, shin = mul(swing, rot[:, 1]), mul(swing, mul(bend, rot[:, 2]))
    out = qpos.copy()
    frame = [np.broadcast_to(model.body_quat[b], (len(rows), 4)) for b in (leg.thigh, leg.shin, leg.foot)]
    out[rows, leg.hip] = normalize(mul(conj(mul(rot[:, 0], frame[0])), thigh))
    out[rows, leg.knee] = normalize(mul(conj(mul(thigh, frame[1])), shin))
    out[rows, leg.ankle] = normalize(mul(conj(mul(shin, frame[2])), rot[:, 3]))
    reached[rows] = z
    return out, reached
