"""A CMU clip written onto the skeleton conventions of other captures and engines, for tests: the same motion with
other joint names, hierarchies, joint frames, axes, units, rotation orders, channels and frame rates.

The clip is read by tests/bvh_fk.py (not by the code under test) into local rotation matrices and
translations; each edit changes the convention and keeps every kept joint's world rotation, and - unless
it says otherwise - its world position, so the known answer of a re-export is the CMU clip's own forward
kinematics (the joints renamed, the lengths scaled by the unit). `CONVENTIONS` builds six of them:

* ``lafan1``: Ubisoft LAFAN1's - centimetres, Y up, Z Y X, names LeftUpLeg ... LeftToe, Spine/Spine1/
  Spine2, no hip offset joints or fingers, every bone along its joint's local +X (so the rest pose, every
  channel zero, is a straight line, not a T-pose), the root's OFFSET its world position in the first frame.
* ``bandai``: Bandai Namco's - a static extra root joint_Root above the hips, position channels on every
  joint, bones along local +X, names UpperLeg_L, LowerLeg_L, Foot_L, Toes_L, Shoulder_L, UpperArm_L, ...,
  centimetres, Z X Y.
* ``vicon``: a Vicon-style export - Z up, inches, a child performer (every length 0.7 of the subject's),
  mixed rotation orders, CMU's ASF names (lfemur, ltibia, lhumerus, lradius, ...), every End Site
  turned into an extra end joint (<name>_end), the synthetic T-pose first frame kept.
* ``rokoko``: a Rokoko export with Mixamo names (mixamorig:LeftUpLeg, ...) - 62 joints (fingers of
  three joints added to each hand, end joints HeadTop_End, LeftToe_End, eyes LeftEye and RightEye under
  the head), Y X Z, resampled to 100 frames per second, centimetres, the T-pose first frame kept.
* ``max3ds``: a 3ds Max-style skeleton - Hips -> Spine -> Head (CMU's three spine and two neck joints
  merged: the kept joints' world rotations are the clip's, but where the merged joints bent, the
  positions above them are not), L_Thigh, L_Calf, L_Clavicle, L_UpperArm ..., inches, Z X Y.
* ``ue5``: an Unreal-style skeleton - a static root above the pelvis with IK target joints hung from
  it (ik_foot_root, ik_hand_root -> ik_hand_gun -> ik_hand_l), twist joints beside the thigh and
  upper arm, names pelvis, spine_01..03, thigh_l, calf_l, ball_l, upperarm_l, lowerarm_l, bones along
  local +X, Z up, centimetres, X Y Z.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from bvh_fk import UNIT, parse, translations
from bvh_fk import local_rotations as fk_local_rotations
from scipy.spatial.transform import Rotation, Slerp

INCH = 0.0254
CM = 0.01
#: Y-up to Z-up file axes: (x, y, z)_zup = (X, -Z, Y)_yup... chosen so that up Y goes to +Z, proper
Y_TO_Z = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
ORDERS = ("XYZ", "YZX", "ZXY", "XZY", "YXZ", "ZYX")


@dataclass
class Clip:
    """A skeleton and its motion: names (J,), parents (J,), offsets (J, 3) [units], ends {joint: (3,)},
    local (n, J, 3, 3) rotations, trans (n, J, 3) translations [units], positions (joints with position
    channels), orders (J,) rotation channel orders, frame_time [s]."""

    names: list
    parents: list
    offsets: np.ndarray
    ends: dict
    local: np.ndarray
    trans: np.ndarray
    positions: set
    orders: list
    frame_time: float
    rest_frames: int = 1
    answer: dict = field(default_factory=dict)

    def index(self, name):
        return self.names.index(name)

    def children(self, j):
        return [c for c, p in enumerate(self.parents) if p == j]


def read(path) -> Clip:
    """A CMU clip (its first frame the synthetic T-pose) as a `Clip`; `answer` maps each joint to itself."""
    b = parse(path)
    orders = ["".join(c[0] for c in ch if c.endswith("rotation")) for ch in b.channels]
    positions = {j for j, ch in enumerate(b.channels) if any(c.endswith("position") for c in ch)}
    return Clip(list(b.names), list(b.parents), b.offsets.copy(), dict(b.ends), fk_local_rotations(b),
                translations(b), positions, orders, b.frame_time, 1, {n: n for n in b.names})


def _remove(c: Clip, keep: list[int]) -> Clip:
    """The clip with only the joints `keep` (their parents among them), reindexed."""
    new = {j: i for i, j in enumerate(keep)}
    parents = [new[c.parents[j]] if c.parents[j] >= 0 else -1 for j in keep]
    return replace(c, names=[c.names[j] for j in keep], parents=parents, offsets=c.offsets[keep],
                   ends={new[j]: e for j, e in c.ends.items() if j in new}, local=c.local[:, keep], trans=c.trans[:, keep],
                   positions={new[j] for j in c.positions if j in new}, orders=[c.orders[j] for j in keep],
                   answer={c.names[j]: c.answer[c.names[j]] for j in keep if c.names[j] in c.answer})


def prune(c: Clip, name: str) -> Clip:
    """Remove joint `name` and everything below it (its parent ends in an End Site where it began)."""
    j = c.index(name)
    gone = {j}
    for k in range(len(c.names)):
        if c.parents[k] in gone:
            gone.add(k)
    out = _remove(c, [k for k in range(len(c.names)) if k not in gone])
    parent = out.index(c.names[c.parents[j]])
    if not out.children(parent):
        out.ends[parent] = c.offsets[j].copy()
    return out


def drop(c: Clip, name: str) -> Clip:
    """Remove joint `name`, its children hung from its parent: their world rotations kept (local = the
    dropped joint's times theirs), their OFFSET the rest composition (exact where the dropped joint never
    rotates, as CMU's LHipJoint)."""
    j = c.index(name)
    local, trans, offsets = c.local.copy(), c.trans.copy(), c.offsets.copy()
    for k in c.children(j):
        local[:, k] = c.local[:, j] @ c.local[:, k]
        offsets[k] = c.offsets[j] + c.offsets[k]
        trans[:, k] = offsets[k] if k not in c.positions else c.trans[:, j] + np.einsum("nab,nb->na", c.local[:, j],
                                                                                       c.trans[:, k])
    parents = [c.parents[j] if p == j else p for p in c.parents]
    out = replace(c, local=local, trans=trans, offsets=offsets, parents=parents)
    out = _remove(out, [k for k in range(len(c.names)) if k != j])
    out.answer.pop(name, None)
    return out


def rename(c: Clip, names: dict) -> Clip:
    answer = {names.get(n, n): a for n, a in c.answer.items()}
    return replace(c, names=[names.get(n, n) for n in c.names], answer=answer)


def reframe(c: Clip, frames: np.ndarray, axes: np.ndarray | None = None) -> Clip:
    """Each joint's frame turned by frames[j] (J, 3, 3) - new world frame = axes x old world frame x
    frames[j] - and the file's axes turned by `axes` (None: kept): local' = F_par^T local F_j (the root's:
    axes local F_root), translations and OFFSETs' = F_par^T t (the root's: axes t), End Sites' = F_j^T e."""
    axes = np.eye(3) if axes is None else axes
    local, trans, offsets = c.local.copy(), c.trans.copy(), c.offsets.copy()
    for j, par in enumerate(c.parents):
        left = axes if par < 0 else frames[par].T
        local[:, j] = left @ c.local[:, j] @ frames[j]
        trans[:, j] = c.trans[:, j] @ left.T
        offsets[j] = left @ c.offsets[j]
    ends = {j: frames[j].T @ e for j, e in c.ends.items()}
    return replace(c, local=local, trans=trans, offsets=offsets, ends=ends)


def _swing(a, b):
    """(3, 3) the smallest rotation taking direction a to direction b."""
    a, b = np.asarray(a, float) / np.linalg.norm(a), np.asarray(b, float) / np.linalg.norm(b)
    v, s = np.cross(a, b), float(a @ b)
    if s < -1 + 1e-9:
        return Rotation.from_rotvec(np.pi * np.cross(a, [0.0, 0.0, 1.0] if abs(a[2]) < 0.9 else [1.0, 0, 0])
                                    / np.linalg.norm(np.cross(a, [0.0, 0.0, 1.0] if abs(a[2]) < 0.9 else [1.0, 0, 0]))).as_matrix()
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + s)


