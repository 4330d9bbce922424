"""A BVH clip as a reference motion of the figure: parsed, retargeted, cleaned up (runner/capture/retarget.py).

On the subject's own figure (runner/capture/subject_figure.py: made from this clip's skeleton) the
retargeting is lossless: the root path is the captured one (no scale), and the modelled joints' positions
relative to the root are the capture's (docs/mocap.md, "What the figure keeps"). In a scene with surfaces
the root height is still corrected per frame by at most 3 cm (`correct_root_height`), so that the feet in
contact stand on the fitted surfaces instead of sinking into them; the export onto the source skeleton
takes that correction off again (runner/capture/source_export.py).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from runner.capture.clip import Capture, as_capture
from runner.capture.figure_record import clip_skeleton
from runner.capture.foot_plant import plant_feet
from runner.capture.glitches import repair_glitches
from runner.capture.retarget import (
    Reference,
    check_figure,
    clamp_hyperextension,
    hyperextension,
    leg_length_ratio,
    retarget,
    tidy_quaternions,
)
from runner.capture.root_height import check_root_correction, correct_root_height
from runner.capture.skeleton import RecognisedSkeleton
from runner.capture.skeleton_map import SkeletonMap
from solver.capture_frame import CaptureFrame
from solver.errors import InputError
from solver.figure import Figure
from solver.layout import StateLayout

#: the stages of `load_bvh_reference` its `progress` callback reports
IMPORT_STAGES = ("parse", "retarget", "glitches", "clamp", "root height", "footplant", "tidy")


#: `load_bvh_reference`'s default root scale: the figure's leg length over the subject's
ROOT_SCALE_LEGS = "legs"


@dataclass(frozen=True)
class Retargeted:
    """A clip retargeted onto a figure (`retarget_capture`), in the capture's own coordinates, before the
    scene's levelling and the clean-up: what the readings of one clip onto one figure share (a fitted scene
    reads the clip onto the figure alone to find where the feet rest, then onto the scene fitted there).

    Attributes:
        qpos: (n, nq) the retargeted frames, the rest frames dropped (read-only).
        skeleton: the recognised skeleton (roles, unit, axes, rest frames). scale: the root path's scale
            applied (`load_bvh_reference` root_scale). own: the figure is the subject's own.
    """

    qpos: np.ndarray
    skeleton: RecognisedSkeleton
    scale: float
    own: bool


def retarget_capture(capture: Capture, model, root_scale: float | str = ROOT_SCALE_LEGS,
                     skeleton_map: SkeletonMap | None = None, rest_pose: bool = False) -> Retargeted | None:
    """`load_bvh_reference`'s retargeting step alone: the clip onto the figure of `model` (its skeleton
    recognised, the body frames the figure records or measured, the root scale), or None for a clip on the
    figure's own skeleton (read exactly, nothing to retarget). Arguments and errors as `load_bvh_reference`."""
    from runner.export.bvh import is_figure_clip

    clip = capture.clip
    if is_figure_clip(clip, model):
        return None
    figure = check_figure(Figure.from_model(model))
    skel, frames, own = clip_skeleton(clip, model, skeleton_map, rest_pose)  # own: the subject's own figure
    scale = 1.0 if own and root_scale == ROOT_SCALE_LEGS else _root_scale(root_scale, clip, skel, model, capture.source)
    qpos = retarget(clip, skel, frames, figure, StateLayout.from_model(model), scale)[skel.rest_frames:]
    qpos.flags.writeable = False
    return Retargeted(qpos, skel, scale, own)


