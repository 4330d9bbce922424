"""Retargeting: a BVH clip of any skeleton convention onto the 39-DOF figure (the reference motion), and
its clean-up.

The pipeline (one concept: from a BVH file to a reference motion and keyframes on *our* figure):

1. Parse the BVH file with `bvhio` (runner/capture/bvh.py, after a check of its text that gives
   line-numbered errors) and recognise its skeleton (runner/capture/skeleton.py): which joint plays which
   role (hips, spine, chest, neck, head, and per side upper leg, lower leg, foot, toe, upper arm,
   forearm, hand), the length unit, the up axis, and a leading rest frame (CMU's cgspeed conversion
   starts with a synthetic T-pose), or take them from a skeleton map file.
2. Forward kinematics (BVH convention: a joint's local rotation R = R1 R2 R3 for its rotation channels
   listed 1 2 3, applied to column vectors; a joint's translation is its OFFSET or its position
   channels), in metres and in MuJoCo axes (z up; the file's up axis to z by a cyclic permutation of
   the axes: for Y-up files (x, y, z) = (Z, X, Y), as for CMU's clips).
3. Retargeting: each figure body's world orientation is its driving joint's world orientation times a
   constant offset R_off (runner/capture/body_frames.py: the body's anatomical frame in the joint's frame,
   measured on the clip, or recorded in the subject's figure); a limb whose bone a file bends by position
   channels of its own turns along the bone (`_along_bones`). Local joint quaternions follow as
   q_joint = conj(q_parent_world) q_child_world, unit, w x y z, hemisphere-consistent over time.
   Joints the figure merges are composed, not dropped: a body's world orientation includes every
   rotation above its driving joint (the torso's is every spine joint's; the thigh's includes a hip
   offset joint such as CMU's LHipJoint), so the joint quaternion between two bodies is the chain's
   composition (docs/mocap.md, "What the figure keeps"). On the subject's own figure
   (runner/capture/subject_figure.py: the figure's segments are the subject's bones, its ball site the toe
   joint) the hip, knee, ankle and toe-joint positions relative to the hips are the capture's, and the
   root path is the captured one. On another figure, which keeps its own bone lengths, the root
   position is the hips' position scaled by the ratio of the figure's leg length to the subject's
   (`leg_length_ratio`), as humanoid retargeting scales root motion by the hips' height (Unity's
   `Animator.humanScale`): a subject 10% taller than the figure covers 10% more ground per stride, and
   the figure's shorter legs, at the subject's joint angles, would slide its planted feet (a 16_23
   walk with bones scaled 1.1 and the root path left as captured: reference skate 2.19 instead of 1.58
   mm/frame, and planting the feet moved the joints 7.5 deg from the capture where the plain spline
   was 5.2 deg off).
4. Clean-up for hard constraints: knee and elbow hyperextension (flexion < 0 about the figure's
   flexion axes, `solver.figure.Figure.flexion_axes`) is clamped to 0 by removing the twist about the
   hinge axis (swing-twist decomposition); then the root height is corrected (`correct_root_height`)
   so that a foot in contact has its lowest contact site on the surface under it, and no contact site
   is ever below a surface.

Data of the shipped clips: CMU Graphics Lab Motion Capture Database, mocap.cs.cmu.edu (models/cmu/README.md).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from runner.capture.body_frames import DRIVERS, BodyFrames
from runner.capture.bvh import BvhClip
from runner.capture.skeleton import RecognisedSkeleton, skeleton_world
from solver.errors import InputError
from solver.figure import Figure
from solver.layout import StateLayout
from solver.quaternion import align_hemispheres, conj, hinge_angle, mul, normalize, swing_twist

if TYPE_CHECKING:
    from runner.capture.clip import Capture
    from runner.capture.foot_plant import FootPlant
    from runner.capture.glitches import Glitch

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
            `runner.capture.reference_motion.load_bvh_reference`; the source-skeleton export takes it off).
        skeleton: the clip's recognised skeleton (None: a clip on the figure's own skeleton, read exactly).
        clamped: {knee or elbow joint: (n,) [deg]} the hyperextension the clean-up removed per frame
            (`hyperextension`), or None.
        plant: the capture with its resting feet planted on their surfaces, which the keyframes are taken
            from (`runner.capture.foot_plant.FootPlant`: its qpos, and what it moved), or None (a clip on the
            figure's own skeleton). `qpos` stays the capture: the motion metrics judge against it.
        glitches: the capture's tracking glitches repaired in `qpos` (`runner.capture.glitches.Glitch`: a joint
            turning faster than any human joint between two frames).
        capture: the clip as read (`runner.capture.clip.Capture`), which the steps after the import take
            instead of reading `source` again; None for a motion not read from a clip.
    """

    times: np.ndarray
    qpos: np.ndarray
    source: str
    frame_time: float
    root_scale: float = 1.0
    captured_root: bool = False
    skeleton: RecognisedSkeleton | None = None
    clamped: dict | None = None
    plant: FootPlant | None = None
    glitches: tuple[Glitch, ...] = ()
    capture: Capture | None = None

    @property
    def count(self) -> int:
        return len(self.times)

    @property
    def duration(self) -> float:
        """[s] time of the last frame."""
        return float(self.times[-1])

    def keyed(self) -> Reference:
        """The motion keyframes are chosen on and take their values from: the capture with its resting feet
        planted (`plant.qpos`, docs/mocap.md "The keyframes' feet"), or this reference when not planted."""
        return self if self.plant is None else replace(self, qpos=self.plant.qpos, plant=None)


