"""Retargeting: a CMU BVH clip onto the 39-DOF figure (the reference motion), and its clean-up.

The pipeline (one concept: from a BVH file to a reference motion and keyframes on *our* figure):

1. Parse the BVH file with `bvhio` (hierarchy, channels, Euler angles -> local quaternions), after a
   check of the text (`_check_bvh_text`: the HIERARCHY grammar, the MOTION header, every data line)
   that gives exact line-numbered errors for user mistakes and protects against two `bvhio` 1.5.4
   defects: its line reader loops forever at end of file (a truncated file would hang it), and the line
   numbers in its SyntaxErrors are wrong inside nested joints.
2. Forward kinematics of the CMU skeleton (BVH convention: local rotation R = Rz Ry Rx for the channel
   order Z Y X, applied to column vectors), in metres (1 unit = 0.05644 m, the ASF `length 0.45`) and in
   MuJoCo axes: BVH is Y up with the figure facing +Z and its left at +X; MuJoCo is z up, facing +x,
   left +y. So (x, y, z)_mujoco = (Z, X, Y)_bvh, a proper rotation (`BVH_TO_MUJOCO`).
3. Retargeting: each figure body's world orientation is the corresponding CMU bone's world orientation
   times a fixed rest-pose offset R_off (`rest_offsets`): the smallest rotation that takes the figure
   bone's direction at the identity pose (`solver.figure.Figure.segments`: hip -> knee, knee -> ankle,
   ankle -> ball of the foot, shoulder -> elbow, elbow -> wrist) to the CMU bone's direction in the
   CMU rest (T-) pose (all
   channels zero). So the CMU T-pose maps to the figure with arms out sideways, and with legs and feet
   along the subject's own rest bone directions (the CMU thigh and shin bones point about 20 degrees
   outward in its rest pose, so mapping them to the identity would cross the figure's legs); the
   pelvis and the torso have R_off = identity. Local joint quaternions follow as
   q_joint = conj(q_parent_world) q_child_world, unit, w x y z, hemisphere-consistent over time.
   Joints the figure merges are composed, not dropped: a body's world orientation includes every
   rotation above its driving joint (the torso's is LowerBack Spine Spine1; the thigh's includes
   LHipJoint), so the joint quaternion between two bodies is the chain's composition (docs/mocap.md,
   "What the figure keeps"). On the subject's own figure (runner/mocap/subject_figure.py: the figure's
   segments are the subject's bones, its ball site the toe joint) the hip, knee, ankle and toe-joint
   positions relative to the hips are the capture's, and the root path is the captured one. On another
   figure, which keeps its own bone lengths, the root position is the CMU Hips position scaled by the ratio
   of the figure's leg length to the subject's (`leg_length_ratio`), as humanoid retargeting scales
   root motion by the hips' height (Unity's `Animator.humanScale`): a subject 10% taller than the
   figure covers 10% more ground per stride, and the figure's shorter legs, at the subject's joint
   angles, would slide its planted feet (a 16_23 walk with bones scaled 1.1 and the root path left
   as captured: reference skate 2.19 instead of 1.58 mm/frame, and planting the feet moved the joints
   7.5 deg from the capture where the plain spline was 5.2 deg off).
4. Clean-up for hard constraints: knee and elbow hyperextension (flexion < 0 about the figure's
   flexion axes, `solver.figure.Figure.flexion_axes`) is
   clamped to 0 by removing the twist about the hinge axis (swing-twist decomposition); then the root
   height is corrected (`correct_root_height`) so that a foot in contact has its lowest contact site
   on the surface under it, and no contact site is ever below a surface.

The synthetic T-pose first frame of the cgspeed BVH conversion is dropped (see
models/cmu/README.md). Data: CMU Graphics Lab Motion Capture Database, mocap.cs.cmu.edu.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from runner.mocap.bvh import POSITION_CHANNELS, BvhClip
from solver.errors import InputError
from solver.figure import Figure
from solver.layout import StateLayout
from solver.quaternion import align_hemispheres, conj, mul, normalize, swing_twist, twist_angle

# constants
# --------------------------------------------------------------------------------------------------

#: metres per CMU ASF length unit (ASF `length 0.45`: 1 unit = 1/0.45 inch).
UNIT_TO_METRES = 0.0254 / 0.45

#: (3, 3) rotation taking BVH axes (Y up, facing +Z, left +X) to MuJoCo axes (z up, facing +x, left +y).
BVH_TO_MUJOCO = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])

#: figure body -> (CMU joint whose world orientation drives it, CMU child joint giving the bone
#: direction, or None for an identity rest offset).
BONE_MAP: Mapping[str, tuple[str, str | None]] = MappingProxyType(
    {
        "pelvis": ("Hips", None),
        "l_thigh": ("LeftUpLeg", "LeftLeg"),
        "l_shin": ("LeftLeg", "LeftFoot"),
        "l_foot": ("LeftFoot", "LeftToeBase"),
        "r_thigh": ("RightUpLeg", "RightLeg"),
        "r_shin": ("RightLeg", "RightFoot"),
        "r_foot": ("RightFoot", "RightToeBase"),
        "torso": ("Spine1", None),
        "l_upper_arm": ("LeftArm", "LeftForeArm"),
        "l_forearm": ("LeftForeArm", "LeftHand"),
        "r_upper_arm": ("RightArm", "RightForeArm"),
        "r_forearm": ("RightForeArm", "RightHand"),
    }
)

# --------------------------------------------------------------------------------------------------
# data
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Reference:
    """A dense reference motion of the figure, retargeted from motion capture.

    Attributes:
        times: (n,) frame times [s], starting at 0, spaced `frame_time`.
        qpos: (n, nq) MuJoCo `qpos` per frame: root position [m], unit quaternions (w x y z),
            hemisphere-consistent over time per joint; the root in the scene's frame (the levelled
            capture frame of a fitted scene, `solver.capture_frame`).
        source: the BVH file it came from.
        frame_time: [s] time between frames of the clip.
        root_scale: the scale applied to the captured root path (`retarget`; 1: as captured).
        captured_root: the root path is the captured one, unscaled, up to the per-frame height
            correction that stands the feet on the scene's surfaces (the subject's own figure,
            `runner.mocap.reference.load_bvh_reference`; the source-skeleton export takes it off).
    """

    times: np.ndarray
    qpos: np.ndarray
    source: str
    frame_time: float
    root_scale: float = 1.0
    captured_root: bool = False

    @property
    def count(self) -> int:
        return len(self.times)

    @property
    def duration(self) -> float:
        """[s] time of the last frame."""
        return float(self.times[-1])


# --------------------------------------------------------------------------------------------------
# kinematics of the CMU skeleton and retargeting
# --------------------------------------------------------------------------------------------------


def _to_mujoco_quat(q: np.ndarray) -> np.ndarray:
    """Express (..., 4) rotations given in BVH axes in MuJoCo axes: R' = M R M^T, i.e. v' = M v."""
    out = np.array(q, float, copy=True)
    out[..., 1:] = q[..., 1:] @ BVH_TO_MUJOCO.T
    return out


def cmu_world(clip: BvhClip) -> tuple[np.ndarray, np.ndarray]:
    """World orientation and position of every CMU joint, in MuJoCo axes and metres.

    Forward kinematics: q_world[j] = q_world[parent] q_local[j], p_world[j] = p_world[parent] +
    R(q_world[parent]) p_local[j] (BVH convention, column vectors), then the BVH -> MuJoCo axes change
    and the unit scale `UNIT_TO_METRES`.

    Args:
        clip: a parsed clip.
    Returns:
        quat: (n, J, 4) world orientations (w x y z) in MuJoCo axes.
        pos: (n, J, 3) world joint positions [m] in MuJoCo axes.
    """
    n, J = clip.local_quat.shape[:2]
    q = np.empty((n, J, 4))
    p = np.empty((n, J, 3))
    for j in range(J):
        par = clip.parents[j]
        if par < 0:
            q[:, j] = clip.local_quat[:, j]
            p[:, j] = clip.local_pos[:, j]
        else:
            q[:, j] = mul(q[:, par], clip.local_quat[:, j])
            p[:, j] = p[:, par] + _rotate(q[:, par], clip.local_pos[:, j])
    return _to_mujoco_quat(q), (p @ BVH_TO_MUJOCO.T) * UNIT_TO_METRES


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate (..., 3) vectors by (..., 4) unit quaternions."""
    qv = np.concatenate([np.zeros(v.shape[:-1] + (1,)), v], axis=-1)
    return mul(mul(q, qv), conj(q))[..., 1:]


