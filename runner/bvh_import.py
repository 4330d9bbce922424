"""Motion-capture import: a CMU BVH clip retargeted onto the 39-DOF figure, and keyframes picked from it.

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
   times a fixed rest-pose offset R_off (`_rest_offsets`): the smallest rotation that takes the figure
   bone's direction at the identity pose to the CMU bone's direction in the CMU rest (T-) pose (all
   channels zero). So the CMU T-pose maps to the figure with arms out sideways, and with legs and feet
   along the subject's own rest bone directions (the CMU thigh and shin bones point about 20 degrees
   outward in its rest pose, so mapping them to the identity would cross the figure's legs); the
   pelvis and the torso have R_off = identity. Local joint quaternions follow as
   q_joint = conj(q_parent_world) q_child_world, unit, w x y z, hemisphere-consistent over time. The
   figure keeps its own bone lengths; the root position is the CMU Hips position.
4. Clean-up for hard constraints: knee and elbow hyperextension (flexion < 0, see `FLEXION_AXES`) is
   clamped to 0 by removing the twist about the hinge axis (swing-twist decomposition); then the root
   height is corrected (`_correct_root_height`) so that a foot in contact has its lowest contact site
   on the surface under it, and no contact site is ever below a surface.

The synthetic T-pose first frame of the cgspeed BVH conversion is dropped (see
/work/shared/data/cmu/README.md). Data: CMU Graphics Lab Motion Capture Database, mocap.cs.cmu.edu.
"""
from __future__ import annotations

import math
import shlex
import sys
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Iterable, Mapping, Sequence

import numpy as np

from solver.errors import InputError
from solver.keyframes import Keyframes
from solver.layout import StateLayout
from solver.quaternion import align_hemispheres, conj, mul, normalize, twist_angle

# --------------------------------------------------------------------------------------------------
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

#: figure bone directions at the identity pose (body frame = world frame), matching BONE_MAP's CMU
#: bone directions: hip -> knee, knee -> ankle, shoulder -> elbow, elbow -> wrist point straight down;
#: the foot's is ankle -> ball of the foot (0.13 m forward, 0.045 m down), the analogue of the CMU
#: LeftFoot -> LeftToeBase bone.
FIGURE_BONE_DIRECTION: Mapping[str, tuple[float, float, float]] = MappingProxyType(
    {
        "l_thigh": (0.0, 0.0, -1.0),
        "l_shin": (0.0, 0.0, -1.0),
        "l_foot": (0.13, 0.0, -0.045),
        "r_thigh": (0.0, 0.0, -1.0),
        "r_shin": (0.0, 0.0, -1.0),
        "r_foot": (0.13, 0.0, -0.045),
        "l_upper_arm": (0.0, 0.0, -1.0),
        "l_forearm": (0.0, 0.0, -1.0),
        "r_upper_arm": (0.0, 0.0, -1.0),
        "r_forearm": (0.0, 0.0, -1.0),
    }
)

#: figure joint -> (parent body, child body). The root (free joint) drives the pelvis.
JOINT_BODIES: Mapping[str, tuple[str, str]] = MappingProxyType(
    {
        "l_hip": ("pelvis", "l_thigh"),
        "l_knee": ("l_thigh", "l_shin"),
        "l_ankle": ("l_shin", "l_foot"),
        "r_hip": ("pelvis", "r_thigh"),
        "r_knee": ("r_thigh", "r_shin"),
        "r_ankle": ("r_shin", "r_foot"),
        "torso": ("pelvis", "torso"),
        "l_shoulder": ("torso", "l_upper_arm"),
        "l_elbow": ("l_upper_arm", "l_forearm"),
        "r_shoulder": ("torso", "r_upper_arm"),
        "r_elbow": ("r_upper_arm", "r_forearm"),
    }
)

#: hinge-like joints and their flexion axis in the parent frame (models/humanoid39.xml): flexion is
#: `twist_angle(q, axis)`, hyperextension is flexion < 0.
FLEXION_AXES: Mapping[str, tuple[float, float, float]] = MappingProxyType(
    {
        "l_knee": (0.0, 1.0, 0.0),
        "r_knee": (0.0, 1.0, 0.0),
        "l_elbow": (0.0, -1.0, 0.0),
        "r_elbow": (0.0, -1.0, 0.0),
    }
)

#: the figure's contact sites, grouped by foot.
FOOT_SITES: Mapping[str, tuple[str, str]] = MappingProxyType(
    {"left": ("l_heel", "l_toe"), "right": ("r_heel", "r_toe")}
)

#: joints a default partial keyframe fixes: the root and the legs; torso and arms are left free
#: (the optimizer chooses the upper body, the animator pins the stride).
LOWER_BODY_JOINTS: tuple[str, ...] = ("root", "l_hip", "l_knee", "l_ankle", "r_hip", "r_knee", "r_ankle")

