"""Where each figure body sits on a recognised skeleton: its frame relative to the joint that drives it,
and the places of the joints it carries, measured on the clip's motion.

A figure body's world orientation is its driving joint's times a constant rotation R_off (docs/mocap.md,
"What the figure keeps"): figure world = source world x R_off. R_off is the body's anatomical frame
expressed in the joint's frame, built from what every convention shares - the joints' world positions
and orientations over the clip - and never from the rest pose (in many conventions not a standing pose):

* **pelvis**: y (left) along the right to the left hip joint, z up towards the shoulders' midpoint;
* **torso**: y along the right to the left shoulder joint, z from the torso's pivot (the spine joint
  above the hips) to the shoulders' midpoint;
* **thigh and shin, upper arm and forearm**: the figure's segment direction along the bone; the figure's
  flexion axis (knee, elbow) along the joint's functional hinge axis, the flexion-weighted mean of
  bone x next bone over the clip (a mean helical axis, Ehrig et al. 2007, J. Biomech. 40:2150-2157),
  its sign from anatomy (a knee's axis points to the pelvis's left, in any posture; flexing, a hanging
  forearm swings forward of the torso: `_hinge_flipped`), so that a clip that mostly hyperextends a joint does not
  turn it round; a joint that bends less than `MIN_FLEXION` on average gives no axis, and the parent body's
  frame, turned by the mean relative rotation and swung onto the bone, is taken instead;
* **foot**: z along the world's up while the foot is flat, x towards the ball of the foot. The foot is
  taken to be flat in the slower half of its frames (the faster of the ankle and the ball of the foot:
  foot flat is where both the heel and the forefoot are still, as velocity-based gait-event detection
  defines it, Ghoussayni et al. 2004, Gait & Posture 20:266-272) and, of those, in the `FLAT_FRACTION`
  of all frames with the ankle lowest (heel strike and push-off raise it; a foot held still in the air
  is high). The lowest ankle alone took a stair climber's push-off from the floor, the only frames that
  foot had there, for flat (143_17's left foot, 42 degrees toes-down against 10 on the right), and the
  stillest frames alone a runner's first forefoot stance. Only frames whose shin stands within 75 degrees
  of vertical count (where the clip has any): a kneeling subject's feet lie on their tops, lower than they
  stand, and taken for flat they turned the figure's feet over. A skeleton that gives the foot no length
  (no toe joint, its End Site at the ankle: a toeless Perception Neuron export) shows no ball; there x is
  forward as the skeleton stands in its rest pose (`rest_forward`), the one direction taken from it.

Each vector is the mean over the clip's frames in the joint's frame, and each frame is made with the
TRIAD method (the first vector exact, the second fixing the rotation about it; Shuster & Oh 1981, J.
Guidance Control 4(1):70-77). Because only world quantities enter, two conventions of one motion (bones
along +X or a T-pose at rest, any rotation order) give the same figure.

Files made before the frames were measured - a keyframe file that records no skeleton, among them the
shipped models/run_and_step.keyframes.json, and a subject figure that records no frames - were made
with the CMU skeleton's rest pose (every channel zero: a T-pose, legs straight, feet flat) as the
figure's identity pose, and are read so again (`rest_pose_frames`): the pelvis and torso take their
joint's frame, a limb or foot the smallest rotation from the figure's segment to the rest bone.

The places of the joints a body carries (hips and pivot on the pelvis, shoulders, neck and head on the
torso, ball and toe tip on the foot) are their mean positions in the body's frame over the clip: the
rigid body nearest the capture in least squares; exact where the source's joints between them do not
move (CMU's LHipJoint), a mean where they do (a bending spine, moving clavicles).
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np
from scipy.spatial.transform import Rotation

from runner.capture.bvh import BvhClip
from runner.capture.bvh_kinematics import rotate, tip_positions
from runner.capture.skeleton import RecognisedSkeleton, skeleton_world
from solver.errors import InputError
from solver.quaternion import conj, mul, normalize

__all__ = ["DRIVERS", "BODY_JOINT", "ELBOW_HYPEREXTENSION",
           "MIN_FLEXION", "RAISED_ARM", "SHIN_TILT", "FLAT_FRACTION", "BodyFrames", "body_frames", "rest_pose_frames",
           "triad"]

#: figure body -> the role whose joint drives its orientation
DRIVERS = MappingProxyType({
    "pelvis": "hips", "l_thigh": "l_upper_leg", "l_shin": "l_lower_leg", "l_foot": "l_foot",
    "r_thigh": "r_upper_leg", "r_shin": "r_lower_leg", "r_foot": "r_foot", "torso": "chest",
    "l_upper_arm": "l_upper_arm", "l_forearm": "l_forearm", "r_upper_arm": "r_upper_arm", "r_forearm": "r_forearm"})
#: figure body -> the role whose joint is at the body's joint centre (the torso pivots at the spine joint)
BODY_JOINT = MappingProxyType({**DRIVERS, "torso": "spine"})
#: limb body -> (role where its bone ends, the figure joint whose flexion axis it carries)
LIMBS = MappingProxyType({
    "l_thigh": ("l_lower_leg", "l_knee"), "l_shin": ("l_foot", "l_knee"), "r_thigh": ("r_lower_leg", "r_knee"),
    "r_shin": ("r_foot", "r_knee"), "l_upper_arm": ("l_forearm", "l_elbow"), "l_forearm": ("l_hand", "l_elbow"),
    "r_upper_arm": ("r_forearm", "r_elbow"), "r_forearm": ("r_hand", "r_elbow")})
#: a hinge must bend on average more than this for its axis to be measured (sin 10 deg; below it the
#: capture's marker noise of a few degrees is a large part of bone x next bone)
MIN_FLEXION = np.sin(np.radians(10.0))
#: [1] the upper arm's rise (its direction's component along the torso's up) above which a flexing elbow no
#: longer swings the forearm forward but towards the head: sin 30 deg, the arm 30 deg above level
RAISED_ARM = 0.5
#: [rad] the most an elbow hyperextends: 15 deg (AAOS 1965 gives extension 0; Kapandji, The Physiology of the
#: Joints, vol. 1, 6th ed., 2007: 5-15 deg in lax joints), so an elbow bent further in most frames is flexed
ELBOW_HYPEREXTENSION = float(np.radians(15.0))
#: [rad] a flat foot's shin is at most this far from vertical: 75 deg, past the deepest crouch with the heels down
#: in the clips here (63 deg, a dancer's), short of a kneel's shin along the floor (90)
SHIN_TILT = float(np.radians(75.0))
#: the fraction of frames, those of the slower half with the ankle lowest, in which a foot is taken to be flat
FLAT_FRACTION = 0.1
#: [m] a foot whose ball of the foot is nearer its ankle than this has no length the skeleton gives (a toeless
#: export with its End Site at the ankle): a centimetre, a tenth of the shortest adult foot's ankle-to-ball reach
MIN_FOOT = 0.01
_PARENT = {"l_thigh": "pelvis", "l_shin": "l_thigh", "r_thigh": "pelvis", "r_shin": "r_thigh",
           "l_upper_arm": "torso", "l_forearm": "l_upper_arm", "r_upper_arm": "torso", "r_forearm": "r_upper_arm"}


@dataclass(frozen=True)
class BodyFrames:
    """Figure bodies on a clip's skeleton (module docstring).

    Attributes:
        offsets: {body: (4,) unit quaternion R_off} with figure world = source world (of `DRIVERS`[body])
            x R_off, MuJoCo axes.
        points: {body: {name: (3,) [m]}} mean places in the body's frame, relative to its joint centre:
            pelvis: "l_thigh", "r_thigh", "torso"; torso: "l_upper_arm", "r_upper_arm", "neck", "skull", "top";
            feet: "ball", "tip"; limbs: the next joint's name (the bone).
    """

    offsets: Mapping[str, np.ndarray]
    points: Mapping[str, Mapping[str, np.ndarray]]


def triad(a_fig, b_fig, a_src, b_src, what: str = "a body's frame") -> np.ndarray:
    """(4,) the rotation R taking a_fig to a_src exactly and b_fig as near b_src as that allows (TRIAD,
    Shuster & Oh 1981). Raises InputError if a pair is parallel (naming `what`: the file and the body)."""
    def frame(a, b):
        a = np.asarray(a, float) / np.linalg.norm(a)
        c = np.cross(a, b)
        if np.linalg.norm(c) < 1e-9:
            raise InputError(f"{what}: the two directions that fix it are parallel, so the skeleton is degenerate "
                             "there; check the HIERARCHY, or name other joints for it in a skeleton map "
                             "(--skeleton-map FILE, docs/mocap.md \"Skeleton map\")")
        c /= np.linalg.norm(c)
        return np.column_stack([a, c, np.cross(a, c)])

    m = frame(a_src, b_src) @ frame(a_fig, b_fig).T
    q = Rotation.from_matrix(m).as_quat()
    return np.r_[q[3], q[:3]]


def _in_frame(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(n, 3) world vectors v in the frames of the (n, 4) orientations q."""
    return rotate(conj(q), v)


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def body_frames(clip: BvhClip, skel: RecognisedSkeleton, figure) -> BodyFrames:
    """Measure the figure's bodies on `clip` (module docstring).

    Args:
        clip: a parsed clip. skel: its recognised skeleton. figure: `solver.figure.Figure` (its segment
            directions and flexion axes; the shipped figure's for a subject figure being made).
    Returns:
        BodyFrames.
    Raises:
        InputError: a bone of zero length, or two directions that fix a frame are parallel.
    """
    q, p = skeleton_world(clip, skel)
    q, p = q[skel.rest_frames:], p[skel.rest_frames:]
    at = {r: skel.index(clip, r) for r in ("hips", "spine", "chest", "head", "neck", "l_upper_leg", "r_upper_leg",
                                           "l_upper_arm", "r_upper_arm", "l_lower_leg", "r_lower_leg", "l_foot",
                                           "r_foot", "l_forearm", "r_forearm", "l_hand", "r_hand")}
    for r in ("l_toe", "r_toe"):
        if r in skel.roles:
            at[r] = skel.index(clip, r)
    P = {r: p[:, j] for r, j in at.items()}
    Q = {r: q[:, j] for r, j in at.items()}
    for body, (end, _) in LIMBS.items():
        if np.linalg.norm(P[end] - P[BODY_JOINT[body]], axis=-1).min() < 1e-6:
            raise InputError(f"{skel.source}: joint {skel.joint(end)} has a zero-length OFFSET from "
                             f"{skel.joint(BODY_JOINT[body])}, so the bone that ends there has no length; fix the "
                             "HIERARCHY, or name other joints in a skeleton map (--skeleton-map FILE)")
    shoulders = 0.5 * (P["l_upper_arm"] + P["r_upper_arm"])
    hips = 0.5 * (P["l_upper_leg"] + P["r_upper_leg"])
    def what(body):
        return f"{skel.source}: the {body}'s frame"

    off = {"pelvis": triad([0, 1, 0], [0, 0, 1], _mean_in(Q["hips"], P["l_upper_leg"] - P["r_upper_leg"]),
                           _mean_in(Q["hips"], shoulders - hips), what("pelvis")),
           "torso": triad([0, 1, 0], [0, 0, 1], _mean_in(Q["chest"], P["l_upper_arm"] - P["r_upper_arm"]),
                          _mean_in(Q["chest"], shoulders - P["spine"]), what("torso"))}
    for body in ("l_thigh", "l_shin", "r_thigh", "r_shin", "l_upper_arm", "l_forearm", "r_upper_arm", "r_forearm"):
        off[body] = _limb_offset(body, figure, P, Q, off, what(body))
    up = np.broadcast_to([0.0, 0.0, 1.0], p[:, 0].shape)
    for side in "lr":
        ankle = P[f"{side}_foot"]
        ball = _ball(clip, skel, (q, p), side, at)
        flat = _flat(ankle, ball, P[f"{side}_lower_leg"])
        ahead = _mean_in(Q[f"{side}_foot"], ball - ankle)
        if np.linalg.norm(ahead) < MIN_FOOT:  # the skeleton gives the foot no length: forward as it stands at rest
            ahead = rest_forward(clip, skel, side)
        off[f"{side}_foot"] = triad([0, 0, 1], [1, 0, 0], _mean_in(Q[f"{side}_foot"][flat], up[flat]), ahead,
                                    what(f"{side}_foot"))
    offsets = MappingProxyType({b: normalize(np.asarray(v, float)) for b, v in off.items()})
    return BodyFrames(offsets, MappingProxyType(_points(clip, skel, (q, p), at, offsets)))


