"""Skeleton recognition: which joint of a BVH clip plays which role, in what unit, with which axis up.

A BVH clip of any common convention goes in without user action (docs/mocap.md, "Skeletons of any
convention"). `recognise` finds, from the hierarchy and the motion (never from a rest pose, which in
many conventions is not a standing pose: LAFAN1's and Bandai Namco's bones all lie along local +X
with every channel zero):

* **the roles** (runner/capture/skeleton_map.py `ROLES`) from the tree: the hips are the first joint from
  the root whose branches are an upper body (the branch with the most end points) and two legs (two
  consecutive bones of comparable length; a static extra root above them, or IK targets hung from the
  root, are passed through); the chest
  is the upper body's first branching joint, its two farthest-reaching branches are the arms and the
  remaining one (or the one named neck or head) the neck and head (where it has two branches, the head's and
  a chain to the joint the arms hang from, Biovision-style, those arms), its chain up to the last joint named
  neck, head or skull where one is (Mixamo's eyes under the head are the head's). Along a limb the knee or elbow is
  the first joint whose name says so (LeftLeg, LowerLeg_L, Calf, Knee; ForeArm, LowerArm_L, Elbow);
  without such a name the hand is where the fingers branch off, or else the upper and lower bone are
  the two consecutive bones of the largest summed length (thigh + shin, upper arm + forearm), so that a
  hip offset or a clavicle before them is passed over; the foot and toe (the hand) follow. End joints (a leaf named ...End, ...Nub, ...Tip or ...Top)
  only mark where a bone ends. Left and right come from the names (Left, _L, L_, l...) or, where the names do not say,
  from the geometry: the left limb is on the side of up x forward, forward being where the feet point.
* **the length unit** from the legs: of metres, centimetres, millimetres, inches (and, for the CMU
  skeleton's names, the CMU ASF unit), the one whose stature (leg / 0.491, Winter 2009 fig. 4.1) is a
  person's, 0.8-2.4 m, nearest 1.75 m.
* **the up axis**: the file axis nearest the mean direction from the ankles to the chest over the clip.
* **leading rest frames**: a first frame that jumps to another pose (a T-pose the exporter put
  before the motion, as CMU's cgspeed conversion does: always, for a clip with its names) is not part
  of the motion (`REST_JUMP`).

A skeleton map file (`--skeleton-map FILE`) names the joint of any role, the unit, the up axis or the
leading rest frames, and wins over what is found. What cannot be found is one line naming the roles and the fix.
"""
from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from runner.capture.bvh import POSITION_CHANNELS, BvhClip
from runner.capture.bvh_kinematics import bone_length, file_world, reach, tip_positions, to_mujoco
from runner.capture.skeleton_map import OPTIONAL, ROLES, UNITS, SkeletonMap
from solver.errors import InputError

__all__ = ["RecognisedSkeleton", "recognise", "skeleton_world", "name_side", "unit_note"]

#: [m] a person's leg, hip to ankle joint centre, is 0.491 of stature (Winter, "Biomechanics and Motor
#: Control of Human Movement", 2009, fig. 4.1: hip 0.530 H, ankle 0.039 H above the sole)
LEG_OF_STATURE = 0.491
#: [m] the statures a performer may have (a small child to the tallest adults) and the typical one
STATURES = (0.8, 2.4, 1.75)
#: a first frame is a separate pose (a T-pose put before the motion) when its step to the next frame, or
#: the change of step there (relative to the hips, the largest over the joints), is more than this many
#: times the clip's 99th percentile: a synthetic T-pose gives 7-100 at 120 fps and 2.1-47 at 15-30 fps
#: on the shipped clips, a first frame of motion at most 0.8
REST_JUMP = 2.0
#: names, as written, that only the CMU skeleton's BVH files use (cgspeed's conversion): they allow its
#: length unit, and mark a first frame as the conversion's synthetic T-pose
CMU_NAMES = frozenset({"LHipJoint", "RHipJoint", "LowerBack", "LeftFingerBase", "RightFingerBase"})
_END = re.compile(r"(end|nub|tip|top|site)$", re.IGNORECASE)
_UPPER = re.compile(r"spine|back|chest|torso|thorax|abdomen|neck|head|clav|collar|arm", re.IGNORECASE)
_HEADLIKE = re.compile(r"neck|head|skull", re.IGNORECASE)
_TWIST = re.compile(r"twist|roll", re.IGNORECASE)
_BONES = ("femur|tibia|foot|toes?|clavicle|humerus|radius|wrist|hand|hip|knee|ankle|shoulder|elbow|thigh|"
          "upleg|leg|arm|forearm|collar|calf|shin|fingers|thumb")