# --------------------------------------------------------------------------------------------------
# retargeting
# --------------------------------------------------------------------------------------------------


def leg_lengths(clip: BvhClip, skel: RecognisedSkeleton) -> np.ndarray:
    """(2,) [m] the subject's left and right leg: hip -> knee + knee -> ankle joint centres, the mean
    over the clip's frames (the bones' lengths; 0.836 m for the subject of 16_23, 0.865 m for 35_17)."""
    _, p = skeleton_world(clip, skel)
    out = []
    for s in "lr":
        hip, knee, ankle = (p[:, skel.index(clip, f"{s}_{r}")] for r in ("upper_leg", "lower_leg", "foot"))
        out.append(np.linalg.norm(knee - hip, axis=-1).mean() + np.linalg.norm(ankle - knee, axis=-1).mean())
    return np.array(out)


def leg_length_ratio(clip: BvhClip, skel: RecognisedSkeleton, model) -> float:
    """The figure's leg length over the subject's: the scale `retarget` applies to the root path.

    Leg length = hip -> knee + knee -> ankle, the mean of both legs: for the figure the lengths of its
    thigh and shin segments (`Figure.segments`: 0.42 + 0.42 m for humanoid39.xml), for the subject
    `leg_lengths`.

    Raises:
        InputError: a leg of zero length, or the figure lacks a leg body (`check_figure`).
    """
    segments = check_figure(Figure.from_model(model)).segments
    figure = np.mean([segments[f"{s}_thigh"].length + segments[f"{s}_shin"].length for s in "lr"])
    subject = float(leg_lengths(clip, skel).mean())
    if subject <= 1e-9:
        raise InputError(f"{clip.source}: the legs ({skel.joint('l_upper_leg')} to {skel.joint('l_foot')}) have no "
                         "length; check the HIERARCHY's OFFSETs")
    return float(figure / subject)


def check_figure(figure: Figure) -> Figure:
    """`figure` if its bodies are those the retargeting drives (`DRIVERS`, models/humanoid39.xml's) and every
    limb body has a segment (`Figure.segments`), else InputError naming the bodies and the fix."""
    missing = [b for b in DRIVERS if b not in figure.bodies]
    extra = [b for b in figure.bodies if b not in DRIVERS]
    if missing or extra:
        raise InputError(f"the figure's bodies differ from those the retargeting drives ({', '.join(DRIVERS)}): "
                         f"missing {', '.join(missing) or 'none'}, not driven {', '.join(extra) or 'none'}; "
                         "use a figure with the bodies of models/humanoid39.xml")
    no_end = [b for b in DRIVERS if b != "pelvis" and b != "torso" and b not in figure.segments]
    if no_end:
        raise InputError(f"the figure's bodies {', '.join(no_end)} have no segment end (no single child body): "
                         f'add <text name="figure:end:{no_end[0]}" data="SITE"/> to its MJCF\'s <custom>, '
                         "naming a site of that body where its bone ends")
    return figure