def bones_along_x(c: Clip) -> np.ndarray:
    """(J, 3, 3) frames putting each joint's bone (to its child of the longest OFFSET, or its End Site)
    along its local +X, as Maya-style exports (LAFAN1, Bandai Namco) write them."""
    out = np.empty((len(c.names), 3, 3))
    for j in range(len(c.names)):
        kids = c.children(j)
        bone = max((c.offsets[k] for k in kids), key=np.linalg.norm) if kids else c.ends.get(j, np.zeros(3))
        out[j] = _swing([1.0, 0.0, 0.0], bone) if np.linalg.norm(bone) > 1e-9 else np.eye(3)
    return out


def scale(c: Clip, s: float) -> Clip:
    return replace(c, offsets=c.offsets * s, trans=c.trans * s, ends={j: e * s for j, e in c.ends.items()})


def static_root(c: Clip, name: str) -> Clip:
    """A joint that never moves (identity rotation, at the origin) above the root, with position channels."""
    n = len(c.local)
    eye = np.broadcast_to(np.eye(3), (n, 1, 3, 3))
    return replace(c, names=[name] + c.names, parents=[-1] + [p + 1 for p in c.parents],
                   offsets=np.vstack([np.zeros(3), c.offsets]), ends={j + 1: e for j, e in c.ends.items()},
                   local=np.concatenate([eye, c.local], axis=1), trans=np.concatenate([np.zeros((n, 1, 3)), c.trans], 1),
                   positions={0} | {j + 1 for j in c.positions}, orders=[c.orders[0]] + c.orders)