_LEFT = re.compile(rf"^(left.*|l|lft|l({_BONES}).*)$")
_RIGHT = re.compile(rf"^(right.*|r|rt|r({_BONES}).*)$")


@dataclass(frozen=True)
class RecognisedSkeleton:
    """A clip's skeleton as the figure reads it (module docstring).

    Attributes:
        roles: {role: joint name}; the optional roles (`OPTIONAL`) may be absent.
        unit: [m] per file unit. unit_name: "cm", "inch", ... or the number a map gave.
        axes: (3, 3) rotation from the file's axes to MuJoCo's (z up): v_mujoco = axes @ v_file.
        up: the file axis that points up ("y", "-z", ...).
        position_joints: the joints with position channels (their translation is the channels'); none at or
            above the hips: the root stands at its OFFSET (three.js's pirouette.bvh).
        above_hips: the joints above the hips (a static extra root), root first.
        rest_frames: leading frames that are not motion (0, or 1 for a T-pose put before it).
        rest_given: rest_frames came from a skeleton map (recorded in `skeleton_map`), not found.
        how: how the roles were found ("the hierarchy and names", or with the map file named).
        source: the clip file.
        unit_assumed: None, or why the unit is a typical subject's: no unit makes the subject a person
            (`unit_note`).
    """

    roles: Mapping[str, str]
    unit: float
    unit_name: str
    axes: np.ndarray
    up: str
    position_joints: tuple[str, ...]
    above_hips: tuple[str, ...]
    rest_frames: int
    how: str
    source: str
    rest_given: bool = False
    unit_assumed: str | None = None

    def joint(self, role: str) -> str:
        """The joint of `role`; an absent spine is the chest, an absent neck the head."""
        fallback = {"spine": "chest", "neck": "head"}
        return self.roles[role] if role in self.roles else self.roles[fallback[role]]

    def index(self, clip: BvhClip, role: str) -> int:
        return clip.index(self.joint(role))

    def skeleton_map(self) -> SkeletonMap:
        """The complete map (every role found, unit, up): recognising with it gives this skeleton again."""
        return SkeletonMap(dict(self.roles), self.unit, self.unit_name, self.up, self.source,
                           self.rest_frames if self.rest_given else None, self.unit_assumed)


def skeleton_world(clip: BvhClip, skel: RecognisedSkeleton) -> tuple[np.ndarray, np.ndarray]:
    """World orientation (n, J, 4) (w x y z) and position (n, J, 3) [m] of every joint, in MuJoCo axes
    (z up): R' = A R A^T, p' = unit A p with A = skel.axes. Every frame of the file."""
    q, p = file_world(clip)
    return to_mujoco(q, skel.axes), (p @ skel.axes.T) * skel.unit


# --------------------------------------------------------------------------------------------------
# the tree
# --------------------------------------------------------------------------------------------------


def _children(clip: BvhClip) -> list[list[int]]:
    """Child joints of each joint, end joints left out (`_is_end`)."""
    kids: list[list[int]] = [[] for _ in clip.names]
    for j, par in enumerate(clip.parents):
        if par >= 0 and not _is_end(clip, j):
            kids[par].append(j)
    return kids