def _swing(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation (unit quaternion) taking direction a to direction b (both (3,))."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    c = float(a @ b)
    if c < -1.0 + 1e-12:  # opposite: any perpendicular axis
        axis = np.cross(a, [1.0, 0.0, 0.0])
        if np.linalg.norm(axis) < 1e-6:
            axis = np.cross(a, [0.0, 1.0, 0.0])
        return np.r_[0.0, axis / np.linalg.norm(axis)]
    q = np.r_[1.0 + c, np.cross(a, b)]
    return q / np.linalg.norm(q)


def rest_offsets(clip: BvhClip, figure: Figure) -> dict[str, np.ndarray]:
    """Rest-pose offset R_off (unit quaternion) per figure body: figure world = CMU world * R_off.

    For a limb bone, the smallest rotation taking the figure's segment direction at the identity pose
    (`Figure.segments`, body frame = world frame there) to the CMU bone direction in the CMU rest pose
    (the child joint's OFFSET, in MuJoCo axes); identity for the pelvis and torso.
    """
    out = {}
    for body, (_, child) in BONE_MAP.items():
        if child is None:
            out[body] = np.array([1.0, 0.0, 0.0, 0.0])
            continue
        d_cmu = BVH_TO_MUJOCO @ clip.offsets[clip.index(child)]
        if np.linalg.norm(d_cmu) < 1e-9:
            raise InputError(
                f"{clip.source}: joint {child} has a zero OFFSET, so the bone that ends there has no "
                "direction; the retargeting needs the CMU skeleton (Hahne's BVH conversion)"
            )
        out[body] = _swing(figure.segments[body].direction, d_cmu)
    return out


#: the leg bones whose lengths give the root path's scale: (figure thigh body, figure shin body, CMU
#: knee joint, CMU ankle joint); a figure segment runs from its body's joint to the next joint, a CMU
#: bone's length is the OFFSET of the joint it ends at.
LEG_BONES = (("l_thigh", "l_shin", "LeftLeg", "LeftFoot"), ("r_thigh", "r_shin", "RightLeg", "RightFoot"))


def leg_length_ratio(clip: BvhClip, model) -> float:
    """The figure's leg length over the subject's: the scale `retarget` applies to the root path.

    Leg length = hip -> knee + knee -> ankle at the rest pose, the mean of both legs: for the figure
    the lengths of its thigh and shin segments (`Figure.segments`: 0.42 + 0.42 m for humanoid39.xml),
    for the subject the norms of the CMU OFFSETs of the knee and ankle joints in metres (0.836 m for
    the subject of 16_23, 0.865 m for 35_17, 0.863 m for 127_33).

    Args:
        clip: a parsed clip with the CMU leg joints. model: the scene's MjModel (the figure's bodies).
    Returns:
        the ratio, > 0 [1].
    Raises:
        InputError: the clip is not the CMU skeleton (`check_skeleton`), a leg joint has a zero OFFSET,
            or the figure lacks a leg body (`check_figure`).
    """
    check_skeleton(clip)
    segments = check_figure(Figure.from_model(model)).segments
    figure, subject = [], []
    for thigh, shin, cmu_knee, cmu_ankle in LEG_BONES:
        figure.append(segments[thigh].length + segments[shin].length)
        bones = [np.linalg.norm(clip.offsets[clip.index(j)]) * UNIT_TO_METRES for j in (cmu_knee, cmu_ankle)]
        if min(bones) <= 1e-9:
            raise InputError(f"{clip.source}: joint {cmu_knee} or {cmu_ankle} has a zero OFFSET, so the leg "
                             "has no length; the retargeting needs the CMU skeleton (Hahne's BVH conversion)")
        subject.append(float(sum(bones)))
    return float(np.mean(figure) / np.mean(subject))


def check_figure(figure: Figure) -> Figure:
    """`figure` if its bodies are those `BONE_MAP` drives (models/humanoid39.xml's) and every limb body
    has a segment (`Figure.segments`), else InputError naming the bodies and the fix."""
    missing = [b for b in BONE_MAP if b not in figure.bodies]
    extra = [b for b in figure.bodies if b not in BONE_MAP]
    if missing or extra:
        raise InputError(f"the figure's bodies differ from those the retargeting drives ({', '.join(BONE_MAP)}): "
                         f"missing {', '.join(missing) or 'none'}, not driven {', '.join(extra) or 'none'}; "
                         "use a figure with the bodies of models/humanoid39.xml")
    no_end = [b for b, (_, child) in BONE_MAP.items() if child and b not in figure.segments]
    if no_end:
        raise InputError(f"the figure's bodies {', '.join(no_end)} have no segment end (no single child body): "
                         f'add <text name="figure:end:{no_end[0]}" data="SITE"/> to its MJCF\'s <custom>, '
                         "naming a site of that body where its bone ends")
    return figure


def _required_joints() -> list[str]:
    req = []
    for joint, child in BONE_MAP.values():
        req += [joint] + ([child] if child else [])
    return list(dict.fromkeys(req))


def check_skeleton(clip: BvhClip) -> None:
    """Raises InputError (naming the file, the joints or channels and the fix) unless the clip has the
    CMU joints the retargeting needs, the root Hips, and the root's position channels."""
    missing = [j for j in _required_joints() if j not in clip.names]
    if missing:
        raise InputError(
            f"{clip.source}: the skeleton has no joint(s) {', '.join(missing)}; the retargeting needs the "
            f"CMU skeleton's {', '.join(_required_joints())} (the cgspeed BVH conversion of "
            "mocap.cs.cmu.edu). Rename the joints of your skeleton to these names"
        )
    if clip.names[0] != "Hips":
        raise InputError(f"{clip.source}: the ROOT joint is {clip.names[0]!r}; the CMU skeleton's root is 'Hips'")
    missing_pos = [c for c in POSITION_CHANNELS if c not in clip.channels[0]]
    if missing_pos:
        raise InputError(
            f"{clip.source}: the ROOT joint Hips has no {', '.join(missing_pos)} channel(s) (it has "
            f"{' '.join(clip.channels[0]) or 'none'}); the root path needs 'CHANNELS 6 Xposition Yposition "
            "Zposition Zrotation Yrotation Xrotation'"
        )


def retarget(clip: BvhClip, figure: Figure, layout: StateLayout, root_scale: float = 1.0) -> np.ndarray:
    """Retarget every frame of a clip onto the figure: `qpos` before any clean-up.

    Root position = root_scale times the CMU Hips position [m] (scaled about the capture's origin);
    body orientations = CMU bone orientations times the rest offsets (module docstring, step 3); joint
    quaternions relative to the parent body; each joint's quaternions hemisphere-aligned over time, the
    first with w >= 0.

    Args:
        clip: a parsed clip (all frames). figure: the figure (`Figure.from_model`; its segments and
            joints). layout: the scene's qpos layout.
        root_scale: scale of the root path, > 0 (`leg_length_ratio` for the figure's legs; 1: as captured).
    Returns:
        (n, nq) qpos.
    Raises:
        InputError: a joint the retargeting needs is missing from the clip, or the Hips has no
            position channels (`check_skeleton`); the figure's bodies are not `BONE_MAP`'s (`check_figure`).
    """
    check_skeleton(clip)
    check_figure(figure)
    qw, pw = cmu_world(clip)
    offsets = rest_offsets(clip, figure)
    body_q = {b: mul(qw[:, clip.index(j)], offsets[b]) for b, (j, _) in BONE_MAP.items()}
    n = len(qw)
    qpos = np.zeros((n, layout.nq))
    root = figure.joints[0]  # the free joint: the root body's
    qpos[:, root.qposadr : root.qposadr + 3] = root_scale * pw[:, clip.index("Hips")]
    qpos[:, root.qposadr + 3 : root.qposadr + 7] = body_q[figure.root]
    for joint in figure.joints[1:]:
        parent, child = figure.joint_bodies[joint.name]
        qpos[:, joint.qpos_slice] = mul(conj(body_q[parent]), body_q[child])
    return tidy_quaternions(qpos, layout)


def tidy_quaternions(qpos: np.ndarray, layout: StateLayout) -> np.ndarray:
    """Unit joint quaternions of (n, nq) qpos, w >= 0 at the first frame, hemisphere-consistent over time."""
    out = qpos.copy()
    for slot in layout.quat_slots:
        q = normalize(out[:, slot])
        if q[0, 0] < 0:
            q = -q
        out[:, slot] = align_hemispheres(q)
    return out


def clamp_hyperextension(qpos: np.ndarray, figure: Figure) -> tuple[np.ndarray, int]:
    """Clamp knee and elbow hyperextension to zero flexion.

    Flexion is `twist_angle(q, axis)` with the figure's flexion axes (`Figure.flexion_axes`). Where it
    is negative, the twist about the hinge axis is removed: q = s t (swing-twist decomposition,
    `solver.quaternion.swing_twist`), q <- s = q conj(t), which has twist angle exactly 0 and the same swing.
    Other joints are unchanged.

    Args:
        qpos: (n, nq) with unit quaternions. figure: the figure (its flexion axes and joints).
    Returns:
        (clamped qpos (n, nq), number of joint-frames changed).
    """
    out = qpos.copy()
    changed = 0
    for name, axis in figure.flexion_axes.items():
        a = np.array(axis)
        sl = figure.joint(name).qpos_slice
        q = out[:, sl]
        bad = twist_angle(q, a) < 0
        if not bad.any():
            continue
        swing, _ = swing_twist(q[bad], a)
        out[np.flatnonzero(bad), sl] = normalize(swing)
        changed += int(bad.sum())
    return out, changed
