"""The scene a clip is retargeted onto: a given MJCF file, one fitted to where the clip's feet rest
(`--scene auto`: a floor plane, tilted if the capture's is, and boxes; runner/capture/scene_fit.py), written
next to the outputs in the levelled capture frame (the fitted floor at z = 0, solver/capture_frame.py), or
(`--scene floor`) the clip's own ground plane, a level floor at its height 0, with boxes given in its
coordinates (`--boxes FILE.json`: a DCC's scene, the Blender add-on's)."""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from runner.capture.clip import Capture, as_capture
from runner.capture.reference_motion import ROOT_SCALE_LEGS, Retargeted, load_bvh_reference, retarget_capture
from runner.capture.retarget import Reference
from runner.capture.root_height import RootCorrectionRefused
from runner.capture.scene_fit import FittedScene, fit_contacts, fit_scene, scene_mjcf
from runner.capture.skeleton import recognise, unit_note
from runner.files import atomic_output
from solver.capture_frame import CaptureFrame
from solver.contacts import Contact, contact_points
from solver.errors import InputError
from solver.figure import model_feet
from solver.model import load_model
from solver.peak_bounds import MIN_FRAMES
from solver.surfaces import StaticSurfaces

#: `--scene auto`: fit the scene to the clip
AUTO = "auto"
#: `--scene floor`: a level floor at the clip's own height 0 (along its up axis), and the `--boxes`
FLOOR = "floor"


@dataclass(frozen=True)
class ClipScene:
    """A clip retargeted onto its scene.

    Attributes:
        reference: the retargeted clip, in the scene's frame (root height corrected onto the scene's
            surfaces, except on the subject's own figure).
        model: the scene's MjModel. scene_path: its MJCF file.
        fitted: the fitted floor and boxes as the scene has them: in the levelled capture frame, the floor
            level at z = 0 (None for a given scene).
        capture_floor: the same fit in the capture's own coordinates (a floor tilted or off z = 0 by
            the capture's calibration; None for a given scene).
        frame: the rigid transform from the capture's coordinates to the scene's (`capture_floor.
            levelling()`; the identity for a given scene without one).
        notes: what the fit changed to make the clip fit its scene (a user should know), one line each.
    """

    reference: Reference
    model: object
    scene_path: Path
    fitted: FittedScene | None = None
    capture_floor: FittedScene | None = None
    frame: CaptureFrame = field(default_factory=CaptureFrame.identity)
    notes: tuple[str, ...] = ()

    @property
    def warnings(self) -> tuple[str, ...]:
        """The lines a user is warned with: an assumed length unit (`runner.capture.skeleton.unit_note`), then `notes`."""
        skel = self.reference.skeleton
        unit = None if skel is None else unit_note(skel)
        return ((unit,) if unit else ()) + tuple(self.notes)