def _is_end(clip: BvhClip, j: int) -> bool:
    """An end joint: a leaf that only marks where its parent's bone ends, named so (...End, ...Nub, ...Tip,
    ...Top, ...Site: HeadTop_End, LeftToe_End, Bip01 L Toe0Nub)."""
    if j in np.asarray(clip.parents) or clip.parents[j] < 0:
        return False
    return bool(_END.search(clip.names[j]))


def _leaves(children, j: int) -> int:
    return 1 if not children[j] else sum(_leaves(children, c) for c in children[j])


def _descend(children, j: int) -> int:
    """The first joint at or below j with more than one child."""
    while len(children[j]) == 1:
        j = children[j][0]
    return j


def _chain(clip: BvhClip, children, j: int) -> list[int]:
    """The joints from j along its longest path to an end."""
    out = [j]
    while children[out[-1]]:
        out.append(max(children[out[-1]], key=lambda c: bone_length(clip, c) + reach(clip, children, c)))
    return out


def _limb(clip: BvhClip, children, chain: list[int], leg: bool) -> dict[str, int]:
    """Upper, lower, foot|hand (and toe) joints of a limb chain: the lower joint is the first whose name
    says knee or forearm (`_is_lower`); without such a name, on an arm, the hand is the first joint where
    fingers branch off (twist joints beside a bone not counted); else the upper and lower bones are the
    two consecutive ones of the largest summed length."""
    if len(chain) < 3:
        return {}
    named = [k for k, j in enumerate(chain) if _is_lower(clip.names[j], leg)]
    fingers = [k for k, j in enumerate(chain) if len([c for c in children[j] if not _TWIST.search(clip.names[c])]) > 1]
    if named and 1 <= named[0] <= len(chain) - 2:
        i = named[0] - 1
    elif not leg and fingers and fingers[0] >= 2:  # the hand: where the fingers branch off
        i = fingers[0] - 2
    else:
        lengths = [bone_length(clip, chain[k + 1]) for k in range(len(chain) - 1)]
        i = max(range(len(chain) - 2), key=lambda k: lengths[k] + lengths[k + 1])
    names = ("upper_leg", "lower_leg", "foot", "toe") if leg else ("upper_arm", "forearm", "hand")
    return {name: chain[i + k] for k, name in enumerate(names) if i + k < len(chain)}


def _is_lower(name: str, leg: bool) -> bool:
    """The name says knee / lower leg (leg) or elbow / forearm (arm): LeftLeg, LowerLeg_L, Bip01 L Calf,
    RightKnee, ltibia; LeftForeArm, LowerArm_L, LeftElbow, lradius."""
    t = set(_tokens(name))
    if leg:
        return bool(t & {"knee", "calf", "shin", "lowerleg"}) or any(w.endswith("tibia") for w in t) or (
            "leg" in t and not t & {"up", "upper", "thigh", "hip"})
    return bool(t & {"fore", "forearm", "elbow", "lowerarm"}) or any(w.endswith("radius") for w in t) or (
        "arm" in t and "lower" in t)


def _limb_like(clip: BvhClip, chain: list[int]) -> bool:
    """The chain has two consecutive bones of comparable length (the shorter at least half the longer),
    as a thigh and shin: not a helper chain (an IK target hung from the root, a prop)."""
    lengths = [bone_length(clip, j) for j in chain[1:]]
    return any(min(a, b) > 0 and min(a, b) >= 0.5 * max(a, b) for a, b in zip(lengths, lengths[1:]))


