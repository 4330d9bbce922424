"""The joint roles of a skeleton and the skeleton map file (`--skeleton-map FILE`) that names them.

A role is a place on the body the figure needs (docs/mocap.md, "Skeletons of any convention"): the hips,
the first joint of the spine above them (the torso's pivot), the chest (where the arms branch off), the
neck and the head, and on each side (``l_`` left, ``r_`` right) the upper leg, lower leg, foot, toe,
upper arm, forearm and hand. The recogniser (runner/capture/skeleton.py) finds them from the hierarchy and
the names; a map file names the joint of any role it could not find (or overrides it), and may give the
length unit, the up axis and the leading rest frames:

    {"hips": "pelvis", "chest": "spine_03", "l_upper_leg": "thigh_l", "unit": "cm", "up": "z", "rest_frames": 0}

This module holds the role names and reads, checks and writes that file (a JSON object).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from solver.errors import InputError

__all__ = ["SIDE_ROLES", "ROLES", "OPTIONAL", "UNITS", "AXES", "SkeletonMap", "read_skeleton_map",
           "parse_skeleton_map"]

#: the roles of each side, from the trunk outwards
SIDE_ROLES = ("upper_leg", "lower_leg", "foot", "toe", "upper_arm", "forearm", "hand")
#: every role: the trunk's, then the left side's (``l_``) and the right side's (``r_``)
ROLES = ("hips", "spine", "chest", "neck", "head") + tuple(f"{s}_{r}" for s in "lr" for r in SIDE_ROLES)
#: roles a skeleton may lack: no joint between hips and chest (the chest is the pivot), no neck joint
#: (the head's), no toe joint (the foot's end is the ball of the foot)
OPTIONAL = frozenset({"spine", "neck", "l_toe", "r_toe"})
#: [m] per unit of the lengths a BVH file may be written in; "cmu": the CMU ASF unit (`length 0.45`:
#: 1 unit = 1/0.45 inch), which only the CMU skeleton's files use
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "inch": 0.0254, "cmu": 0.0254 / 0.45}
#: the file axis that points up, as a map file may give it
AXES = ("x", "y", "z", "-x", "-y", "-z")


@dataclass(frozen=True)
class SkeletonMap:
    """What a skeleton map file gives.

    Attributes:
        roles: {role: joint name} (any subset of `ROLES`).
        unit: [m] per file unit, or None (found from the bone lengths). unit_name: as written ("cm", "0.01").
        up: the file axis pointing up ("y", "-z", ...), or None (found from the motion).
        rest_frames: leading frames that are not motion (0 or 1), or None (found from the names and the
            motion: a file written by a program that knows it has none, e.g. the Blender add-on, says 0).
        source: the file (for messages).
        unit_assumed: why `unit` is a typical subject's (`runner.capture.skeleton.RecognisedSkeleton.unit_assumed`):
            written by the tool into a subject figure's record, so that the figure keeps the warning.
    """

    roles: dict = field(default_factory=dict)
    unit: float | None = None
    unit_name: str | None = None
    up: str | None = None
    source: str = ""
    rest_frames: int | None = None
    unit_assumed: str | None = None

    def text(self) -> str:
        """The map as the JSON text of a map file (one line)."""
        doc = dict(self.roles)
        if self.unit is not None:
            doc["unit"] = self.unit_name if self.unit_name in UNITS else self.unit
        if self.up is not None:
            doc["up"] = self.up
        if self.rest_frames is not None:
            doc["rest_frames"] = self.rest_frames
        if self.unit_assumed is not None:
            doc["unit_assumed"] = self.unit_assumed
        return json.dumps(doc, separators=(",", ":"))


def read_skeleton_map(path: str | Path) -> SkeletonMap:
    """Read a skeleton map file (module docstring).

    Raises:
        InputError: the file is missing or not JSON, or a key or value is wrong (file, key, value and the
            fix named).
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"--skeleton-map {path}: no such file (current folder: {Path.cwd()}); give a JSON file "
                         "naming the joint of each role, e.g. {\"hips\": \"pelvis\", \"l_foot\": \"foot_l\"}")
    try:
        text = p.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"--skeleton-map {path}: cannot read it ({e}); give a JSON text file") from None
    return parse_skeleton_map(text, str(path))


def parse_skeleton_map(text: str, source: str) -> SkeletonMap:
    """A `SkeletonMap` from the text of a map file (`read_skeleton_map`); `source` names it in messages."""
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as e:
        raise InputError(f"{source}: line {e.lineno}: not JSON ({e.msg}); a skeleton map is a JSON object, e.g. "
                         "{\"hips\": \"pelvis\", \"l_foot\": \"foot_l\"}") from None
    if not isinstance(doc, dict):
        raise InputError(f"{source}: a skeleton map is a JSON object {{\"role\": \"joint\", ...}}, not "
                         f"{type(doc).__name__}")
    roles, unit, unit_name, up, rest, assumed = {}, None, None, None, None, None
    for key, value in doc.items():
        if key == "unit":
            unit, unit_name = _unit(value, source)
        elif key == "up":
            if not isinstance(value, str) or value.lower() not in AXES:
                raise InputError(f"{source}: \"up\": {value!r} is not an axis; give one of {', '.join(AXES)} "
                                 "(the file axis that points up)")
            up = value.lower()
        elif key == "rest_frames":
            if value not in (0, 1) or isinstance(value, bool):
                raise InputError(f"{source}: \"rest_frames\": {value!r} is not 0 or 1; give 1 when the file's first "
                                 "frame is a rest pose put before the motion (a T-pose), else 0")
            rest = int(value)
        elif key == "unit_assumed" and isinstance(value, str):  # the tool's own note in a subject figure's record
            assumed = value
        elif key in ROLES:
            if not isinstance(value, str) or not value.strip():
                raise InputError(f"{source}: \"{key}\": {value!r} is not a joint name; give the name of the "
                                 "joint as the HIERARCHY writes it")
            roles[key] = value.strip()
        else:
            raise InputError(f"{source}: unknown key \"{key}\"; the keys are the roles {', '.join(ROLES)}, and "
                             "\"unit\", \"up\" and \"rest_frames\"")
    return SkeletonMap(roles, unit, unit_name, up, source, rest, assumed)


def _unit(value, source: str) -> tuple[float, str]:
    """(metres per unit, the name as given) of a map file's "unit"."""
    if isinstance(value, str) and value.lower() in UNITS:
        return UNITS[value.lower()], value.lower()
    number = value if isinstance(value, (int, float)) and not isinstance(value, bool) else float("nan")
    if not (math.isfinite(number) and number > 0):
        raise InputError(f"{source}: \"unit\": {value!r} is neither one of {', '.join(UNITS)} nor a number of "
                         "metres per unit > 0 (e.g. 0.01 for centimetres)")
    return float(number), repr(float(number))