def clip_scene(clip: str | Path | Capture, scene: str | Path, figure: str | Path, fitted_out: str | Path,
               root_scale: float | str = ROOT_SCALE_LEGS, skeleton_map=None, root_height: bool = True,
               boxes=()) -> ClipScene:
    """Retarget `clip` onto `scene`, or with scene == "auto" onto a scene fitted to it.

    Fitting (docs/contacts.md "Fitted scenes"): retarget onto the figure alone (no surfaces, so no
    root-height correction: the feet stay at the heights the capture gives them, a floor that rises
    along the clip included; a correction onto a level floor would flatten it frame by frame, and
    hides a box it cannot see), find where the feet rest (`fit_contacts`), fit a floor plane and boxes
    (`fit_scene`), level it (`FittedScene.levelling`: the rigid transform taking the fitted floor to
    z = 0, so that gravity is normal to it; a tilted capture floor is a calibration error of the capture
    volume), write the levelled scene MJCF with that transform recorded in it to `fitted_out` (its include
    of the figure relative to that folder, so it loads from where it is saved), and retarget again onto
    it: `load_bvh_reference` moves the root into the levelled frame, and the height correction then
    stands the feet on the fitted floor and boxes (at most 3 cm on the subject's own figure, or the clip is
    refused: `runner.capture.root_height.check_root_correction`).

    Args:
        clip: the run's `Capture` (runner/capture/clip.py), or a BVH file, then read here once. scene: an
            MJCF file or "auto". figure: the figure's MJCF
            (models/humanoid39.xml). fitted_out: where the fitted scene is written (only for "auto").
        root_scale: the root path's scale (`load_bvh_reference`: "legs" or a number).
        skeleton_map: a `runner.capture.skeleton_map.SkeletonMap` or None (`load_bvh_reference`).
        root_height: correct the root height onto the surfaces (`load_bvh_reference`); False for an
            animator's keys (`--key-frames`), which are where they are.
        boxes: with scene == "floor", ((min (3,), max (3,)), ...) boxes in the clip's coordinates (file
            axes and units, `read_boxes`), written to `fitted_out` with the floor.
    Raises:
        InputError: the clip or a scene cannot be read, the clip has fewer than MIN_FRAMES frames, or its skeleton lacks
            a joint; with scene "auto", no foot rests in the clip.
    """
    clip = as_capture(clip)  # read once: the fit and the retargeting onto the fitted scene take the same value
    frames = len(clip.clip.local_quat) - recognise(clip.clip, skeleton_map).rest_frames  # the capture's, rest frames off
    if frames < MIN_FRAMES:
        raise InputError(f"{clip.source}: {frames} frames of capture; it needs at least {MIN_FRAMES}, the 6 Hz filter of its "
                         "no-jolt bounds (solver.peak_bounds); give a longer clip")
    if str(scene) == FLOOR:
        out = _writable(fitted_out)
        capture = _floor_scene(clip, figure, boxes, skeleton_map)
        return _onto_fitted(clip, capture, figure, out, root_scale, skeleton_map, check=False, root_height=root_height)
    if str(scene) != AUTO:
        model = load_model(scene)
        frame = CaptureFrame.from_model(model, str(scene))  # a malformed record named with its file
        ref = load_bvh_reference(clip, model, root_scale=root_scale, skeleton_map=skeleton_map, root_height=root_height)
        return ClipScene(ref, model, Path(scene), frame=frame)
    bare = load_model(figure)  # no surfaces: the root height as captured (no correction to fit against)
    onto = retarget_capture(clip, bare, root_scale, skeleton_map)  # once: the fitted scene holds the same figure
    first = load_bvh_reference(clip, bare, root_scale=root_scale, skeleton_map=skeleton_map, retargeted=onto)
    feet = model_feet(bare)
    pos = contact_points(bare, first.qpos)  # the figure's sites, foot by foot; rounded: their spheres' lowest points
    contacts = fit_contacts(first.times, pos, feet)
    if not contacts:
        raise InputError(f"{clip.source}: no foot rests in the clip ({len(first.times)} frames), so no scene can be fitted "
                         "to where the feet rest (--scene auto); give the scene: --scene floor for a level floor at the "
                         "clip's height 0, or --scene FILE.xml")
    capture = fit_scene(first.times, pos, contacts, feet)
    out = _writable(fitted_out)
    try:
        return _onto_fitted(clip, capture, figure, out, root_scale, skeleton_map, root_height=root_height, onto=onto)
    except RootCorrectionRefused as refused:
        notes = []
        if capture.boxes:  # boxes no foot rests on (a foot held still in the air, fitted as a prop): the floor alone
            notes.append(f"{len(capture.boxes)} fitted box(es) dropped, the scene is the floor alone: with them, {refused}")
            capture = FittedScene(capture.floor_z, (), capture.floor_slope)
            try:
                return replace(_onto_fitted(clip, capture, figure, out, root_scale, skeleton_map, root_height=root_height,
                                                 onto=onto), notes=tuple(notes))
            except RootCorrectionRefused as again:
                refused = again
        notes.append(f"{refused}; the root is corrected by that much all the same, and the result is only as good as the "
                     "fitted floor under those feet")
        return replace(_onto_fitted(clip, capture, figure, out, root_scale, skeleton_map, check=False,
                                         root_height=root_height, onto=onto), notes=tuple(notes))


def _writable(path) -> Path:
    """`path` as a Path; InputError when its folder does not exist."""
    out = Path(path)
    if not out.parent.is_dir():
        raise InputError(f"{out}: the folder {out.parent} does not exist; create it first")
    return out