def load_bvh_reference(path: str | Path | Capture, model, progress=None, root_scale: float | str = ROOT_SCALE_LEGS,
                       skeleton_map: SkeletonMap | None = None, rest_pose: bool = False,
                       fitted: bool = False, root_height: bool = True, retargeted: Retargeted | None = None) -> Reference:
    """Read a BVH clip and retarget it onto the figure: the dense reference motion. A clip on the
    figure's own skeleton (written by `dynsplines export --to FILE.bvh` or `--export FILE.bvh`: a joint
    named after every figure body) is read exactly instead (`runner.export.bvh.figure_qpos_from_bvh`):
    every frame, no retargeting, no clamping, no root-height correction.

    Steps (runner/capture/retarget.py docstring): parse (bvhio), recognise the skeleton
    (`runner.capture.figure_record.clip_skeleton`), drop a leading rest frame (CMU's cgspeed T-pose), forward
    kinematics in metres and MuJoCo axes, body-offset retargeting, local joint quaternions (unit, w x y z,
    hemisphere-consistent), the root moved into the scene's levelled capture frame
    (`solver.capture_frame.CaptureFrame.from_model`), tracking glitches repaired (`repair_glitches`),
    knee/elbow hyperextension clamped (`clamp_hyperextension`), the root height corrected so feet in contact
    stand on their surfaces and no site is below one (`correct_root_height`); for the keyframes, the resting
    feet planted (`runner.capture.foot_plant.plant_feet`, `Reference.plant`, `Reference.keyed`).

    Args:
        path: the run's `Capture` (runner/capture/clip.py), or a BVH file of a human skeleton of any
            convention (runner/capture/skeleton.py), then read here.
        model: the scene's MjModel (figure + floor + step box), e.g. models/run_and_step.xml; its
            figure must be models/humanoid39.xml (joint and site names). With a model that has no
            static surfaces (the figure alone) the root height is left as retargeted.
        progress: optional progress(stages_done, next_stage) after each of `IMPORT_STAGES`.
        root_scale: the scale of the captured root path: "legs" (default: the figure's leg length over
            the subject's, `leg_length_ratio`, so that the figure's strides cover the ground the
            subject's did) or a number > 0 (1: the root path as captured, e.g. for a scene built around
            the capture's own coordinates, or a keyframe file made before the scaling).
        skeleton_map: roles, unit or up axis that win over the recognised ones (`--skeleton-map`; on the
            figure made for this skeleton its recorded ones are used).
        rest_pose: the figure's bodies on the skeleton's rest pose, as keyframe files made before the
            bodies were measured on the clip (`runner.capture.body_frames.rest_pose_frames`).
        fitted: the scene was fitted to this clip (`runner.capture.scene.clip_scene`): on the subject's own
            figure, a root correction beyond its bound is refused (`check_root_correction`: the fit
            missed where the feet rest). In a scene of your own the correction is what the scene needs.
        root_height: correct the root height (`correct_root_height`); False: the root as retargeted, for
            an animator's keys (`--key-frames`: the poses are the keyframes, in the animator's scene).
        retargeted: `retarget_capture` of this clip onto this model's figure, made before (onto the figure
            alone, say), so the clip is retargeted once; None: retargeted here.
    On the subject's own figure (the model's figure records this clip's skeleton) "legs" is 1: see the
    module docstring for why the root height is still corrected and how the export takes it off.

    Returns:
        Reference with times (n,) [s] from 0, qpos (n, nq), source = str(path), frame_time [s],
        root_scale, captured_root (the subject's own figure: root unscaled, only its height corrected),
        skeleton (the recognised skeleton), capture (the clip as read);
        n = frames in the file minus its rest frames.
    Raises:
        InputError: missing/unreadable file, malformed BVH (line named), wrong channel count, a
            role the retargeting needs is not found, the model lacks a joint or site it needs, a malformed
            capture frame in the scene, root_scale is neither "legs" nor a number > 0, or (`fitted`) the
            root correction is beyond its bound.
    """
    from runner.export.bvh import figure_qpos_from_bvh, is_figure_clip

    step = progress or (lambda i, stage: None)
    capture = as_capture(path)
    clip, path = capture.clip, capture.source
    step(1, "parsed")
    if is_figure_clip(clip, model):  # our own export: the figure's qpos, read back without loss
        qpos = figure_qpos_from_bvh(clip, model)
        step(len(IMPORT_STAGES), "figure skeleton, read exactly")
        return Reference(np.arange(len(qpos)) * clip.frame_time, qpos, str(path), clip.frame_time, capture=capture)
    onto = retargeted or retarget_capture(capture, model, root_scale, skeleton_map, rest_pose)
    skel, scale, own = onto.skeleton, onto.scale, onto.own
    layout = StateLayout.from_model(model)
    figure = check_figure(Figure.from_model(model))
    qpos = CaptureFrame.from_model(model).root(onto.qpos, figure.joints[0].qpos_slice.start)  # the levelled frame
    step(2, "retargeted")
    qpos, glitches = repair_glitches(qpos, layout, clip.frame_time)  # a joint turning faster than any human's
    step(3, "glitches")
    clamped = hyperextension(qpos, figure)
    qpos, _ = clamp_hyperextension(qpos, figure)
    step(4, "clamped")
    qpos, plant = _on_the_surfaces(qpos, model, layout, clip.frame_time, str(path), own and fitted, step, root_height)
    step(7, "done")
    times = np.arange(len(qpos)) * clip.frame_time
    return Reference(times, qpos, str(path), clip.frame_time, scale, captured_root=own, skeleton=skel,
                     clamped=clamped, plant=plant, glitches=glitches, capture=capture)


def _on_the_surfaces(qpos, model, layout, frame_time: float, source: str, bounded: bool, step, root_height=True):
    """The import's last clean-up (`load_bvh_reference` steps 5-6): the root height corrected so that feet
    in contact stand on the surfaces and nothing is below one (a no-op without surfaces; on the subject's
    own figure it only takes up the captured feet's deviation, at most 3 cm, from the fitted scene, and
    with `bounded` a larger or sudden correction is refused), then the keyframes' footplant.

    Returns:
        (qpos (n, nq) tidied, `FootPlant` with its qpos tidied); root_height False: no correction.
    Raises:
        RootCorrectionRefused: `bounded` and the correction beyond its bound (`check_root_correction`).
    """
    corrected = correct_root_height(qpos, model, frame_time) if root_height else qpos
    if bounded and root_height:
        check_root_correction(corrected[:, 2] - qpos[:, 2], frame_time, source)
    step(5, "root height")
    plant = plant_feet(corrected, model, frame_time)  # the keyframes' feet on their surfaces, by the legs
    step(6, "footplant")
    return tidy_quaternions(corrected, layout), replace(plant, qpos=tidy_quaternions(plant.qpos, layout))


def _root_scale(root_scale, clip, skel, model, path) -> float:
    """The number `root_scale` stands for (`load_bvh_reference`). Raises InputError naming a bad value."""
    if isinstance(root_scale, str) and root_scale == ROOT_SCALE_LEGS:
        return leg_length_ratio(clip, skel, model)
    try:
        value = float(root_scale)
    except (TypeError, ValueError):
        value = float("nan")
    if not (np.isfinite(value) and value > 0):
        raise InputError(f"{path}: root scale {root_scale!r} is neither {ROOT_SCALE_LEGS!r} nor a number > 0")
    return value