def rest_pose_frames(clip: BvhClip, skel: RecognisedSkeleton, figure) -> BodyFrames:
    """The body offsets of files made before they were measured (module docstring): identity for the
    pelvis and torso; for a limb or foot the smallest rotation from the figure's segment direction to the
    bone in the skeleton's rest pose (every channel zero), in MuJoCo axes. No points.

    Raises:
        InputError: a bone of zero length in the rest pose (joint named).
    """
    rest = clip.rest_positions()
    off = {"pelvis": np.array([1.0, 0, 0, 0]), "torso": np.array([1.0, 0, 0, 0])}
    for body, (end, _) in {**LIMBS, "l_foot": ("l_toe", None), "r_foot": ("r_toe", None)}.items():
        start = BODY_JOINT[body]
        bone = skel.axes @ (rest[skel.index(clip, end)] - rest[skel.index(clip, start)])
        if np.linalg.norm(bone) < 1e-9:
            raise InputError(f"{skel.source}: joint {skel.joint(end)} has a zero OFFSET, so the bone that ends there "
                             "has no direction; fix the HIERARCHY")
        off[body] = _swing(np.asarray(figure.segments[body].direction, float), bone)
    return BodyFrames(MappingProxyType(off), MappingProxyType({}))


def rest_forward(clip: BvhClip, skel: RecognisedSkeleton, side: str) -> np.ndarray:
    """(3,) the direction a foot points in its joint's frame for a skeleton that gives the foot no length (no toe
    joint, its End Site at the ankle): forward as the skeleton stands in its rest pose (every channel zero, where
    every joint's frame is the world's), horizontal and square to the line from the right hip to the left.

    Raises:
        InputError: the rest pose's hips do not span a horizontal line (names the file and the fix).
    """
    rest = clip.rest_positions()
    left = skel.axes @ (rest[skel.index(clip, "l_upper_leg")] - rest[skel.index(clip, "r_upper_leg")])
    ahead = np.cross(left, [0.0, 0.0, 1.0])
    if np.linalg.norm(ahead) < 1e-6 * max(np.linalg.norm(left), 1e-300):
        raise InputError(f"{skel.source}: joint {skel.joint(f'{side}_foot')} has no toe and its End Site is at the joint, "
                         "so the foot has no direction, and the rest pose does not show one; name a toe joint in a "
                         "skeleton map (--skeleton-map FILE) or give the foot's End Site its length")
    return ahead / np.linalg.norm(ahead)