def _hips(clip: BvhClip, children) -> tuple[int, int, list[int]] | None:
    """(hips, the upper body's branch, the two legs' branches): going down from the root, the first joint
    with two limb-like branches besides the one with the most end points (the upper body); a joint whose
    other branches are not limbs (IK targets, props hung from a root) is passed down into that branch.
    Without any, the first joint with two branches besides the upper body's (a degenerate leg is then
    named by the bone checks of runner/capture/body_frames.py)."""
    score = lambda c: (_leaves(children, c), bool(_UPPER.search(clip.names[c])), reach(clip, children, c))  # noqa: E731

    def split(node):
        upper = max(children[node], key=score)
        rest = [c for c in children[node] if c != upper]
        if len(rest) == 1:  # the legs branch off a joint of their own below the hips
            rest = children[_descend(children, rest[0])]
        return upper, sorted(rest, key=lambda c: reach(clip, children, c), reverse=True)[:2]

    node = first = _descend(children, 0)
    while len(children[node]) >= 2:
        upper, legs = split(node)
        if len(legs) == 2 and _leaves(children, upper) >= 3 and all(
                _limb_like(clip, _chain(clip, children, c)) for c in legs):  # the upper body ends in hands and head
            return node, upper, legs
        node = _descend(children, upper)
    if len(children[first]) < 2:
        return None
    upper, legs = split(first)
    return (first, upper, legs) if len(legs) == 2 else None


def _upper_branches(children, chest: int) -> list[int]:
    """The branches of the arms and the head at the chest: its children, or where it has two, one the head's
    (fewer ends) and one a chain to a joint with the two arms (a Biovision-style Chest -> Chest2 -> collars
    beside Chest -> Neck -> Head), the two arms' and the head's: the chest is then where the head and the arms
    part, below the joint the arms hang from."""
    kids = list(children[chest])
    if len(kids) == 2:
        for arms, head in (kids, kids[::-1]):
            below = _descend(children, arms)
            if len(children[below]) == 2 and _leaves(children, head) < _leaves(children, arms):
                return list(children[below]) + [head]
    return kids


def _structure(clip: BvhClip) -> tuple[dict[str, int], list[dict[str, int]], list[dict[str, int]]]:
    """The trunk roles {role: joint} and the two legs' and two arms' roles, unsided (module docstring);
    what is not found is left out."""
    children = _children(clip)
    trunk: dict[str, int] = {}
    found = _hips(clip, children)
    if found is None:
        return trunk, [], []
    hips, upper, legs = found
    trunk["hips"] = hips
    legs = [_limb(clip, children, _chain(clip, children, c), leg=True) for c in legs]
    chest = _descend(children, upper)
    branches = _upper_branches(children, chest)
    arms: list[dict[str, int]] = []
    if len(branches) >= 3:
        named = [c for c in branches if _HEADLIKE.search(clip.names[c])]
        by_reach = sorted(branches, key=lambda c: reach(clip, children, c), reverse=True)
        head = named[0] if len(named) == 1 else by_reach[2]
        arms = [_limb(clip, children, _chain(clip, children, c), leg=False) for c in by_reach if c != head][:2]
        head_chain = _chain(clip, children, head)
        named = [k for k, j in enumerate(head_chain) if _HEADLIKE.search(clip.names[j])]
        if named:  # the head is the last joint named so: past it are the head's own parts (Mixamo's eyes, a jaw)
            head_chain = head_chain[: named[-1] + 1]
        trunk["chest"] = chest
        trunk["head"] = head_chain[-1]
        if len(head_chain) > 1:
            trunk["neck"] = head_chain[0]
        path = [chest]
        while clip.parents[path[-1]] != hips:
            path.append(int(clip.parents[path[-1]]))
        if path[-1] != chest:
            trunk["spine"] = path[-1]
    return trunk, legs, arms


# --------------------------------------------------------------------------------------------------
# sides, unit, up, rest frames
# --------------------------------------------------------------------------------------------------


def _tokens(name: str) -> list[str]:
    """Words of a joint name: split at non-letters and at case changes ("mixamorig:LeftUpLeg" -> mixamorig,
    left, up, leg; "UpperLeg_L" -> upper, leg, l; "LThigh" -> l, thigh)."""
    spaced = re.sub(r"(?<=[a-z0-9])(?=[A-Z])|(?<=[A-Z])(?=[A-Z][a-z])", " ", name)
    return [t.lower() for t in re.split(r"[^A-Za-z0-9]+", spaced) if t]


