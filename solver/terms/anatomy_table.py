"""The figure's anatomical limits: a published normal range of motion per ball joint, and the hinge axes
of the knees and elbows, measured on the swing-twist decomposition of each joint's quaternion.

Range of motion. The American Academy of Orthopaedic Surgeons' average ranges (AAOS, "Joint Motion:
Method of Measuring and Recording", 1965; reprinted in Greene & Heckman, "The Clinical Measurement of
Joint Motion", AAOS 1994, and tabulated in Norkin & White, "Measurement of Joint Motion: A Guide to
Goniometry", appendix A), in degrees from the anatomical zero position (standing, arms at the sides,
feet flat), which is the figure's identity pose (models/humanoid39.xml):

    joint            motion (negative / positive)          range [deg]   source
    hip              flexion / extension                   -120 .. 30    AAOS
                     adduction / abduction                  -30 .. 45    AAOS
                     internal / external rotation           -45 .. 45    AAOS
    knee             flexion (hyperextension: `bending`)       .. 135    AAOS
    ankle            dorsiflexion / plantarflexion          -20 .. 50    AAOS
                     inversion / eversion (subtalar)        -35 .. 15    AAOS
                     adduction / abduction (toe in / out)   -30 .. 30    not in the table (loose bound)
    trunk (torso)    extension / flexion                    -25 .. 80    AAOS thoracolumbar spine
                     right / left lateral flexion           -35 .. 35    AAOS thoracolumbar spine
                     rotation                               -45 .. 45    AAOS thoracolumbar spine
    shoulder         flexion / extension                   -180 .. 60    AAOS
                     adduction / abduction                  -45 .. 180   AAOS abduction; adduction (the
                                                                         arm across the chest) not in the
                                                                         table (loose bound)
                     internal / external rotation           -70 .. 90    AAOS
    elbow            flexion (hyperextension: `bending`)       .. 150    AAOS

The figure's torso joint carries the whole spine and the head; it has no neck or wrist joints.

Decomposition. Each joint has a twist axis a along its distal segment (thigh, arm and trunk: the long
axis, z at rest; foot: its long axis x; knee and elbow: the flexion axis). A joint quaternion q = s t
splits into a twist t about a and a swing s about an axis normal to a (`solver.quaternion.swing_twist`);
a motion is either the twist angle (rotation about the segment: internal / external rotation,
inversion / eversion, knee and elbow flexion) or the signed swing about one direction e normal to a
(`solver.quaternion.swing_about`: the angle a goniometer reads in the plane normal to e). Axes are
mirrored left to right so that a positive angle is the same anatomical motion on both sides.

Hinges. Knees and elbows are ball joints in the figure; their rotation off the hinge is the swing angle
about the flexion axis (`solver.quaternion.swing_angle`, `Figure.flexion_axes`): 0 for a pure hinge.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solver.quaternion import swing_about_grad, swing_angle, twist_angle_grad

__all__ = ["BoundedMotion", "ROM_SOURCE", "motion_axes", "range_of_motion", "motion_angles", "motion_angle_grads",
           "off_hinge_angles"]

ROM_SOURCE = ('AAOS, "Joint Motion: Method of Measuring and Recording" (1965); Greene & Heckman, '
              '"The Clinical Measurement of Joint Motion" (AAOS, 1994)')

_X, _Y, _Z = np.eye(3)

#: per joint kind: (twist axis of the left side, lateral direction of the left side, motions); a motion is
#: (negative name, positive name, "twist" | "sagittal" | "lateral", lo [deg], hi [deg]). "sagittal" is
#: the swing about +y (both sides), "lateral" the swing about the lateral direction (left: +x for
#: thigh, arm and trunk, +z for the foot; mirrored for the right side), "twist" the twist about the axis
#: (mirrored for the right side). None: not bounded by this term.
_KINDS = {
    "hip": (_Z, _X, (("flexion", "extension", "sagittal", -120.0, 30.0),
                     ("adduction", "abduction", "lateral", -30.0, 45.0),
                     ("internal rotation", "external rotation", "twist", -45.0, 45.0))),
    "ankle": (_X, _Z, (("dorsiflexion", "plantarflexion", "sagittal", -20.0, 50.0),
                       ("adduction", "abduction", "lateral", -30.0, 30.0),
                       ("inversion", "eversion", "twist", -35.0, 15.0))),
    "trunk": (_Z, _X, (("extension", "flexion", "sagittal", -25.0, 80.0),
                       ("left lateral flexion", "right lateral flexion", "lateral", -35.0, 35.0),
                       ("rotation", "rotation", "twist", -45.0, 45.0))),
    "shoulder": (_Z, _X, (("flexion", "extension", "sagittal", -180.0, 60.0),
                          ("adduction", "abduction", "lateral", -45.0, 180.0),
                          ("internal rotation", "external rotation", "twist", -70.0, 90.0))),
    "knee": (None, None, (("hyperextension", "flexion", "twist", None, 135.0),)),
    "elbow": (None, None, (("hyperextension", "flexion", "twist", None, 150.0),)),
}
#: the shipped figure's joints: {joint name: (kind, side +1 left / -1 right / 0 middle)}
FIGURE_JOINTS = {"l_hip": ("hip", 1), "r_hip": ("hip", -1), "l_knee": ("knee", 1), "r_knee": ("knee", -1),
                 "l_ankle": ("ankle", 1), "r_ankle": ("ankle", -1), "torso": ("trunk", 0),
                 "l_shoulder": ("shoulder", 1), "r_shoulder": ("shoulder", -1),
                 "l_elbow": ("elbow", 1), "r_elbow": ("elbow", -1)}


@dataclass(frozen=True)
class BoundedMotion:
    """One bounded motion of one joint.

    Attributes:
        joint: the figure's joint name. motion: "negative name / positive name" (e.g. "flexion /
            extension"). kind: "twist" (rotation about `axis`) or "swing" (signed swing about `e`).
        axis: (3,) unit twist axis, joint frame. e: (3,) unit swing direction normal to `axis` (kind
            "swing"; None for "twist").
        lo, hi: [rad] the range; -inf / inf where unbounded.
    """

    joint: str
    motion: str
    kind: str
    axis: np.ndarray
    e: np.ndarray | None
    lo: float
    hi: float

    def widened(self, lo: float, hi: float) -> BoundedMotion:
        """The same motion with the range widened to include [lo, hi] [rad]."""
        return BoundedMotion(self.joint, self.motion, self.kind, self.axis, self.e,
                             min(self.lo, float(lo)), max(self.hi, float(hi)))


def range_of_motion(figure) -> tuple[BoundedMotion, ...]:
    """The bounded motions (module docstring's table) of the figure's joints named in FIGURE_JOINTS.

    Knee and elbow flexion is the twist about the figure's flexion axis (`Figure.flexion_axes`); a
    figure without a flexion axis for one of them leaves its flexion unbounded here.

    Args:
        figure: `solver.figure.Figure`.
    Returns:
        tuple of BoundedMotion, joint by joint in the figure's qpos order.
    """
    out = []
    for joint in figure.joints:
        if joint.name not in FIGURE_JOINTS or joint.kind != "ball":
            continue
        kind, side = FIGURE_JOINTS[joint.name]
        axis, lateral, motions = _KINDS[kind]
        if axis is None:  # knee, elbow: flexion about the flexion axis
            if joint.name not in figure.flexion_axes:
                continue
            axis = np.asarray(figure.flexion_axes[joint.name], float)
        else:
            mirror = -1.0 if side < 0 else 1.0
            axis, lateral = mirror * axis, mirror * lateral
        for neg, pos, which, lo, hi in motions:
            e = None if which == "twist" else _Y if which == "sagittal" else lateral
            out.append(BoundedMotion(joint.name, f"{neg} / {pos}", "twist" if e is None else "swing", axis, e,
                                     -np.inf if lo is None else np.radians(lo), np.radians(hi)))
    return tuple(out)


def motion_axes(motions) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The motions as arrays: (twist axes (c, 3), swing directions (c, 3) (for a twist any unit normal to
    its axis, unused), twist mask (c,) bool)."""
    axes = np.array([m.axis for m in motions], float).reshape(-1, 3)
    twist = np.array([m.kind == "twist" for m in motions], bool)
    es = np.array([np.cross(m.axis, _X if abs(m.axis[0]) < 0.9 else _Y) if m.e is None else m.e for m in motions],
                  float).reshape(-1, 3)
    return axes, es / np.linalg.norm(es, axis=1, keepdims=True), twist


def motion_angles(Y: np.ndarray, idx: np.ndarray, motions, arrays=None) -> np.ndarray:
    """The angle of each bounded motion along a path [rad] (module docstring, "Decomposition"):
    `solver.quaternion.twist_angle` (on the quaternion with w >= 0) or `swing_about`, for all motions
    at once.

    Args:
        Y: (n, nq) qpos. idx: (c, 4) qpos indices of each motion's joint quaternion. motions: (c,)
            BoundedMotion. arrays: `motion_axes(motions)` if the caller keeps it (else computed).
    Returns:
        (n, c) angles [rad]; twists in (-pi, pi].
    """
    axes, es, twist = motion_axes(motions) if arrays is None else arrays
    q = Y[:, idx]  # (n, c, 4)
    w, v = q[..., 0], q[..., 1:]
    p = np.einsum("nci,ci->nc", v, axes)
    out = np.empty(p.shape)
    if twist.any():
        sign = np.where(w[:, twist] < 0, -1.0, 1.0)
        out[:, twist] = 2.0 * np.arctan2(sign * p[:, twist], sign * w[:, twist])
    sw = ~twist
    if sw.any():
        ps, ws, vs = p[:, sw], w[:, sw], v[:, sw]
        N = ws * np.einsum("nci,ci->nc", vs, es[sw]) - ps * np.einsum("nci,ci->nc", vs, np.cross(axes[sw], es[sw]))
        out[:, sw] = 2.0 * np.arctan2(N, ws * ws + ps * ps)
    return out


def motion_angle_grads(Y: np.ndarray, idx: np.ndarray, motions, rows: np.ndarray, cols: np.ndarray,
                       arrays=None) -> np.ndarray:
    """d angle / d q of motion cols[i] at sample rows[i] (`motion_angles`, same arguments), with respect
    to that motion's qpos[idx[cols[i]]]: `twist_angle_grad` (sign-corrected) or `swing_about_grad`.

    Args:
        rows, cols: (m,) int, the (sample, motion) pairs wanted (the active ones of a penalty).
    Returns:
        (m, 4); 0 where the angle is not differentiable (a half-turn swing).
    """
    axes, es, twist = motion_axes(motions) if arrays is None else arrays
    q = Y[rows[:, None], np.asarray(idx)[cols]]  # (m, 4)
    sign = np.where(q[:, :1] < 0, -1.0, 1.0)
    a, e = axes[cols], es[cols]
    return np.where(twist[cols][:, None], sign * twist_angle_grad(q * sign, a), swing_about_grad(q, a, e))


def off_hinge_angles(Y: np.ndarray, idx: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """Rotation of each hinge-like joint off its hinge [rad]: the swing angle about the flexion axis.

    Args:
        Y: (n, nq) qpos. idx: (j, 4) qpos indices of the joints. axes: (j, 3) unit flexion axes.
    Returns:
        (n, j) angles in [0, pi].
    """
    return swing_angle(Y[:, np.asarray(idx, int).reshape(-1, 4)], np.asarray(axes, float).reshape(-1, 3))