def read_boxes(path) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """The boxes of a `--boxes FILE.json`: [{"min": [x, y, z], "max": [x, y, z]}, ...], axis-aligned, in the
    clip's coordinates (its axes and length unit, as its HIERARCHY and motion are written).

    Raises:
        InputError: the file is missing, not JSON, or a box is not two finite corners with min < max.
    """
    import json

    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8-sig"))
    except FileNotFoundError:
        raise InputError(f"--boxes {path}: no such file; give a JSON list such as "
                         "[{\"min\": [0, 1, 0], \"max\": [1, 2, 0.3]}]") from None
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise InputError(f"--boxes {path}: cannot read it as JSON ({e})") from None
    out = []
    for i, box in enumerate(doc if isinstance(doc, list) else [None]):
        try:
            lo, hi = (np.asarray(box[k], float) for k in ("min", "max"))
        except (TypeError, KeyError, ValueError):
            lo = hi = np.zeros(0)
        if lo.shape != (3,) or hi.shape != (3,) or not np.all(np.isfinite([lo, hi])) or np.any(hi <= lo):
            raise InputError(f"--boxes {path}: box {i} is {box!r}; give {{\"min\": [x, y, z], \"max\": [x, y, z]}} "
                             "with min < max, in the clip's coordinates")
        out.append((lo, hi))
    return tuple(out)


def _floor_scene(clip: Capture, figure, boxes, skeleton_map) -> FittedScene:
    """`--scene floor`: a level floor at the clip's height 0 and the boxes, in MuJoCo axes and metres (the
    clip's recognised axes and unit: p = unit A p_file; A a signed permutation, so a box stays a box)."""
    from runner.capture.figure_record import clip_skeleton

    skel = clip_skeleton(clip.clip, load_model(figure), skeleton_map)[0]
    out = []
    for lo, hi in boxes:
        a, b = (skel.unit * (skel.axes @ np.asarray(v, float)) for v in (lo, hi))
        lo_m, hi_m = np.minimum(a, b), np.maximum(a, b)
        out.append(((lo_m + hi_m) / 2, (hi_m - lo_m) / 2))
    return FittedScene(0.0, tuple(out))


def _onto_fitted(clip: Capture, capture: FittedScene, figure, out: Path, root_scale, skeleton_map, check: bool = True,
                 root_height: bool = True, onto: Retargeted | None = None) -> ClipScene:
    """The clip retargeted onto the scene `capture` (in the capture's coordinates), levelled and written to
    `out` (`clip_scene`); with `check`, a root correction beyond its bound raises RootCorrectionRefused.
    `onto`: the clip already retargeted onto the figure alone (`retarget_capture`), or None."""
    frame, fitted = capture.levelling(), capture.levelled()
    with atomic_output(out, suffix=".xml") as tmp_path:
        Path(tmp_path).write_text(scene_mjcf(fitted, figure, relative_to=out.parent, model=out.stem, capture=frame))
    model = load_model(out)
    ref = load_bvh_reference(clip, model, root_scale=root_scale, skeleton_map=skeleton_map, fitted=check,
                             root_height=root_height, retargeted=onto)
    return ClipScene(ref, model, out, fitted, capture, frame)


def name_surfaces(model, reference: Reference, contacts: list[Contact]) -> list[Contact]:
    """Each contact with `surface` set to the scene geom under its site in its middle frame (the highest
    box whose footprint holds the site, else the first floor plane)."""
    surfaces = StaticSurfaces.from_model(model)
    n_planes = len(surfaces.plane_point)
    planes = [surfaces.names[i] for i in range(n_planes) if abs(surfaces.plane_normal[i, 2]) > 1e-6]
    out = []
    for c in contacts:
        i = int(np.clip(round((c.start + c.end) / 2 / reference.frame_time), 0, reference.count - 1))
        p = contact_points(model, reference.qpos[i:i + 1], (c.site,))[0, 0]
        tops = surfaces.box_tops_below(p)
        name = planes[0] if planes else ""
        if np.isfinite(tops).any():
            name = surfaces.names[n_planes + int(np.argmax(tops))]
        out.append(Contact(c.site, c.start, c.end, name))
    return out