#: contact definition (see `contact_mask`): a foot is in contact while its lowest site is at most this
#: high above the surface under it [m] ...
CONTACT_HEIGHT = 0.06
#: ... and that site moves slower than this [m/s].
CONTACT_SPEED = 0.6
#: clearance of the lowest site of a foot in contact after the height correction [m]: a small positive
#: margin so that keyframes, rounded to 6 decimals in a JSON file, never touch below the surface.
CONTACT_CLEARANCE = 0.002

_POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
_ROTATION_CHANNELS = ("Xrotation", "Yrotation", "Zrotation")


# --------------------------------------------------------------------------------------------------
# data
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Reference:
    """A dense reference motion of the figure, retargeted from motion capture.

    Attributes:
        times: (n,) frame times [s], starting at 0, spaced `frame_time`.
        qpos: (n, nq) MuJoCo `qpos` per frame: root position [m], unit quaternions (w x y z),
            hemisphere-consistent over time per joint.
        source: the BVH file it came from.
        frame_time: [s] time between frames of the clip.
    """

    times: np.ndarray
    qpos: np.ndarray
    source: str
    frame_time: float

    @property
    def count(self) -> int:
        return len(self.times)

    @property
    def duration(self) -> float:
        """[s] time of the last frame."""
        return float(self.times[-1])


@dataclass(frozen=True)
class BvhClip:
    """A parsed BVH clip (CMU units, BVH axes), before retargeting.

    Attributes:
        names: the J joint names in file order (depth-first).
        channels: the J joints' channel names, e.g. ("Zrotation", "Yrotation", "Xrotation").
        parents: (J,) parent index of each joint, -1 for the root.
        offsets: (J, 3) joint offsets from the parent [BVH units].
        local_quat: (n, J, 4) local rotation of each joint per frame (w x y z), BVH axes.
        local_pos: (n, J, 3) local translation per frame [BVH units] (the offset, or the position
            channels where a joint has them).
        frame_time: [s] time between frames.
        source: the file.
    """

    names: tuple[str, ...]
    channels: tuple[tuple[str, ...], ...]
    parents: np.ndarray
    offsets: np.ndarray
    local_quat: np.ndarray
    local_pos: np.ndarray
    frame_time: float
    source: str

    def index(self, name: str) -> int:
        return self.names.index(name)


# --------------------------------------------------------------------------------------------------
# parsing
# --------------------------------------------------------------------------------------------------


def _check_bvh_text(text: str, src: str) -> tuple[int, int]:
    """Check the structure of a BVH text enough to give line-numbered errors and to make bvhio safe.

    Checks: HIERARCHY first, ROOT next, the joint grammar (`_check_hierarchy`: braces, OFFSET, CHANNELS
    with matching count and known names, End Site), MOTION, "Frames: N" (N >= 2), "Frame Time: T"
    (T > 0), exactly N data lines each with one finite number per declared channel. After this,
    bvhio's reader cannot run past the end of the file.

    Args:
        text: the file's text. src: the file name for messages.
    Returns:
        (frames, channels): the declared frame count and the total channel count.
    Raises:
        InputError: naming the line, the value and the fix.
    """
    lines = text.splitlines()
    rows = [(i + 1, ln.split()) for i, ln in enumerate(lines) if ln.strip()]
    if not rows:
        raise InputError(f"{src}: the file is empty; a BVH file starts with HIERARCHY and has a MOTION section")
    lineno, tok = rows[0]
    if tok != ["HIERARCHY"]:
        raise InputError(
            f"{src}: line {lineno}: expected 'HIERARCHY', found {' '.join(tok)[:60]!r}; "
            "is this a BVH file? A BVH file starts with HIERARCHY, then ROOT <name>"
        )
    if len(rows) < 2 or rows[1][1][:1] != ["ROOT"] or len(rows[1][1]) != 2:
        ln, t = rows[1] if len(rows) > 1 else (lineno, [])
        raise InputError(f"{src}: line {ln}: expected 'ROOT <name>' after HIERARCHY, found {' '.join(t)!r}")
    channels, motion_at = _check_hierarchy(rows, src)
    rest = rows[motion_at + 1 :]
    if len(rest) < 2:
        raise InputError(
            f"{src}: line {rows[motion_at][0]}: MOTION must be followed by 'Frames: N' and 'Frame Time: T'"
        )
    (ln_f, t_f), (ln_t, t_t) = rest[0], rest[1]
    if len(t_f) != 2 or t_f[0] != "Frames:":
        raise InputError(f"{src}: line {ln_f}: expected 'Frames: N', found {' '.join(t_f)!r}")
    try:
        frames = int(t_f[1])
    except ValueError:
        raise InputError(f"{src}: line {ln_f}: frame count {t_f[1]!r} is not an integer; write 'Frames: N'") from None
    if frames < 2:
        raise InputError(
            f"{src}: line {ln_f}: Frames: {frames}; need at least 2 frames (the first, a T-pose, is dropped)"
        )
    if len(t_t) != 3 or t_t[:2] != ["Frame", "Time:"]:
        raise InputError(f"{src}: line {ln_t}: expected 'Frame Time: T' (seconds), found {' '.join(t_t)!r}")
    try:
        frame_time = float(t_t[2])
    except ValueError:
        frame_time = float("nan")
    if not (math.isfinite(frame_time) and frame_time > 0):
        raise InputError(
            f"{src}: line {ln_t}: Frame Time {t_t[2]!r} is not a positive number of seconds; "
            "e.g. 'Frame Time: .0083333' for 120 frames per second"
        )
    data = rest[2:]
    if len(data) != frames:
        where = f"line {data[-1][0]}" if data else f"line {ln_t}"
        raise InputError(
            f"{src}: {where}: the file has {len(data)} frame lines but line {ln_f} says Frames: {frames}; "
            "fix the count or restore the missing lines (file truncated?)"
        )
    for i, (ln, t) in enumerate(data):
        if len(t) != channels:
            raise InputError(
                f"{src}: line {ln}: frame {i + 1} has {len(t)} values but the HIERARCHY declares {channels} "
                "channels; every frame line needs one number per channel"
            )
        try:
            vals = [float(v) for v in t]
        except ValueError:
            bad = next(v for v in t if not _is_float(v))
            raise InputError(f"{src}: line {ln}: frame {i + 1} has the non-number {bad!r}; use plain numbers") from None
        if not all(math.isfinite(v) for v in vals):
            bad = next(v for v in t if not math.isfinite(float(v)))
            raise InputError(f"{src}: line {ln}: frame {i + 1} has the value {bad!r}; values must be finite")
    return frames, channels