def name_side(names: list[str]) -> str | None:
    """"l", "r" or None: the side the joint names of one limb say (more of one side than the other)."""
    left = right = 0
    for name in names:
        words = _tokens(name) + [re.sub(r"[^a-z]", "", name.lower())]
        left += any(_LEFT.match(w) for w in words)
        right += any(_RIGHT.match(w) for w in words)
    return "l" if left > right else "r" if right > left else None


def _up_axis(direction: np.ndarray) -> tuple[str, np.ndarray]:
    """The file axis nearest the (3,) up direction, and the rotation taking file axes to MuJoCo's: the
    up axis to z by a cyclic permutation (Y up: Z, X -> x, y, as CMU's files map to MuJoCo; Z up: the
    identity), a downward axis turned over about the new x."""
    k = int(np.argmax(np.abs(direction)))
    sign = 1.0 if direction[k] > 0 else -1.0
    perm = np.zeros((3, 3))
    for row, col in enumerate(((k + 1) % 3, (k + 2) % 3, k)):
        perm[row, col] = 1.0
    if sign < 0:
        perm = np.diag([1.0, -1.0, -1.0]) @ perm
    return ("" if sign > 0 else "-") + "xyz"[k], perm


def _axes_of(up: str) -> np.ndarray:
    v = np.zeros(3)
    v["xyz".index(up[-1])] = -1.0 if up.startswith("-") else 1.0
    return _up_axis(v)[1]


def _leg(p: np.ndarray, legs: list[dict[str, int]]) -> float:
    """[file units] the mean length of the legs (hip to knee to ankle) over the frames and sides."""
    return float(np.mean([np.linalg.norm(p[:, lg["lower_leg"]] - p[:, lg["upper_leg"]], axis=-1).mean()
                          + np.linalg.norm(p[:, lg["foot"]] - p[:, lg["lower_leg"]], axis=-1).mean() for lg in legs]))


def _unit(clip: BvhClip, p: np.ndarray, legs: list[dict[str, int]]) -> tuple[float, str] | None:
    """(metres per unit, name) whose stature is a person's (module docstring); None if none is."""
    leg = _leg(p, legs)
    cmu = bool(CMU_NAMES & set(clip.names))
    lo, hi, typical = STATURES
    fits = [(abs(np.log(leg * u / LEG_OF_STATURE / typical)), u, name) for name, u in UNITS.items()
            if (name != "cmu" or cmu) and lo <= leg * u / LEG_OF_STATURE <= hi]
    return min(fits)[1:] if fits else None


def _assumed_unit(leg: float) -> tuple[float, str, str]:
    """No named unit makes the subject a person (0.8-2.4 m tall): (metres per unit of a typical subject, its name, why),
    as a skeleton map's {"unit": x} would give it. The statures the named units give are in the why."""
    tall = ", ".join(f"{leg * u / LEG_OF_STATURE:.3g} m in {name}" for name, u in UNITS.items() if name != "cmu")
    lo, hi, typical = STATURES
    u = typical * LEG_OF_STATURE / leg
    return u, f"{u:.3g}", (f"the legs are {leg:.4g} units long, a subject {tall}, none {lo:g}-{hi:g} m tall: read as a "
                           f"{typical:g} m subject, {u:.3g} m per unit")


def unit_note(skel: RecognisedSkeleton) -> str | None:
    """The warning line of an assumed length unit (`RecognisedSkeleton.unit_assumed`), None when it was found or given."""
    if skel.unit_assumed is None:
        return None
    return (f"cannot tell the length unit of {skel.source}: {skel.unit_assumed} (gravity, the body's mass and the "
            "contact heights at that size; the outputs in the file's own units); give \"unit\" in a skeleton map if "
            "the subject is another size (--skeleton-map FILE, docs/mocap.md \"Skeleton map\")")