def retarget(clip: BvhClip, skel: RecognisedSkeleton, frames: BodyFrames, figure: Figure, layout: StateLayout,
             root_scale: float = 1.0) -> np.ndarray:
    """Retarget every frame of a clip onto the figure: `qpos` before any clean-up.

    Root position = root_scale times the hips' world position [m] (scaled about the capture's origin);
    body orientations = the driving joints' world orientations times the body offsets (module docstring,
    step 3); joint quaternions relative to the parent body; each joint's quaternions hemisphere-aligned
    over time, the first with w >= 0.

    Args:
        clip: a parsed clip (all frames, the rest frames included). skel: its recognised skeleton.
        frames: the figure's bodies on it (`runner.capture.body_frames.body_frames`, or a subject figure's
            record). figure: the figure. layout: the scene's qpos layout.
        root_scale: scale of the root path, > 0 (`leg_length_ratio` for the figure's legs; 1: as captured).
    Returns:
        (n, nq) qpos, a row per frame of the file.
    Raises:
        InputError: the figure's bodies are not `DRIVERS`' (`check_figure`).
    """
    check_figure(figure)
    qw, pw = skeleton_world(clip, skel)
    body_q = {b: mul(qw[:, skel.index(clip, role)], np.broadcast_to(frames.offsets[b], qw[:, 0].shape))
              for b, role in DRIVERS.items()}
    body_q = _along_bones(body_q, clip, skel, pw)
    qpos = np.zeros((len(qw), layout.nq))
    root = figure.joints[0]  # the free joint: the root body's
    qpos[:, root.qposadr : root.qposadr + 3] = root_scale * pw[:, skel.index(clip, "hips")]
    qpos[:, root.qposadr + 3 : root.qposadr + 7] = body_q[figure.root]
    for joint in figure.joints[1:]:
        parent, child = figure.joint_bodies[joint.name]
        qpos[:, joint.qpos_slice] = mul(conj(body_q[parent]), body_q[child])
    return tidy_quaternions(qpos, layout)


#: [m] a limb's bone shorter than this (1 mm: below any capture's resolution) has no direction to turn the limb along
BONE_MIN = 1e-3


def _along_bones(body_q: dict, clip: BvhClip, skel: RecognisedSkeleton, pw: np.ndarray) -> dict:
    """The limbs' world orientations (`body_q`, {body: (n, 4)}) turned along their bones where the file moves
    joints by position channels of their own (a Perception Neuron export "with displacement": a foot 2.8-12.7
    cm off its OFFSET from the knee). The driving joint's rotation then no longer points the bone: each limb
    (`body_frames.LIMBS`: thigh, shin, upper arm, forearm) turns by the shortest rotation from its bone
    at the clip's mean translations to its bone in the frame, the capture's joint positions `pw` (n, J, 3)
    [m], so the figure's knee, ankle, elbow and wrist lie along the capture's bones. A file whose joints
    other than the root keep their OFFSETs (or constant translations) is left exactly as it is."""
    from runner.capture.body_frames import LIMBS
    from runner.capture.bvh_kinematics import between, forward

    pos = clip.local_pos[:, 1:]
    if not np.any(pos != pos[:1]):
        return body_q
    mean = clip.local_pos.copy()
    mean[:, 1:] = pos.mean(axis=0)
    pm = (forward(clip.parents, clip.local_quat, mean)[1] @ skel.axes.T) * skel.unit
    out = dict(body_q)
    for body, (end, _) in LIMBS.items():
        s, e = skel.index(clip, DRIVERS[body]), skel.index(clip, end)
        a, b = pm[:, e] - pm[:, s], pw[:, e] - pw[:, s]
        ok = np.minimum(np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)) > BONE_MIN  # a bone to point
        if ok.any():
            out[body] = body_q[body].copy()
            out[body][ok] = normalize(mul(between(a[ok], b[ok]), body_q[body][ok]))
    return out


def tidy_quaternions(qpos: np.ndarray, layout: StateLayout) -> np.ndarray:
    """Unit joint quaternions of (n, nq) qpos, w >= 0 at the first frame, hemisphere-consistent over time."""
    out = qpos.copy()
    for slot in layout.quat_slots:
        q = normalize(out[:, slot])
        if q[0, 0] < 0:
            q = -q
        out[:, slot] = align_hemispheres(q)
    return out


def hyperextension(qpos: np.ndarray, figure: Figure) -> dict[str, np.ndarray]:
    """{knee or elbow joint: (n,) [deg]} how far each frame bends the joint backwards: minus its flexion
    (`hinge_angle` about the figure's flexion axis, in (-180, 180]) where that is negative, else 0."""
    return {name: np.degrees(np.maximum(-hinge_angle(qpos[:, figure.joint(name).qpos_slice], np.array(axis)), 0.0))
            for name, axis in figure.flexion_axes.items()}


def clamp_hyperextension(qpos: np.ndarray, figure: Figure) -> tuple[np.ndarray, int]:
    """Clamp knee and elbow hyperextension to zero flexion.

    Flexion is `hinge_angle(q, axis)` (in (-pi, pi]) with the figure's flexion axes (`Figure.flexion_axes`). Where it
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
        bad = hinge_angle(q, a) < 0
        if not bad.any():
            continue
        swing, _ = swing_twist(q[bad], a)
        out[np.flatnonzero(bad), sl] = normalize(swing)
        changed += int(bad.sum())
    return out, changed