def _flat(ankle: np.ndarray, ball: np.ndarray, knee: np.ndarray | None = None) -> np.ndarray:
    """(m,) the frames in which a foot is taken to be flat (module docstring), from the (n, 3) [m] places
    of its ankle, ball and knee: of the slower half, the `FLAT_FRACTION` of all frames with the ankle lowest,
    among those whose shin stands within SHIN_TILT of vertical (a foot flat on the floor carries its shin above
    it; a kneeling foot lies on its top, lower than it stands, with the shin along the floor); where no slow
    frame's shin stands, of the frames whose shin does; where none does, of the slower half. knee None: every
    frame."""
    speed = np.maximum(*(np.linalg.norm(np.gradient(x, axis=0), axis=-1) for x in (ankle, ball)))
    slow = speed <= np.median(speed)
    if knee is not None:
        shin = knee - ankle
        upright = shin[:, 2] >= np.cos(SHIN_TILT) * np.linalg.norm(shin, axis=-1)
        slow = next((m for m in (slow & upright, upright) if m.any()), slow)  # else no frame is upright
    slow = np.flatnonzero(slow)
    return slow[np.argsort(ankle[slow, 2], kind="stable")[:max(1, round(FLAT_FRACTION * len(ankle)))]]


def _mean_in(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(3,) the mean of world vectors v (n, 3) in the frames q (n, 4)."""
    return _in_frame(q, v).mean(axis=0)


def _limb_offset(body: str, figure, P: dict, Q: dict, off: dict, what: str) -> np.ndarray:
    """R_off of a limb body: segment along the bone, flexion axis along the measured hinge (module docstring);
    `what` names it in an error (`triad`)."""
    end, hinge_joint = LIMBS[body]
    start = BODY_JOINT[body]
    bone = _mean_in(Q[start], P[end] - P[start])
    upper = body.replace("shin", "thigh").replace("forearm", "upper_arm")
    lower = body.replace("thigh", "shin").replace("upper_arm", "forearm")
    u = _unit(P[BODY_JOINT[lower]] - P[BODY_JOINT[upper]])
    v = _unit(P[LIMBS[lower][0]] - P[BODY_JOINT[lower]])
    cross = np.cross(u, v)
    seg = figure.segments[body].direction
    if np.linalg.norm(cross, axis=-1).mean() >= MIN_FLEXION:
        hinge = _mean_in(Q[start], cross)
        if _hinge_flipped(hinge_joint, rotate(Q[start], np.broadcast_to(hinge, u.shape)), u, v, Q, off):
            hinge = -hinge
        return triad(seg, figure.flexion_axes[hinge_joint], bone, hinge, what)
    parent = _PARENT[body]
    rel = mul(conj(Q[start]), mul(Q[DRIVERS[parent]], np.broadcast_to(off[parent], Q[start].shape)))
    mean = Rotation.from_quat(normalize(rel)[:, [1, 2, 3, 0]]).mean().as_quat()
    mean = np.r_[mean[3], mean[:3]]
    turned = rotate(mean, np.asarray(seg, float))
    return mul(_swing(turned, bone), mean)


def _hinge_flipped(hinge_joint: str, hinge: np.ndarray, u: np.ndarray, v: np.ndarray, Q: dict, off: dict) -> bool:
    """Whether the measured hinge axis (n, 3) [world, per frame] points against flexion, by anatomy, not by which
    way the clip bends most (module docstring). A knee's flexion axis is the femur's medio-lateral axis (Grood &
    Suntay, J. Biomech. Eng. 105:136-144, 1983), which the hip's rotation (at most 45 degrees either way, AAOS
    1965) keeps near the pelvis's: it points to the pelvis's left, in any posture. An elbow's follows the upper
    arm, which the shoulder turns anywhere: flexing an arm that hangs or is held out to the side swings the
    forearm forward of the torso (a raised arm's towards or behind the head), a test summed over the frames
    whose upper arm (`u` (n, 3), the upper bone) is no higher than RAISED_ARM; a clip whose arms are always
    higher keeps the measured bend (the mean of bone x next bone points to flexion wherever the joint bends more
    than it hyperextends), and so does an elbow bent further than any elbow hyperextends (`ELBOW_HYPEREXTENSION`)
    in most frames (more than half, the angle between `u` and the next bone `v` (n, 3)): its bend is flexion, and
    the swing test, which arms rounded in front of the body misread (a dancer's first position: the forearm
    swings across the torso, not forward; a pirouette's right elbow, bent 24-88 degrees, was read as bent
    backwards and straightened), is not asked. A swing test fails where the limb never hangs: a seated
    subject's thighs are level, and the shin's forward swing is zero in every frame."""
    if "knee" in hinge_joint:
        frame = mul(Q[DRIVERS["pelvis"]], np.broadcast_to(off["pelvis"], Q[DRIVERS["pelvis"]].shape))
        return float(np.sum(hinge * rotate(frame, np.broadcast_to([0.0, 1.0, 0.0], u.shape)))) < 0.0
    if np.mean(np.sum(u * v, axis=-1) < np.cos(ELBOW_HYPEREXTENSION)) > 0.5:  # bent beyond it in most frames
        return False
    frame = mul(Q[DRIVERS["torso"]], np.broadcast_to(off["torso"], Q[DRIVERS["torso"]].shape))
    low = np.sum(u * rotate(frame, np.broadcast_to([0.0, 0.0, 1.0], u.shape)), axis=-1) <= RAISED_ARM
    forward = rotate(frame, np.broadcast_to([1.0, 0.0, 0.0], u.shape))
    return float(np.sum(np.sum(np.cross(hinge[low], u[low]) * forward[low], axis=-1))) < 0.0


def _swing(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(4,) the smallest rotation taking direction a to direction b."""
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    c = float(a @ b)
    if c < -1.0 + 1e-12:
        axis = np.cross(a, [1.0, 0.0, 0.0])
        if np.linalg.norm(axis) < 1e-6:
            axis = np.cross(a, [0.0, 1.0, 0.0])
        return np.r_[0.0, axis / np.linalg.norm(axis)]
    q = np.r_[1.0 + c, np.cross(a, b)]
    return q / np.linalg.norm(q)


def _ball(clip, skel, world, side: str, at: dict) -> np.ndarray:
    """(n, 3) [m] the ball of the foot: the toe joint, or without one where the foot's chain ends."""
    if f"{side}_toe" in at:
        return world[1][:, at[f"{side}_toe"]]
    return tip_positions(clip, world, at[f"{side}_foot"], skel.axes, skel.unit)


def _points(clip, skel, world, at: dict, offsets) -> dict:
    """{body: {name: (3,)}} the mean places (`BodyFrames.points`)."""
    q, p = world
    P = {r: p[:, j] for r, j in at.items()}

    def place(body, point):
        frame = mul(q[:, at[DRIVERS[body]]], np.broadcast_to(offsets[body], q[:, 0].shape))
        return _in_frame(frame, point - P[BODY_JOINT[body]]).mean(axis=0)

    out = {"pelvis": {"l_thigh": place("pelvis", P["l_upper_leg"]), "r_thigh": place("pelvis", P["r_upper_leg"]),
                      "torso": place("pelvis", P["spine"])},
           "torso": {"l_upper_arm": place("torso", P["l_upper_arm"]), "r_upper_arm": place("torso", P["r_upper_arm"]),
                     "neck": place("torso", P["neck"]), "skull": place("torso", P["head"]),
                     "top": place("torso", tip_positions(clip, world, at["head"], skel.axes, skel.unit))}}
    for side in "lr":
        ball = _ball(clip, skel, world, side, at)
        toe = at.get(f"{side}_toe", at[f"{side}_foot"])
        out[f"{side}_foot"] = {"ball": place(f"{side}_foot", ball),
                               "tip": place(f"{side}_foot", tip_positions(clip, world, toe, skel.axes, skel.unit))}
    for body, (end, _) in LIMBS.items():
        out[body] = {"end": place(body, P[end])}
    return out