def _rest_frames(clip: BvhClip, p: np.ndarray, hips: int, joints: list[int]) -> int:
    """1 if the clip has CMU's names (the cgspeed conversion always starts with a synthetic T-pose, and
    a one-frame glitch near the start of a short clip can hide its jump) or the first frame is a
    separate pose (`REST_JUMP`, over the role `joints`: not fingers a capture may leave uncaptured),
    else 0 (also for a clip too short to tell, fewer than 4 frames)."""
    if CMU_NAMES & set(clip.names):
        return 1
    if len(p) < 4:
        return 0
    rel = p[:, joints] - p[:, hips:hips + 1]
    step = np.linalg.norm(np.diff(rel, axis=0), axis=-1).max(axis=1)
    change = np.linalg.norm(rel[:-2] - 2.0 * rel[1:-1] + rel[2:], axis=-1).max(axis=1)
    return int(step[0] > REST_JUMP * np.quantile(step[1:], 0.99) or change[0] > REST_JUMP * np.quantile(change[1:], 0.99))


# --------------------------------------------------------------------------------------------------
# recognition
# --------------------------------------------------------------------------------------------------


def recognise(clip: BvhClip, skeleton_map: SkeletonMap | None = None) -> RecognisedSkeleton:
    """The roles, unit, up axis and rest frames of `clip` (module docstring).

    Args:
        clip: a parsed clip. skeleton_map: roles, unit or up axis that win over what is found (None: none).
    Returns:
        the recognised skeleton.
    Raises:
        InputError: a role cannot be found (the roles named, with the map file as the fix), a map names
            a joint the clip lacks, or the roles are not in hierarchy order.
    """
    smap = skeleton_map or SkeletonMap()
    trunk, legs, arms = _structure(clip)
    q, p = file_world(clip)
    roles = {r: clip.names[j] for r, j in trunk.items()}
    for pair in (legs, arms):
        sides = [name_side([clip.names[j] for j in limb.values()]) for limb in pair]
        if len(pair) == 2 and sorted(s or "" for s in sides) != ["l", "r"]:
            sides = _geometric_sides(clip, (q, p), pair, legs, trunk)
        for limb, side in zip(pair, sides, strict=True):
            if side is not None:
                roles.update({f"{side}_{r}": clip.names[j] for r, j in limb.items()})
    roles.update(smap.roles)
    _check_roles(clip, roles, smap)
    idx = {r: clip.index(n) for r, n in roles.items()}
    sided = [{r[2:]: j for r, j in idx.items() if r.startswith(s + "_")} for s in "lr"]
    if smap.up is not None:
        up, axes = smap.up, _axes_of(smap.up)
    else:
        feet = np.mean([p[:, lg["foot"]] for lg in sided], axis=0)
        up, axes = _up_axis((p[:, idx["chest"]] - feet).mean(axis=0))
    unit = (smap.unit, smap.unit_name) if smap.unit is not None else _unit(clip, p, sided)
    assumed = smap.unit_assumed if smap.unit is not None else None
    if unit is None:
        *unit, assumed = _assumed_unit(_leg(p, sided))
    hips = idx["hips"]
    positions = tuple(n for n, ch in zip(clip.names, clip.channels, strict=True) if set(ch) & set(POSITION_CHANNELS))
    above = []
    j = int(clip.parents[hips])
    while j >= 0:
        above.insert(0, clip.names[j])
        j = int(clip.parents[j])
    how = "the hierarchy and names" + (f", and the skeleton map {smap.source}" if smap.roles or smap.unit or smap.up
                                       else "")
    given = smap.rest_frames is not None
    rest = smap.rest_frames if given else _rest_frames(clip, p * unit[0], hips, sorted(set(idx.values())))
    if len(clip.local_quat) - rest < 2:  # a motion's velocities need two frames
        raise InputError(f"{clip.source}: the clip has {len(clip.local_quat) - rest} frame of motion after its {rest} "
                         "rest frame (a T-pose before the motion); a motion needs at least 2 frames: export more frames, "
                         'or give {"rest_frames": 0} in a skeleton map (--skeleton-map FILE) if the first is motion')
    return RecognisedSkeleton(MappingProxyType(roles), float(unit[0]), str(unit[1]), axes, up, positions,
                              tuple(above), rest, how, clip.source, given, assumed)