def end_joints(c: Clip, suffix: str, only=None) -> Clip:
    """Every End Site (of the joints named in `only`, None: all) turned into a joint <parent><suffix> that
    never rotates, ending in a zero End Site."""
    out = c
    for j in sorted(c.ends):
        if only is not None and c.names[j] not in only:
            continue
        name = c.names[j] + suffix
        out = _add(out, out.index(c.names[j]), name, c.ends[j], np.eye(3), np.zeros(3))
        out.ends.pop(out.index(c.names[j]), None)
    return out


def _add(c: Clip, parent: int, name: str, offset, rotation, end) -> Clip:
    """A joint `name` added as the last child of `parent` (depth-first order kept), constant rotation."""
    at = parent + 1
    while at < len(c.names) and _descends(c, at, parent):
        at += 1
    n = len(c.local)
    parents = [p + (p >= at) for p in c.parents]
    parents.insert(at, parent)
    local = np.insert(c.local, at, np.broadcast_to(rotation, (n, 3, 3)), axis=1)
    trans = np.insert(c.trans, at, np.broadcast_to(offset, (n, 3)), axis=1)
    ends = {j + (j >= at): e for j, e in c.ends.items()}
    ends[at] = np.asarray(end, float)
    return replace(c, names=c.names[:at] + [name] + c.names[at:], parents=parents,
                   offsets=np.insert(c.offsets, at, offset, axis=0), ends=ends, local=local, trans=trans,
                   positions={j + (j >= at) for j in c.positions}, orders=c.orders[:at] + ["ZXY"] + c.orders[at:])


def _descends(c: Clip, j: int, ancestor: int) -> bool:
    while j >= 0:
        if j == ancestor:
            return True
        j = c.parents[j]
    return False