def _check_hierarchy(rows: list[tuple[int, list[str]]], src: str) -> tuple[int, int]:
    """Check the HIERARCHY grammar (recursive descent over the non-empty lines' tokens).

    joint := ('ROOT' | 'JOINT') name '{' 'OFFSET' x y z 'CHANNELS' n names... (joint | end)* '}'
    end   := 'End' 'Site' '{' 'OFFSET' x y z '}'

    Args:
        rows: (line number, tokens) of the non-empty lines; rows[0] is HIERARCHY.
        src: the file name for messages.
    Returns:
        (total channel count, index in rows of the MOTION line).
    Raises:
        InputError: naming the line, what was found and what was expected.
    """
    total = 0
    k = 1  # rows[1] is "ROOT name", checked by the caller

    def row(i):
        if i >= len(rows):
            raise InputError(
                f"{src}: the file ends inside the HIERARCHY (truncated?); close every joint with '}}' and "
                "add the MOTION section"
            )
        return rows[i]

    def fail(i, expected):
        ln, t = row(i)
        found = " ".join(t)[:60]
        raise InputError(f"{src}: line {ln}: expected {expected}, found {found!r}; fix the HIERARCHY there")

    def offset(i):
        ln, t = row(i)
        if t[0] != "OFFSET":
            fail(i, "'OFFSET x y z'")
        if len(t) != 4 or not all(_is_float(v) for v in t[1:]):
            raise InputError(f"{src}: line {ln}: {' '.join(t)!r}: OFFSET takes three numbers, e.g. 'OFFSET 0 -7.5 0'")

    def joint(i):
        nonlocal total
        if row(i)[1] != ["{"]:
            fail(i, "'{' opening the joint")
        offset(i + 1)
        ln, t = row(i + 2)
        if t[0] != "CHANNELS":
            fail(i + 2, "'CHANNELS n ...' after the OFFSET")
        try:
            count = int(t[1])
        except (IndexError, ValueError):
            raise InputError(
                f"{src}: line {ln}: CHANNELS needs a count, got {' '.join(t)!r}; "
                "write e.g. 'CHANNELS 3 Zrotation Yrotation Xrotation'"
            ) from None
        names = t[2:]
        if count != len(names):
            raise InputError(
                f"{src}: line {ln}: CHANNELS says {count} channels but lists {len(names)} "
                f"({' '.join(names)}); make the count match the names"
            )
        for name in names:
            if name not in _POSITION_CHANNELS + _ROTATION_CHANNELS:
                raise InputError(
                    f"{src}: line {ln}: unknown channel {name!r}; channels are "
                    f"{', '.join(_POSITION_CHANNELS + _ROTATION_CHANNELS)}"
                )
        total += count
        i += 3
        while True:
            ln, t = row(i)
            if t[0] == "JOINT" and len(t) == 2:
                i = joint(i + 1)
            elif t == ["End", "Site"]:
                if row(i + 1)[1] != ["{"]:
                    fail(i + 1, "'{' opening the End Site")
                offset(i + 2)
                if row(i + 3)[1] != ["}"]:
                    fail(i + 3, "'}' closing the End Site")
                i += 4
            elif t == ["}"]:
                return i + 1
            else:
                fail(i, "'JOINT <name>', 'End Site' or '}'")

    k = joint(k + 1)
    if k >= len(rows) or rows[k][1][:1] != ["MOTION"]:
        if k >= len(rows):
            raise InputError(
                f"{src}: no MOTION line after the HIERARCHY (file truncated?); a BVH file needs "
                "'MOTION', 'Frames: N', 'Frame Time: T' and N lines of numbers"
            )
        fail(k, "'MOTION' after the ROOT joint's closing '}'")
    if rows[k][1] != ["MOTION"]:
        fail(k, "'MOTION' alone on its line")
    return total, k


