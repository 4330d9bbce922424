"""What a subject's figure records about the skeleton it was made for, and the skeleton a clip is read with.

The subject's figure (runner/capture/subject_figure.py) is made for one skeleton and measured on one clip.
It records in its `<custom>` section

* ``subject:skeleton``: a digest of the skeleton's joint names, parents and OFFSETs (`skeleton_digest`);
* ``subject:map``: the recognised skeleton as a complete skeleton map (roles, unit, up axis;
  runner/capture/skeleton_map.py), so that the same roles are read again whatever map was given;
* ``subject:frame:<body>``: each body's offset R_off from its driving joint (runner/capture/body_frames.py).

`clip_skeleton` gives the skeleton and body frames a clip is retargeted with: on a figure made for the
clip's skeleton the recorded ones (so that a clip of that skeleton is retargeted onto it without loss,
and the export onto the source skeleton undoes exactly what the import did), else the clip's own
(recognised, and the figure's bodies measured on it). A figure or keyframe file made before frames were
recorded gets the rest-pose frames it was made with (`runner.capture.body_frames.rest_pose_frames`).
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from runner.capture.body_frames import DRIVERS, BodyFrames, body_frames, rest_pose_frames
from runner.capture.bvh import BvhClip
from runner.capture.skeleton import RecognisedSkeleton, recognise
from runner.capture.skeleton_map import SkeletonMap, parse_skeleton_map
from solver.errors import InputError
from solver.figure import Figure

__all__ = ["SKELETON_TEXT", "MAP_TEXT", "FRAME_PREFIX", "FigureRecord", "skeleton_digest", "figure_record",
           "figure_skeleton_digest", "write_record", "clip_skeleton"]

#: the `<custom>` names of the record (module docstring)
SKELETON_TEXT = "subject:skeleton"
MAP_TEXT = "subject:map"
FRAME_PREFIX = "subject:frame:"


@dataclass(frozen=True)
class FigureRecord:
    """A subject figure's record: digest, the skeleton map (None in a figure made before maps were
    recorded) and the body offsets {body: (4,)} (empty likewise)."""

    digest: str
    skeleton_map: SkeletonMap | None
    offsets: dict


def skeleton_digest(clip: BvhClip) -> str:
    """A digest of the skeleton's joint names, parents and OFFSETs (rounded to 1e-5 units): equal for
    two clips of one subject's skeleton, different for another's."""
    h = hashlib.sha1()
    for name, par, off in zip(clip.names, clip.parents, np.round(clip.offsets, 5) + 0.0, strict=True):
        h.update(f"{name}:{par}:{off[0]:.5f},{off[1]:.5f},{off[2]:.5f};".encode())
    return h.hexdigest()[:16]


def _text(model, name: str) -> str | None:
    import mujoco

    i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_TEXT, name)
    if i < 0:
        return None
    adr, size = int(model.text_adr[i]), int(model.text_size[i])
    return bytes(model.text_data[adr:adr + size]).split(b"\0")[0].decode().strip()


def figure_skeleton_digest(model) -> str | None:
    """The skeleton digest a subject figure records (`SKELETON_TEXT`), or None (another figure)."""
    return _text(model, SKELETON_TEXT)


def figure_record(model) -> FigureRecord | None:
    """The record of the subject figure in `model` (module docstring), or None (another figure).

    Raises:
        InputError: the recorded map or a frame is malformed.
    """
    import mujoco

    digest = figure_skeleton_digest(model)
    if digest is None:
        return None
    text = _text(model, MAP_TEXT)
    smap = parse_skeleton_map(text, f"the figure's {MAP_TEXT}") if text else None
    offsets = {}
    for body in DRIVERS:
        i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, FRAME_PREFIX + body)
        if i >= 0:
            adr, size = int(model.numeric_adr[i]), int(model.numeric_size[i])
            q = np.array(model.numeric_data[adr:adr + size], float)
            if q.shape != (4,) or not np.isfinite(q).all() or abs(np.linalg.norm(q) - 1.0) > 1e-4:
                raise InputError(f"the figure's {FRAME_PREFIX}{body} is not a unit quaternion (w x y z): "
                                 f"{q.tolist()}; remake the figure (--figure subject)")
            offsets[body] = q / np.linalg.norm(q)
    return FigureRecord(digest, smap, offsets)


def write_record(spec, clip: BvhClip, skel: RecognisedSkeleton, frames: BodyFrames) -> None:
    """Add the record (module docstring) to the `mujoco.MjSpec` of a subject figure."""
    spec.add_text(name=SKELETON_TEXT, data=skeleton_digest(clip))
    spec.add_text(name=MAP_TEXT, data=skel.skeleton_map().text())
    for body, q in frames.offsets.items():
        spec.add_numeric(name=FRAME_PREFIX + body, data=[float(v) for v in q])


def clip_skeleton(clip: BvhClip, model, skeleton_map: SkeletonMap | None = None, rest_pose: bool = False):
    """The skeleton and body frames `clip` is retargeted onto the figure of `model` with (module docstring).

    Args:
        clip: a parsed clip. model: the scene's (or the figure's) MjModel.
        skeleton_map: roles, unit or up axis given by the user (`--skeleton-map`); on the figure made for
            this skeleton the recorded map is used instead.
        rest_pose: the body frames of the skeleton's rest pose (a keyframe file made before frames were
            measured, `rest_pose_frames`), unless the figure records its own.
    Returns:
        (RecognisedSkeleton, BodyFrames, own: the model's figure was made for this skeleton).
    Raises:
        InputError: the skeleton cannot be recognised (roles named), or a record is malformed.
    """
    record = figure_record(model)
    own = record is not None and record.digest == skeleton_digest(clip)
    if own and record.skeleton_map is not None and set(record.offsets) == set(DRIVERS):
        skel = recognise(clip, record.skeleton_map)
        return skel, BodyFrames(MappingProxyType(dict(record.offsets)), MappingProxyType({})), True
    skel = recognise(clip, skeleton_map)
    figure = Figure.from_model(model)
    if rest_pose or own:  # an old keyframe file, or a subject figure made before frames were recorded
        return skel, rest_pose_frames(clip, skel, figure), own
    return skel, body_frames(clip, skel, figure), own