def fingers(c: Clip, hand: str, prefix: str, bone) -> Clip:
    """Five fingers of three joints (Thumb, Index, Middle, Ring, Pinky 1-3) under `hand`, spread across
    the hand's bone `bone` (3,) [units, the hand's frame] and curled 10 degrees per joint."""
    h = c.index(hand)
    bone = np.asarray(bone, float)
    along = bone / np.linalg.norm(bone)
    side = np.cross(along, [0.0, 1.0, 0.0] if abs(along[1]) < 0.9 else [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)
    curl = Rotation.from_rotvec(np.radians(10.0) * side).as_matrix()
    out = replace(c, ends={j: e for j, e in c.ends.items() if j != h})
    for i, finger in enumerate(("Thumb", "Index", "Middle", "Ring", "Pinky")):
        parent = out.index(hand)
        offset = 0.8 * bone + (i - 2) * 0.25 * np.linalg.norm(bone) * side
        for k in range(1, 4):
            name = f"{prefix}{finger}{k}"
            out = _add(out, parent, name, offset, curl, 0.25 * bone if k == 3 else np.zeros(3))
            if k < 3:
                out.ends.pop(out.index(name))
            parent = out.index(name)
            offset = 0.25 * bone
    return out


def resample(c: Clip, fps: float) -> Clip:
    """The motion after the rest frames at `fps` [Hz] (slerp, linear translations); the answer is then
    the clip's own forward kinematics."""
    r = c.rest_frames
    n = len(c.local) - r
    t = np.arange(n) * c.frame_time
    t_new = np.arange(int(np.floor(t[-1] * fps + 1e-9)) + 1) / fps
    local = np.empty((r + len(t_new),) + c.local.shape[1:])
    trans = np.empty((r + len(t_new),) + c.trans.shape[1:])
    local[:r], trans[:r] = c.local[:r], c.trans[:r]
    for j in range(len(c.names)):
        local[r:, j] = Slerp(t, Rotation.from_matrix(c.local[r:, j]))(t_new).as_matrix()
        for k in range(3):
            trans[r:, j, k] = np.interp(t_new, t, c.trans[r:, j, k])
    return replace(c, local=local, trans=trans, frame_time=1.0 / fps)


def without_rest_frame(c: Clip) -> Clip:
    return replace(c, local=c.local[c.rest_frames:], trans=c.trans[c.rest_frames:], rest_frames=0)


def write(c: Clip, path, root_offset_world: bool = False) -> Path:
    """The BVH file of `c` (6 decimals); `root_offset_world`: the root's OFFSET is its first frame's position."""
    lines = ["HIERARCHY"]
    cols = []
    offsets = c.offsets.copy()
    if root_offset_world:
        offsets[0] = c.trans[c.rest_frames, 0]

    def joint(j, depth):
        pad = "  " * depth
        lines.append(f"{pad}{'ROOT' if c.parents[j] < 0 else 'JOINT'} {c.names[j]}")
        chans = (["Xposition", "Yposition", "Zposition"] if j in c.positions else []) + [f"{a}rotation" for a in c.orders[j]]
        lines.extend([f"{pad}{{", f"{pad}  OFFSET " + " ".join(f"{v:.6f}" for v in offsets[j] + 0.0),
                      f"{pad}  CHANNELS {len(chans)} {' '.join(chans)}"])
        if j in c.positions:
            cols.append(c.trans[:, j])
        angles = Rotation.from_matrix(c.local[:, j]).as_euler(c.orders[j], degrees=True)
        cols.append(np.degrees(np.unwrap(np.radians(angles), axis=0)))
        for k in c.children(j):
            joint(k, depth + 1)
        if not c.children(j):
            e = c.ends.get(j, np.zeros(3))
            lines.extend([f"{pad}  End Site", f"{pad}  {{", f"{pad}    OFFSET " + " ".join(f"{v:.6f}" for v in e + 0.0),
                          f"{pad}  }}"])
        lines.append(f"{pad}}}")

    joint(0, 0)
    values = np.concatenate(cols, axis=1) + 0.0
    lines += ["MOTION", f"Frames: {len(values)}", f"Frame Time: {c.frame_time:.7f}"]
    lines += [" ".join(f"{v:.6f}" for v in row) for row in values]
    Path(path).write_text("\n".join(lines) + "\n")
    return Path(path)


# --------------------------------------------------------------------------------------------------
# the conventions
# --------------------------------------------------------------------------------------------------

_CMU_FINGERS = ("LeftFingerBase", "LThumb", "RightFingerBase", "RThumb")


def _sided(names: dict) -> dict:
    """{CMU Left... name: new} for both sides, from names given for the left ({"LeftUpLeg": "UpperLeg_L"})."""
    out = {}
    for old, new in names.items():
        out[old] = new
        out[old.replace("Left", "Right", 1)] = new.replace("_L", "_R").replace("Left", "Right").replace("L_", "R_")
    return out


def lafan1(c: Clip) -> tuple[Clip, dict]:
    for j in ("LHipJoint", "RHipJoint"):
        c = drop(c, j)
    for j in _CMU_FINGERS:
        c = prune(c, j)
    c = rename(c, {"LowerBack": "Spine", "Spine": "Spine1", "Spine1": "Spine2", **_sided({"LeftToeBase": "LeftToe"})})
    c = reframe(c, bones_along_x(c))
    c = scale(c, UNIT / CM)
    c = replace(c, orders=["ZYX"] * len(c.names))
    return without_rest_frame(c), {"unit": CM, "axes": "y", "root_offset_world": True}


def bandai(c: Clip) -> tuple[Clip, dict]:
    for j in ("LHipJoint", "RHipJoint"):
        c = drop(c, j)
    for j in _CMU_FINGERS:
        c = prune(c, j)
    c = rename(c, {"LowerBack": "Spine", "Spine": "Spine1", "Spine1": "Chest", **_sided({
        "LeftShoulder": "Shoulder_L", "LeftArm": "UpperArm_L", "LeftForeArm": "LowerArm_L", "LeftHand": "Hand_L",
        "LeftUpLeg": "UpperLeg_L", "LeftLeg": "LowerLeg_L", "LeftFoot": "Foot_L", "LeftToeBase": "Toes_L"})})
    c = reframe(c, bones_along_x(c))
    c = static_root(c, "joint_Root")
    c = scale(c, UNIT / CM)
    c = replace(c, orders=["ZXY"] * len(c.names), positions=set(range(len(c.names))))
    return without_rest_frame(c), {"unit": CM, "axes": "y"}


def vicon(c: Clip) -> tuple[Clip, dict]:
    c = rename(c, {"Hips": "root", "LowerBack": "lowerback", "Spine": "upperback", "Spine1": "thorax", "Neck": "lowerneck",
                   "Neck1": "upperneck", "Head": "head", "LHipJoint": "lhipjoint", "RHipJoint": "rhipjoint",
                   "LeftUpLeg": "lfemur", "LeftLeg": "ltibia", "LeftFoot": "lfoot", "LeftToeBase": "ltoes",
                   "RightUpLeg": "rfemur", "RightLeg": "rtibia", "RightFoot": "rfoot", "RightToeBase": "rtoes",
                   "LeftShoulder": "lclavicle", "LeftArm": "lhumerus", "LeftForeArm": "lradius", "LeftHand": "lwrist",
                   "LeftFingerBase": "lhand", "LeftHandIndex1": "lfingers", "LThumb": "lthumb",
                   "RightShoulder": "rclavicle", "RightArm": "rhumerus", "RightForeArm": "rradius", "RightHand": "rwrist",
                   "RightFingerBase": "rhand", "RightHandIndex1": "rfingers", "RThumb": "rthumb"})
    c = end_joints(c, "_end")
    c = reframe(c, np.broadcast_to(Y_TO_Z.T, (len(c.names), 3, 3)), axes=Y_TO_Z)
    c = scale(c, 0.7 * UNIT / INCH)  # a child: every length 0.7 of the subject's
    c = replace(c, orders=[ORDERS[j % len(ORDERS)] for j in range(len(c.names))])
    return c, {"unit": INCH, "axes": "z", "size": 0.7, "to_cmu": Y_TO_Z.T}


def rokoko(c: Clip) -> tuple[Clip, dict]:
    for j in ("LHipJoint", "RHipJoint"):
        c = drop(c, j)
    for j in _CMU_FINGERS:
        c = prune(c, j)
    c = rename(c, {"LowerBack": "Spine", "Spine": "Spine1", "Spine1": "Spine2"})
    c = end_joints(c, "_End", only=("Head", "LeftToeBase", "RightToeBase"))
    c = rename(c, {"Head_End": "HeadTop_End", "LeftToeBase_End": "LeftToe_End", "RightToeBase_End": "RightToe_End"})
    top = c.offsets[c.index("HeadTop_End")]  # eyes under the head, static leaves, as Mixamo's characters have them
    for name, side in (("LeftEye", 1.0), ("RightEye", -1.0)):
        offset = 0.5 * top + np.linalg.norm(top) * np.array([0.15 * side, 0.0, 0.4])
        c = _add(c, c.index("Head"), name, offset, np.eye(3), 0.1 * np.linalg.norm(top) * np.array([0.0, 0.0, 1.0]))
    for side in ("Left", "Right"):  # a hand 0.45 of the forearm long, along it (CMU's rest frames are the world's)
        c = fingers(c, f"{side}Hand", f"{side}Hand", 0.45 * c.offsets[c.index(f"{side}Hand")])
    c = rename(c, {n: f"mixamorig:{n}" for n in c.names})
    c = scale(c, UNIT / CM)
    c = replace(c, orders=["YXZ"] * len(c.names))
    return resample(c, 100.0), {"unit": CM, "axes": "y", "resampled": True}


def max3ds(c: Clip) -> tuple[Clip, dict]:
    for j in ("LHipJoint", "RHipJoint", "LowerBack", "Spine", "Neck", "Neck1"):
        c = drop(c, j)
    for j in _CMU_FINGERS:
        c = prune(c, j)
    c = rename(c, {"Spine1": "Spine", **_sided({
        "LeftShoulder": "L_Clavicle", "LeftArm": "L_UpperArm", "LeftForeArm": "L_Forearm", "LeftHand": "L_Hand",
        "LeftUpLeg": "L_Thigh", "LeftLeg": "L_Calf", "LeftFoot": "L_Foot", "LeftToeBase": "L_Toe0"})})
    c = scale(c, UNIT / INCH)
    c = replace(c, orders=["ZXY"] * len(c.names))
    return without_rest_frame(c), {"unit": INCH, "axes": "y", "merged": ("Spine", "Head")}


def ue5(c: Clip) -> tuple[Clip, dict]:
    for j in ("LHipJoint", "RHipJoint"):
        c = drop(c, j)
    for j in _CMU_FINGERS:
        c = prune(c, j)
    c = rename(c, {"Hips": "pelvis", "LowerBack": "spine_01", "Spine": "spine_02", "Spine1": "spine_03", "Neck": "neck_01",
                   "Neck1": "neck_02", "Head": "head", "LeftShoulder": "clavicle_l", "LeftArm": "upperarm_l",
                   "LeftForeArm": "lowerarm_l", "LeftHand": "hand_l", "LeftUpLeg": "thigh_l", "LeftLeg": "calf_l",
                   "LeftFoot": "foot_l", "LeftToeBase": "ball_l", "RightShoulder": "clavicle_r", "RightArm": "upperarm_r",
                   "RightForeArm": "lowerarm_r", "RightHand": "hand_r", "RightUpLeg": "thigh_r", "RightLeg": "calf_r",
                   "RightFoot": "foot_r", "RightToeBase": "ball_r"})
    for bone, child in (("upperarm", "lowerarm"), ("thigh", "calf")):  # twist joints hung beside the next bone
        for side in "lr":
            half = 0.5 * c.offsets[c.index(f"{child}_{side}")]
            c = _add(c, c.index(f"{bone}_{side}"), f"{bone}_twist_01_{side}", half, np.eye(3), np.zeros(3))
    c = reframe(c, bones_along_x(c))
    c = static_root(c, "root")
    ground = np.array([0.0, 0.0, 0.0])
    c = _add(c, 0, "ik_foot_root", ground, np.eye(3), np.zeros(3))
    for side in "lr":
        c = _add(c, c.index("ik_foot_root"), f"ik_foot_{side}", c.offsets[c.index(f"thigh_{side}")], np.eye(3),
                 np.zeros(3))
    c = _add(c, 0, "ik_hand_root", ground, np.eye(3), np.zeros(3))
    c = _add(c, c.index("ik_hand_root"), "ik_hand_gun", np.array([0.0, 20.0, 5.0]), np.eye(3), np.zeros(3))
    for side in "lr":
        c = _add(c, c.index("ik_hand_gun"), f"ik_hand_{side}", np.array([1.0, 0.0, 0.0]), np.eye(3), np.zeros(3))
    c = reframe(c, np.broadcast_to(Y_TO_Z.T, (len(c.names), 3, 3)), axes=Y_TO_Z)
    c = scale(c, UNIT / CM)
    c = replace(c, orders=["XYZ"] * len(c.names))
    return without_rest_frame(c), {"unit": CM, "axes": "z", "to_cmu": Y_TO_Z.T}


CONVENTIONS = {"lafan1": lafan1, "bandai": bandai, "vicon": vicon, "rokoko": rokoko, "max3ds": max3ds, "ue5": ue5}


def convention(src, name: str, out) -> tuple[Path, Clip, dict]:
    """Write the CMU clip `src` onto convention `name` (module docstring) as `out`. Returns (the file,
    the clip as written, notes: "unit" [m per unit], "axes" the up axis, "to_cmu" the rotation from the
    file's axes to CMU's (Y up, subject facing +Z) where they differ, "size" the performer's size
    relative to the subject's, "resampled" (another frame rate), "merged" (joints the convention merges:
    positions above them are not the clip's), "root_offset_world")."""
    c, notes = CONVENTIONS[name](read(src))
    return write(c, out, notes.get("root_offset_world", False)), c, notes