def _is_float(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def read_bvh(path: str | Path) -> BvhClip:
    """Read a BVH file: hierarchy, offsets and per-frame local rotations (parsed by `bvhio`).

    Args:
        path: a .bvh file.
    Returns:
        BvhClip with all frames of the file (the T-pose frame included), in BVH units and axes.
    Raises:
        InputError: the file is missing or unreadable, or malformed (the message names the line).
    """
    import warnings

    with warnings.catch_warnings():  # bvhio imports PyGLM as "glm", which PyGLM marks as deprecated
        warnings.simplefilter("ignore", PendingDeprecationWarning)
        import bvhio

    src = str(path)
    p = Path(path)
    if not p.is_file():
        hint = "it is a folder" if p.is_dir() else f"no such file (current folder: {Path.cwd()})"
        raise InputError(f"{src}: cannot read the BVH clip: {hint}; give the path of a .bvh file")
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise InputError(f"{src}: not a text file (byte {e.start} is not UTF-8); give a .bvh motion file") from None
    except OSError as e:
        raise InputError(f"{src}: cannot read the BVH clip: {e.strerror}; check the file's permissions") from None
    _check_bvh_text(text, src)
    try:
        container = bvhio.readAsBvh(str(p))
    except SyntaxError as e:  # not expected after _check_bvh_text; bvhio's own message, no line number
        raise InputError(
            f"{src}: malformed BVH file: {e.args[0] if e.args else e}; check the HIERARCHY and MOTION sections"
        ) from None
    except Exception as e:  # any other failure of the third-party parser on this user file
        raise InputError(f"{src}: malformed BVH file ({type(e).__name__}: {e}); check HIERARCHY and MOTION") from None

    names, channels, parents, offsets, joints = [], [], [], [], []

    def walk(joint, parent):
        names.append(joint.Name)
        channels.append(tuple(joint.Channels))
        parents.append(parent)
        offsets.append(list(joint.Offset))
        joints.append(joint)
        me = len(names) - 1
        for child in joint.Children:
            walk(child, me)

    walk(container.Root, -1)
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputError(f"{src}: joint name(s) {', '.join(dup)} appear more than once; joint names must be unique")
    n = len(joints[0].Keyframes)
    quat = np.empty((n, len(joints), 4))
    pos = np.empty((n, len(joints), 3))
    for j, joint in enumerate(joints):
        quat[:, j] = [list(k.Rotation) for k in joint.Keyframes]  # glm.quat iterates w, x, y, z
        pos[:, j] = [list(k.Position) for k in joint.Keyframes]
    return BvhClip(
        tuple(names),
        tuple(channels),
        np.array(parents, int),
        np.array(offsets, float),
        normalize(quat),
        pos,
        float(container.FrameTime),
        src,
    )



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


def _rest_offsets(clip: BvhClip) -> dict[str, np.ndarray]:
    """Rest-pose offset R_off (unit quaternion) per figure body: figure world = CMU world * R_off.

    For a limb bone, the smallest rotation taking `FIGURE_BONE_DIRECTION` to the CMU bone direction in
    the CMU rest pose (the child joint's OFFSET, in MuJoCo axes); identity for the pelvis and torso.
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
        out[body] = _swing(np.array(FIGURE_BONE_DIRECTION[body]), d_cmu)
    return out


def _required_joints() -> list[str]:
    req = []
    for joint, child in BONE_MAP.values():
        req += [joint] + ([child] if child else [])
    return list(dict.fromkeys(req))


def retarget(clip: BvhClip, layout: StateLayout) -> np.ndarray:
    """Retarget every frame of a clip onto the figure: `qpos` before any clean-up.

    Root position = CMU Hips position [m]; body orientations = CMU bone orientations times the rest
    offsets (module docstring, step 3); joint quaternions relative to the parent body; each joint's
    quaternions hemisphere-aligned over time, the first with w >= 0.

    Args:
        clip: a parsed clip (all frames). layout: the figure's qpos layout.
    Returns:
        (n, nq) qpos.
    Raises:
        InputError: a joint the retargeting needs is missing from the clip, or the Hips has no
            position channels.
    """
    missing = [j for j in _required_joints() if j not in clip.names]
    if missing:
        raise InputError(
            f"{clip.source}: the skeleton has no joint(s) {', '.join(missing)}; the retargeting needs the "
            f"CMU skeleton's {', '.join(_required_joints())} (the cgspeed BVH conversion of "
            "mocap.cs.cmu.edu). Rename the joints of your skeleton to these names"
        )
    if clip.names[0] != "Hips":
        raise InputError(f"{clip.source}: the ROOT joint is {clip.names[0]!r}; the CMU skeleton's root is 'Hips'")
    missing_pos = [c for c in _POSITION_CHANNELS if c not in clip.channels[0]]
    if missing_pos:
        raise InputError(
            f"{clip.source}: the ROOT joint Hips has no {', '.join(missing_pos)} channel(s) (it has "
            f"{' '.join(clip.channels[0]) or 'none'}); the root path needs 'CHANNELS 6 Xposition Yposition "
            "Zposition Zrotation Yrotation Xrotation'"
        )
    qw, pw = cmu_world(clip)
    offsets = _rest_offsets(clip)
    body_q = {b: mul(qw[:, clip.index(j)], offsets[b]) for b, (j, _) in BONE_MAP.items()}
    n = len(qw)
    qpos = np.zeros((n, layout.nq))
    root = layout.joint("root")
    qpos[:, root.qposadr : root.qposadr + 3] = pw[:, clip.index("Hips")]
    qpos[:, root.qposadr + 3 : root.qposadr + 7] = body_q["pelvis"]
    for name, (parent, child) in JOINT_BODIES.items():
        qpos[:, layout.joint(name).qpos_slice] = mul(conj(body_q[parent]), body_q[child])
    return _tidy_quaternions(qpos, layout)


def _tidy_quaternions(qpos: np.ndarray, layout: StateLayout) -> np.ndarray:
    out = qpos.copy()
    for slot in layout.quat_slots:
        q = normalize(out[:, slot])
        if q[0, 0] < 0:
            q = -q
        out[:, slot] = align_hemispheres(q)
    return out


def clamp_hyperextension(qpos: np.ndarray, layout: StateLayout) -> tuple[np.ndarray, int]:
    """Clamp knee and elbow hyperextension to zero flexion.

    Flexion is `twist_angle(q, axis)` with the axes of `FLEXION_AXES`. Where it is negative, the twist
    about the hinge axis is removed: q = s t (swing-twist decomposition, t = normalize(w, (v.a) a)),
    q <- s = q conj(t), which has twist angle exactly 0 and the same swing. Other joints are unchanged.

    Args:
        qpos: (n, nq) with unit quaternions. layout: the figure's layout.
    Returns:
        (clamped qpos (n, nq), number of joint-frames changed).
    """
    out = qpos.copy()
    changed = 0
    for name, axis in FLEXION_AXES.items():
        a = np.array(axis)
        sl = layout.joint(name).qpos_slice
        q = out[:, sl]
        bad = twist_angle(q, a) < 0
        if not bad.any():
            continue
        t = np.concatenate([q[bad, :1], (q[bad, 1:] @ a)[:, None] * a], axis=1)
        t = normalize(t)
        out[np.flatnonzero(bad), sl] = normalize(mul(q[bad], conj(t)))
        changed += int(bad.sum())
    return out, changed


# --------------------------------------------------------------------------------------------------
# feet and surfaces
# --------------------------------------------------------------------------------------------------


def surface_height_under(points: np.ndarray, surfaces) -> np.ndarray:
    """Height of the highest static surface under each point (floor planes, tops of boxes).

    A plane counts everywhere (its height at the point's x, y); a box counts where the point's x, y lie
    within its footprint, with its top face as the surface. Boxes are assumed upright (any rotation
    about z only), as the step box of models/run_and_step.xml is.

    Args:
        points: (..., 3) positions [m].
        surfaces: solver.surfaces.StaticSurfaces of the scene.
    Returns:
        (...,) surface height [m]; -inf where there is no surface at all.
    """
    pts = np.asarray(points, float)
    h = np.full(pts.shape[:-1], -np.inf)
    for p0, nrm in zip(surfaces.plane_point, surfaces.plane_normal):
        if abs(nrm[2]) < 1e-6:
            continue  # a vertical plane (a wall) has no height
        z = p0[2] - (nrm[0] * (pts[..., 0] - p0[0]) + nrm[1] * (pts[..., 1] - p0[1])) / nrm[2]
        h = np.maximum(h, z)
    for c, rot, half in zip(surfaces.box_center, surfaces.box_rot, surfaces.box_half):
        local = (pts - c) @ rot  # box coordinates
        inside = (np.abs(local[..., 0]) <= half[0]) & (np.abs(local[..., 1]) <= half[1])
        top = c[2] + np.abs(rot[2]) @ half
        h = np.where(inside, np.maximum(h, top), h)
    return h


class _SiteKinematics:
    """Contact-site positions of the figure over a motion, by MuJoCo forward kinematics."""

    def __init__(self, model):
        import mujoco

        from solver.surfaces import StaticSurfaces

        self.model = model
        self.data = mujoco.MjData(model)
        self.surfaces = StaticSurfaces.from_model(model, self.data)
        self.names = [s for foot in FOOT_SITES.values() for s in foot]
        ids = []
        for s in self.names:
            sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s)
            if sid < 0:
                raise InputError(
                    f"the model has no site {s!r}; the figure needs contact sites "
                    f"{', '.join(self.names)} (models/humanoid39.xml)"
                )
            ids.append(sid)
        self.ids = np.array(ids)

    def positions(self, qpos: np.ndarray) -> np.ndarray:
        """(n, 4, 3) world positions [m] of l_heel, l_toe, r_heel, r_toe for (n, nq) qpos."""
        import mujoco

        qpos = np.atleast_2d(qpos)
        out = np.empty((len(qpos), len(self.ids), 3))
        for i, q in enumerate(qpos):
            self.data.qpos[:] = q
            mujoco.mj_kinematics(self.model, self.data)
            out[i] = self.data.site_xpos[self.ids]
        return out

    def clearance(self, pos: np.ndarray) -> np.ndarray:
        """(n, 4) height [m] of each site above the surface under it (negative: below the surface)."""
        return pos[..., 2] - surface_height_under(pos, self.surfaces)


def _foot_contact(pos: np.ndarray, clear: np.ndarray, frame_time: float, height: float, speed: float):
    """Per foot: the lowest site's clearance, and whether the foot is in contact.

    Returns:
        lowest: (n, 2) clearance [m] of each foot's lowest site (feet in FOOT_SITES order).
        contact: (n, 2) bool, lowest clearance < `height` and that site's speed < `speed`.
    """
    vel = np.gradient(pos, frame_time, axis=0) if len(pos) > 1 else np.zeros_like(pos)
    spd = np.linalg.norm(vel, axis=-1)  # (n, 4)
    lowest = np.empty((len(pos), 2))
    contact = np.empty((len(pos), 2), bool)
    for f in range(2):
        c = clear[:, 2 * f : 2 * f + 2]
        k = np.argmin(c, axis=1)
        rows = np.arange(len(pos))
        lowest[:, f] = c[rows, k]
        contact[:, f] = (lowest[:, f] < height) & (spd[:, 2 * f : 2 * f + 2][rows, k] < speed)
    return lowest, contact


def contact_mask(qpos: np.ndarray, model, frame_time: float, height: float = CONTACT_HEIGHT,
                 speed: float = CONTACT_SPEED) -> tuple[np.ndarray, np.ndarray]:
    """Which foot is in contact in each frame of a dense motion, and its lowest site's clearance.

    Contact definition: a foot (heel and toe site) is in contact while its lowest site is less than
    `height` above the surface under it (floor, or the top of a box whose footprint contains the site;
    `surface_height_under`) and that site moves slower than `speed` (central differences over frames).

    Args:
        qpos: (n, nq) motion sampled every `frame_time` seconds. model: the scene's MjModel (figure
            plus static surfaces). frame_time: [s]. height: [m]. speed: [m/s].
    Returns:
        contact: (n, 2) bool, left and right foot.
        lowest: (n, 2) clearance [m] of each foot's lowest site (negative: below the surface).
    Raises:
        InputError: the model lacks the contact sites.
    """
    kin = _SiteKinematics(model)
    pos = kin.positions(qpos)
    lowest, contact = _foot_contact(pos, kin.clearance(pos), frame_time, height, speed)
    return contact, lowest


def worst_contact_distance(reference: Reference, model, height: float = CONTACT_HEIGHT,
                           speed: float = CONTACT_SPEED) -> float:
    """Acceptance figure: the worst |clearance| of a foot's lowest contact site while it is in contact.

    Over all frames and both feet in contact (`contact_mask`), the largest distance between the foot's
    lowest site (heel or toe) and the surface under it, above or below. Should be <= 0.03 m.

    Args:
        reference: the motion. model: the scene's MjModel. height [m], speed [m/s]: the contact
            definition of `contact_mask`.
    Returns:
        distance [m]; 0.0 if no foot is ever in contact.
    """
    contact, lowest = contact_mask(reference.qpos, model, reference.frame_time, height, speed)
    if not contact.any():
        return 0.0
    return float(np.max(np.abs(lowest[contact])))


def _correct_root_height(qpos: np.ndarray, model, frame_time: float) -> np.ndarray:
    """Shift the root height per frame so feet in contact stand on the surfaces, and nothing sinks.

    1. Contact frames (`_foot_contact` with a wide height window of 0.15 m: the retargeted feet can be
       several cm off before the correction): dz = CONTACT_CLEARANCE - lowest clearance of the feet
       in contact, so the lowest contact site of a standing foot ends `CONTACT_CLEARANCE` above its
       surface.
    2. Frames without contact (flight): dz interpolated linearly between the neighbouring contact
       frames (held constant before the first and after the last).
    3. dz smoothed over 9 frames (a moving average), then raised where needed so that every contact
       site of every frame is at least `CONTACT_CLEARANCE` above the surface under it.

    Args:
        qpos: (n, nq) retargeted motion. model: the scene's MjModel. frame_time: [s].
    Returns:
        (n, nq) qpos with the root z changed.
    """
    kin = _SiteKinematics(model)
    pos = kin.positions(qpos)
    clear = kin.clearance(pos)
    lowest, contact = _foot_contact(pos, clear, frame_time, height=0.15, speed=CONTACT_SPEED)
    n = len(qpos)
    frames = np.arange(n)
    on = contact.any(axis=1)
    if on.any():
        target = CONTACT_CLEARANCE - np.where(contact, lowest, np.inf).min(axis=1)
        dz = np.interp(frames, frames[on], target[on])
    else:
        dz = np.zeros(n)
    width = min(9, n if n % 2 else n - 1)
    if width >= 3:
        pad = width // 2
        dz = np.convolve(np.pad(dz, pad, mode="edge"), np.ones(width) / width, mode="valid")
    floor = CONTACT_CLEARANCE - clear.min(axis=1)
    dz = np.maximum(dz, floor)
    out = qpos.copy()
    out[:, 2] += dz
    return out


# --------------------------------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------------------------------


def load_bvh_reference(path: str | Path, model) -> Reference:
    """Read a CMU BVH clip and retarget it onto the figure: the dense reference motion.

    Steps (module docstring): parse (bvhio), drop the synthetic T-pose first frame, forward kinematics
    in metres and MuJoCo axes, rest-offset retargeting of body orientations, local joint quaternions
    (unit, w x y z, hemisphere-consistent), knee/elbow hyperextension clamped to 0 flexion
    (`clamp_hyperextension`), root height corrected so feet in contact stand on the floor or the box
    and no contact site is ever below a surface (`_correct_root_height`).

    Args:
        path: a BVH file with the CMU skeleton (Hahne's cgspeed conversion, 31 joints, 1 unit =
            0.05644 m, first frame a T-pose).
        model: the scene's MjModel (figure + floor + step box), e.g. models/run_and_step.xml; its
            figure must be models/humanoid39.xml (joint and site names). With a model that has no
            static surfaces (the figure alone) the root height is left as retargeted.
    Returns:
        Reference with times (n,) [s] from 0, qpos (n, nq), source = str(path), frame_time [s];
        n = frames in the file - 1.
    Raises:
        InputError: missing/unreadable file, malformed BVH (line named), wrong channel count, a
            joint the retargeting needs is missing, or the model lacks a joint or site it needs.
    """
    clip = read_bvh(path)
    layout = StateLayout.from_model(model)
    for name in ("root", *JOINT_BODIES):
        layout.joint(name)
    qpos = retarget(clip, layout)[1:]  # frame 0 is the synthetic T-pose
    qpos, _ = clamp_hyperextension(qpos, layout)
    qpos = _correct_root_height(qpos, model, clip.frame_time)
    qpos = _tidy_quaternions(qpos, layout)
    times = np.arange(len(qpos)) * clip.frame_time
    return Reference(times, qpos, str(path), clip.frame_time)


#: default `partial` argument of `keyframes_from_reference`: the middle keyframe fixes only the root and
#: the legs.
MIDDLE_LOWER_BODY = "middle"


def keyframe_indices(reference: Reference, every: float = 0.25) -> np.ndarray:
    """Frame indices an animator would key: evenly about every `every` seconds, first and last included.

    The clip's duration T is cut into round(T / every) equal intervals (at least one); each key is the
    frame nearest an interval end, so every gap is within a frame of T / round(T / every) (for a
    clip longer than every, between 2/3 and 4/3 of `every`).

    Args:
        reference: the dense motion. every: [s] spacing, > 0.
    Returns:
        (k,) strictly increasing frame indices, k >= 2, first 0, last n - 1.
    Raises:
        InputError: `every` is not a positive number, or the clip is shorter than two frames.
    """
    if isinstance(every, bool) or not (isinstance(every, (int, float)) and math.isfinite(every) and every > 0):
        raise InputError(f"keyframe spacing every={every!r}; give a positive number of seconds, e.g. 0.25")
    if reference.count < 2:
        raise InputError(f"{reference.source}: the clip has {reference.count} frame(s); need at least 2")
    T = reference.duration
    intervals = max(1, int(round(T / every)))
    idx = np.rint(np.linspace(0.0, T, intervals + 1) / reference.frame_time).astype(int)
    return np.unique(np.clip(idx, 0, reference.count - 1))


def keyframes_from_reference(
    reference: Reference,
    model,
    every: float = 0.25,
    partial: Mapping[int, Iterable[str]] | str = MIDDLE_LOWER_BODY,
) -> Keyframes:
    """Keyframes from a dense reference motion, as an animator would set them.

    Full keyframes at `keyframe_indices(reference, every)`; the keyframes listed in `partial` fix only
    the named joints (all components of each), the rest of the figure is free for the optimizer.

    Args:
        reference: the dense motion (`load_bvh_reference`).
        model: the figure's or scene's MjModel (for the qpos layout).
        every: [s] keyframe spacing (about 0.2-0.3 s for a run).
        partial: "middle" (default): the middle keyframe (index k // 2) fixes only `LOWER_BODY_JOINTS`
            (root and legs; torso and arms free). Or a mapping {keyframe index: joint names it fixes};
            {} for full keyframes only.
    Returns:
        solver.Keyframes with times (k,) [s] and values/mask (k, nq); source = reference.source.
    Raises:
        InputError: bad `every`, a partial keyframe index out of range, or an unknown joint name.
    """
    layout = StateLayout.from_model(model)
    idx = keyframe_indices(reference, every)
    k = len(idx)
    if isinstance(partial, str):
        if partial != MIDDLE_LOWER_BODY:
            raise InputError(f"partial={partial!r}; give 'middle' or a mapping {{keyframe index: joint names}}")
        partial = {k // 2: LOWER_BODY_JOINTS} if k > 2 else {}
    values = reference.qpos[idx].copy()
    mask = np.ones_like(values, bool)
    for i, names in dict(partial).items():
        if not (isinstance(i, (int, np.integer)) and 0 <= i < k):
            raise InputError(f"partial keyframe index {i!r} is out of range; there are {k} keyframes (0..{k - 1})")
        mask[i] = False
        for name in names:
            mask[i, layout.joint(name).qpos_slice] = True
    return Keyframes(reference.times[idx], values, mask, source=reference.source)


# --------------------------------------------------------------------------------------------------
# command line
# --------------------------------------------------------------------------------------------------

_DEFAULT_PROG = (
    'python -c "import sys; from runner.bvh_import import keyframes_from_bvh_main as m; '
    'sys.exit(m(sys.argv[1:]))"'
)
_MODELS = Path(__file__).resolve().parents[1] / "models"


def keyframes_from_bvh_main(argv: Sequence[str] | None = None, prog: str | None = None, debug: bool = False) -> int:
    """`keyframes-from-bvh`: write a keyframe file (runner/keyframe_io.py format) made from a BVH clip.

    Arguments: CLIP (a .bvh file), --out FILE (.keyframes.json), --every SECONDS (0.25), --scene MJCF
    (models/run_and_step.xml), --model MJCF (the figure, default humanoid39.xml beside the scene).
    The written file records the exact command (`prog` followed by the arguments) in "source".

    Args:
        argv: the arguments (without the program name); None = sys.argv[1:].
        prog: how the command was invoked, for the record; default: the `python -c` form above.
        debug: re-raise an InputError (its traceback) instead of printing its message.
    Returns:
        0 on success, 2 on bad input (the message goes to stderr).
    """
    import mujoco

    from runner.keyframe_io import write_keyframes

    argv = list(sys.argv[1:] if argv is None else argv)
    from runner.cli import OneLineParser

    ap = OneLineParser(
        prog=prog or "keyframes-from-bvh",
        description="Make a keyframe file from a CMU BVH clip retargeted onto the figure.",
    )
    ap.add_argument("clip", help="BVH clip (CMU skeleton), e.g. models/cmu/127_33.bvh")
    ap.add_argument("--out", required=True, help="keyframe file to write (.keyframes.json)")
    ap.add_argument("--every", type=float, default=0.25, help="keyframe spacing [s] (default 0.25)")
    ap.add_argument("--scene", default=str(_MODELS / "run_and_step.xml"), help="scene MJCF (figure + surfaces)")
    ap.add_argument("--model", default=None, help="figure MJCF (default: humanoid39.xml beside the scene)")
    try:
        args = ap.parse_args(argv)
    except SystemExit as e:  # --help (0) or a usage error (2, its one-line message printed)
        return e.code if isinstance(e.code, int) else 2
    try:
        scene = Path(args.scene)
        if not scene.is_file():
            raise InputError(f"{scene}: no such scene file; give an MJCF scene with --scene")
        figure = Path(args.model) if args.model else scene.parent / "humanoid39.xml"
        try:
            model = mujoco.MjModel.from_xml_path(str(scene))
        except ValueError as e:
            raise InputError(f"{scene}: MuJoCo cannot load the scene: {e}") from None
        reference = load_bvh_reference(args.clip, model)
        keyframes = keyframes_from_reference(reference, model, every=args.every)
        out = Path(args.out)
        source = {
            "clip": _relpath(Path(args.clip), out.parent),
            "command": f"{prog or _DEFAULT_PROG} {shlex.join(argv)}",
            "hand_edits": "none",
        }
        write_keyframes(out, keyframes, StateLayout.from_model(model), model=figure, scene=scene, source=source)
    except InputError as e:
        if debug:
            raise
        print(f"dynsplines: error: {e}", file=sys.stderr)
        return 2
    print(
        f"wrote {args.out}: {keyframes.count} keyframes at {', '.join(f'{t:.3f}' for t in keyframes.times)} s "
        f"({int(keyframes.is_partial.sum())} partial) from {reference.count} frames of {args.clip}"
    )
    return 0


def _relpath(path: Path, start: Path) -> str:
    import os

    return Path(os.path.relpath(path.resolve(), start.resolve())).as_posix()
