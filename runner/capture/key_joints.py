"""Partial keys of an animator's clip (`--key-joints FILE.json`): the clip's joints keyed at a frame, and
the figure joints they fix.

A DCC keys bones, not the figure's joints: at a frame where only some bones carry keys (the left leg
posed, the rest left to the interpolation), the keyframe is partial (paper sec. 2) and fixes the figure
joints those bones drive (runner/capture/body_frames.py `DRIVERS`: a body takes the world orientation of
the joint of its role). A keyed joint the figure merges into a body (CMU's `LHipJoint`, `LowerBack`,
`Spine`, `LeftShoulder`: composed into the body below them) fixes the body of the first driving joint
down its chain; a joint the figure does not model (toes, hands, fingers, neck and head, joints above
the hips) fixes nothing. The file:

    {"30": ["LeftUpLeg", "LeftLeg", "LeftFoot"], "61": ["Hips"]}

names the clip's frames (numbered as `--key-frames`) that are partial and their keyed joints; the
other key frames are full.
"""
from __future__ import annotations

import json
from pathlib import Path

from solver.errors import InputError

__all__ = ["read_key_joints", "figure_joints", "frame_joints"]


def read_key_joints(path: str | Path) -> dict[int, tuple[str, ...]]:
    """{clip frame: keyed joint names} of a key-joints file (module docstring).

    Raises:
        InputError: the file is missing or not JSON, or a key or value is not a frame or joint names.
    """
    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8-sig"))
    except FileNotFoundError:
        raise InputError(f"--key-joints {path}: no such file; give a JSON file such as "
                         "{\"30\": [\"LeftUpLeg\", \"LeftLeg\"]}") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise InputError(f"--key-joints {path}: cannot read it as JSON ({e}); give an object such as "
                         "{\"30\": [\"LeftUpLeg\", \"LeftLeg\"]}") from None
    if not isinstance(doc, dict):
        raise InputError(f"--key-joints {path}: a JSON object {{\"frame\": [\"joint\", ...]}} is expected, not "
                         f"{type(doc).__name__}")
    out = {}
    for key, names in doc.items():
        if not key.strip().lstrip("-").isdigit():
            raise InputError(f"--key-joints {path}: \"{key}\" is not a frame number; the keys are the key frames "
                             "(as --key-frames numbers them)")
        if not (isinstance(names, list) and all(isinstance(n, str) and n for n in names)):
            raise InputError(f"--key-joints {path}: \"{key}\": {names!r} is not a list of joint names")
        out[int(key)] = tuple(names)
    return out


def _driving(clip, skel, model) -> dict[int, str]:
    """{clip joint index: figure joint} of the joints that drive a figure body."""
    from runner.capture.body_frames import DRIVERS
    from solver.figure import Figure

    figure = Figure.from_model(model)
    joint_of = {child: name for name, (_, child) in figure.joint_bodies.items()}
    return {skel.index(clip, role): joint_of[body] for body, role in DRIVERS.items() if body in joint_of}


def figure_joints(clip, skel, model, names) -> tuple[str, ...]:
    """The figure joints that the clip's keyed joints `names` fix (module docstring), in figure order.

    Args:
        clip: the parsed clip (`runner.capture.bvh.BvhClip`). skel: its recognised skeleton. model: the scene
            with the figure made for it. names: keyed joint names of the clip.
    Raises:
        InputError: a name is not a joint of the clip.
    """
    driving = _driving(clip, skel, model)
    hips = skel.index(clip, "hips")
    children: dict[int, list[int]] = {}
    for j, par in enumerate(clip.parents):
        children.setdefault(int(par), []).append(j)
    fixed = set()
    for name in names:
        if name not in clip.names:
            raise InputError(f"--key-joints: {name!r} is not a joint of {clip.source}; name the joints as its "
                             "HIERARCHY does")
        j = clip.index(name)
        above = j
        while above >= 0 and above != hips:
            above = int(clip.parents[above])
        if above != hips:  # above the hips (a static root): not modelled
            continue
        while j not in driving and len(children.get(j, [])) == 1:  # merged into the body below
            j = children[j][0]
        if j in driving:
            fixed.add(driving[j])
    from solver.figure import Figure

    return tuple(jt.name for jt in Figure.from_model(model).joints if jt.name in fixed)


def frame_joints(clip, reference, model, key_frames, key_joints) -> dict | None:
    """{key frame: figure joints} of the partial keys the file `key_joints` names (None: no file).

    Args:
        clip: the run's `runner.capture.clip.Capture`, or the BVH file (then read here). reference: its
            retargeted reference (its recognised skeleton). model: the scene.
        key_frames: the key frames (`--key-frames`). key_joints: the file (`--key-joints`) or None.
    Raises:
        InputError: a file without --key-frames, a frame that is not a key frame, or a joint the clip lacks.
    """
    if key_joints is None:
        return None
    from runner.capture.clip import as_capture

    named = read_key_joints(key_joints)
    if key_frames is None or not set(named) <= set(key_frames):
        raise InputError(f"--key-joints {key_joints}: frames {sorted(set(named) - set(key_frames or ()))} are "
                         "not among --key-frames; a partial key is one of the key frames")
    parsed = as_capture(clip).clip
    return {f: figure_joints(parsed, reference.skeleton, model, names) for f, names in named.items()}