def _geometric_sides(clip, world, pair, legs, trunk) -> list[str | None]:
    """Sides of two limbs from the geometry: the left one's first joint is on the side of up x forward,
    forward being where the feet point (ball or foot end minus ankle), up from the ankles to the chest."""
    if len(legs) != 2 or "chest" not in trunk or any("foot" not in lg for lg in legs):
        return [None, None]
    q, p = world
    ankles = np.mean([p[:, lg["foot"]] for lg in legs], axis=0)
    up = (p[:, trunk["chest"]] - ankles).mean(axis=0)
    up /= np.linalg.norm(up)
    forward = sum(tip_positions(clip, (q, p), lg.get("toe", lg["foot"])) - p[:, lg["foot"]] for lg in legs)
    left = np.cross(up, forward)
    first = [min(limb.values()) for limb in pair]  # the limb's joint nearest the trunk (file order is depth-first)
    a = float(np.sum((p[:, first[0]] - p[:, first[1]]) * left))
    return ["l", "r"] if a > 0 else ["r", "l"]


#: roles whose joints descend from one another, in this order
_ORDER = [("hips", "spine", "chest", "neck", "head")] + [
    tuple(["chest"] + [f"{s}_{r}" for r in ("upper_arm", "forearm", "hand")]) for s in "lr"] + [
    tuple(["hips"] + [f"{s}_{r}" for r in ("upper_leg", "lower_leg", "foot", "toe")]) for s in "lr"]


def _check_roles(clip: BvhClip, roles: dict, smap: SkeletonMap) -> None:
    """InputError unless every required role has a joint of the clip, in hierarchy order."""
    unknown = {r: n for r, n in roles.items() if n not in clip.names}
    if unknown:
        r, n = next(iter(unknown.items()))
        raise InputError(f"{smap.source or clip.source}: \"{r}\": {n!r} is not a joint of {clip.source}; give one of "
                         "the HIERARCHY's joint names")
    missing = [r for r in ROLES if r not in OPTIONAL and r not in roles]
    if missing:
        raise InputError(f"{clip.source}: cannot recognise the skeleton's {', '.join(missing)}; name their joints in a "
                         "skeleton map, e.g. {\"" + missing[0] + "\": \"JOINT\"} (--skeleton-map FILE, docs/mocap.md "
                         "\"Skeleton map\")")
    used = [n for r, n in roles.items() if r != "spine" or n != roles.get("chest")]
    twice = sorted({n for n in used if used.count(n) > 1})
    if twice:
        both = [r for r, n in roles.items() if n == twice[0]]
        raise InputError(f"{clip.source}: the joint {twice[0]} plays the roles {', '.join(both)}; one joint per role: "
                         "fix the skeleton map (--skeleton-map FILE)")
    for chain in _ORDER:
        present = [r for r in chain if r in roles]
        for a, b in zip(present, present[1:]):
            if a == "spine" and roles[a] == roles[b]:
                continue
            j, above = clip.index(roles[b]), clip.index(roles[a])
            while j >= 0 and j != above:
                j = int(clip.parents[j])
            if j < 0 or roles[a] == roles[b]:
                raise InputError(f"{clip.source}: the {b} joint {roles[b]} does not descend from the {a} joint "
                                 f"{roles[a]}; fix the skeleton map (--skeleton-map FILE) or the HIERARCHY")
