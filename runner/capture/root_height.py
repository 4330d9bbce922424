"""Feet and surfaces: the root height correction that puts a resting foot on the surface under it (and no
contact site below a surface), and how far resting feet are from their surfaces (`runner.capture.stance`
says when a foot rests)."""
from __future__ import annotations

import numpy as np

from runner.capture.clearance import CONTACT_CLEARANCE, ContactClearance, moving_average, smoothing_width
from runner.capture.contact_detection import DETECT_SPEED_ON
from runner.capture.retarget import Reference
from solver.contacts import contact_radii, lowest_points
from solver.errors import InputError
from solver.figure import Figure

#: the wide height window [m] in which `correct_root_height` looks for feet at rest to measure the
#: retargeting's height error (the retargeted feet can be several cm off before the correction)
FIT_HEIGHT = 0.15
#: [m] the most the reference's root may be moved on the subject's own figure (`check_root_correction`): a
#: larger correction moves the feet by more than the 3 cm below which a foot counts as resting
#: (DETECT_HEIGHT_ON), so the scene is not where the capture's feet rest and the clip is refused
ROOT_CORRECTION_MAX = 0.03
#: [m] the most that correction may change between two frames 1/120 s apart: the 30 mm of the bound above,
#: which the smoothing (`runner.capture.clearance.SMOOTH_S`) keeps to a fifth of that; a jump is a surface that appears under a foot
ROOT_STEP_MAX = 0.03


def worst_contact_distance(reference: Reference, model) -> float:
    """Acceptance figure: the worst |clearance| of a foot's lowest contact site while the foot rests.

    Over the frames in which a foot rests on a surface (`runner.capture.stance.capture_rest`: in the
    capture's stance, its lowest site below the flight height and still), the largest distance between
    that site (heel or toe) and the surface under it, above or below (docs/contacts.md, "Feet on their
    surfaces").

    Args:
        reference: the motion. model: the scene's MjModel.
    Returns:
        distance [m]; 0.0 if no foot ever rests.
    Raises:
        InputError: the model lacks the contact sites or the feet.
    """
    from runner.capture.stance import capture_rest

    rest, lowest = capture_rest(model, reference.qpos, reference.frame_time)
    if not rest.any():
        return 0.0
    return float(np.max(np.abs(lowest[rest])))


class RootCorrectionRefused(InputError):
    """The root correction a fitted scene needs is beyond its bound (`check_root_correction`)."""


def check_root_correction(correction: np.ndarray, frame_time: float, source: str) -> None:
    """Refuse a reference whose root the correction moves too far or too suddenly (on the subject's own
    figure the correction is the only change to the capture, docs/mocap.md "The reference").

    Args:
        correction: (n,) [m] the height correction c(t) of each frame. frame_time: [s]. source: the clip.
    Raises:
        RootCorrectionRefused (an InputError): |c| above ROOT_CORRECTION_MAX, or c changing by more than
            ROOT_STEP_MAX in 1/120 s, naming the clip, the time and the fix.
    """
    c = np.asarray(correction, float)
    i = int(np.argmax(np.abs(c))) if len(c) else 0
    fix = ("the fitted floor and boxes are not where the subject's feet rest (a ramp or uneven ground is not "
           "fitted: docs/contacts.md, \"Fitted scenes\"); give the scene they stood on with --scene FILE.xml")
    if len(c) and abs(c[i]) > ROOT_CORRECTION_MAX:
        raise RootCorrectionRefused(f"{source}: the feet would need the root moved {1000 * c[i]:+.0f} mm at t = {i * frame_time:.3f} s "
                         f"to stand on the surfaces (at most {1000 * ROOT_CORRECTION_MAX:.0f} mm): {fix}")
    step = np.abs(np.diff(c)) / (120.0 * frame_time)  # per 1/120 s
    if len(step) and step.max() > ROOT_STEP_MAX:
        j = int(np.argmax(step))
        raise RootCorrectionRefused(f"{source}: the root correction jumps {1000 * step[j]:.0f} mm in 1/120 s at t = {j * frame_time:.3f} s "
                         f"(at most {1000 * ROOT_STEP_MAX:.0f} mm): {fix}")


def feet_line(reference: Reference, model) -> str:
    """The printed acceptance figures of a retargeted clip: how far resting feet are from the surfaces
    (`worst_contact_distance`), on the subject's own figure how far the capture's own feet disagree
    (`feet_disagreement`), and what the footplant moved to put them there (`Reference.plant`)."""
    line = f"feet in contact stay within {1000 * worst_contact_distance(reference, model):.1f} mm of the surface under them"
    d = feet_disagreement(reference, model)
    if d is not None:
        line += (f"; the capture's own feet disagree by up to {1000 * d:.1f} mm (by its forward kinematics: a resting "
                 "foot that far above the other foot's lowest point)")
    moved = reference.plant.largest_mm() if reference.plant is not None else {}
    if any(v > 0 for v in moved.values()):
        feet = ", ".join(f"the {foot} foot {mm:.1f} mm" for foot, mm in moved.items() if foot != "root")
        line += (f"; the footplant lowered resting feet onto their surfaces, at most {feet}, by the legs and the root "
                 f"(lowered at most {moved['root']:.1f} mm; docs/mocap.md \"The keyframes' feet\")")
    return line


def correct_root_height(qpos: np.ndarray, model, frame_time: float) -> np.ndarray:
    """Shift the root height per frame so feet in contact stand on the surfaces, and nothing sinks.

    1. The retargeting's height error: the retargeted feet can be several cm off before the
       correction (another subject's bone lengths, the shipped figure), nearly the same offset all
       through a clip. It is the median, over the frames where a foot is provisionally at rest (its
       lowest site within the wide window `FIT_HEIGHT` of the surface and slower than DETECT_SPEED_ON),
       of CONTACT_CLEARANCE - the lowest clearance of those feet.
    2. Contact frames: the frames in which a foot rests once that offset is applied, by the one
       definition the detection is judged against and the acceptance figure uses (`runner.capture.
       stance`: the capture's stance, and in it the lowest site below the flight height and still,
       `resting`). Only these are put on their surfaces: a foot near the top of a small hop is slow
       (its vertical speed passes through 0) and within the wide window, and putting it on the floor
       would pull the whole figure down and erase the flight (a 15 cm hop kept 3 cm of its height);
       a foot rolling off its toes is in the stance's way out, up to 5 cm high, and putting it on
       the floor would pull the other foot into the surface. dz = CONTACT_CLEARANCE - lowest
       clearance of the resting feet, so the lowest contact site of a standing foot ends
       `CONTACT_CLEARANCE` above its surface.
    3. Frames without contact (flight): dz interpolated linearly between the neighbouring contact
       frames (held constant before the first and after the last; the offset of step 1 if no frame
       is in contact).
    4. dz smoothed by a moving average over `SMOOTH_S` (9 frames at 120 Hz), then raised where needed
       so that every contact site of every frame is at least `CONTACT_CLEARANCE` above the surface
       under it (a swinging toe that dips into a surface; a few mm where the surfaces fit the capture).

    Args:
        qpos: (n, nq) retargeted motion. model: the scene's MjModel. frame_time: [s].
    Returns:
        (n, nq) qpos with the root z changed.
    """
    from runner.capture.stance import lowest_sites, resting, stance_mask

    kin = ContactClearance(model)
    pos = kin.positions(qpos)
    clear = kin.clearance(pos)
    n = len(qpos)
    times = np.arange(n) * frame_time
    lowest, speed = lowest_sites(times, pos, clear, kin.feet, kin.names)
    provisional = (lowest < FIT_HEIGHT) & (speed < DETECT_SPEED_ON)
    frames = np.arange(n)
    dz = np.zeros(n)
    if provisional.any():
        offset = float(np.median((CONTACT_CLEARANCE - np.where(provisional, lowest, np.inf).min(axis=1))[
            provisional.any(axis=1)]))
        # the same site is the lowest of each foot with or without the uniform offset: `lowest` stays
        stance = stance_mask(times, pos, clear + offset, kin.feet, kin.names)
        rest = resting(stance, lowest + offset, speed)
        on = rest.any(axis=1)
        if on.any():
            target = CONTACT_CLEARANCE - np.where(rest, lowest, np.inf).min(axis=1)
            dz = np.interp(frames, frames[on], target[on])
        else:
            dz = np.full(n, offset)
    dz = np.maximum(moving_average(dz, smoothing_width(n, frame_time)), CONTACT_CLEARANCE - clear.min(axis=1))
    out = qpos.copy()
    out[:, 2] += dz
    return out


def feet_disagreement(reference: Reference, model) -> float | None:
    """How far the capture's own feet are from allowing a resting foot onto its surface: [m], from the
    source file's forward kinematics, or None when the figure is not the subject's own (its feet are not
    the source's) or no foot ever rests.

    In each frame where a foot rests on a surface (`runner.capture.stance.capture_rest` of the reference),
    both feet's lowest contact points are found from the clip itself: the joint of each foot's role in the
    recognised skeleton (its world position and orientation by the BVH's forward kinematics in metres
    and MuJoCo axes, `runner.capture.skeleton.skeleton_world`, taken into the scene's levelled frame), turned
    by the foot body's offset from it (`runner.capture.figure_record.clip_skeleton`: the frames the figure
    records), carries the figure's heel and toe sites as they sit in the foot (`model.site_pos`, the
    spheres' lowest points), and their heights above the surfaces under them are
    measured. A vertical move of the whole figure (the reference's root correction) changes every height
    alike, and no point may end below a surface: so a resting foot whose lowest point is d above the
    other foot's (the other resting too, or brushing the floor as it swings) ends at least d off its own
    surface, whatever the correction. The capture's feet disagree by the largest such d (docs/mocap.md,
    "Feet on their surfaces"); resting feet further off than that are the scene's or the correction's
    doing.

    Args:
        reference: the retargeted clip (its `capture`: the clip as read; without one its `source` is read
            again). model: the scene's MjModel.
    Raises:
        InputError: the clip cannot be read or its skeleton recognised, or the model lacks the figure's feet.
    """
    from runner.capture.body_frames import DRIVERS
    from runner.capture.clip import as_capture
    from runner.capture.figure_record import clip_skeleton
    from runner.capture.skeleton import skeleton_world
    from runner.capture.stance import capture_rest
    from solver.capture_frame import CaptureFrame
    from solver.quaternion import mul
    from solver.surfaces import StaticSurfaces

    if not reference.captured_root:
        return None
    rest, _ = capture_rest(model, reference.qpos, reference.frame_time)
    rows = rest.any(axis=1)
    if not rows.any():
        return None
    clip = as_capture(reference.capture or reference.source).clip
    figure = Figure.from_model(model)
    smap = reference.skeleton.skeleton_map() if reference.skeleton is not None else None
    skel, frames, _ = clip_skeleton(clip, model, smap)  # as the import read it
    quat, pos = (a[skel.rest_frames:][rows] for a in skeleton_world(clip, skel))
    frame = CaptureFrame.from_model(model)
    surfaces = StaticSurfaces.from_model(model)
    heights = []
    for heel, toe in figure.feet.values():
        body = model.body(int(model.site_bodyid[model.site(heel).id])).name
        j = skel.index(clip, DRIVERS[body])
        off = np.broadcast_to(frames.offsets[body], quat[:, j].shape)
        q = mul(np.broadcast_to(frame.quat, quat[:, j].shape), mul(quat[:, j], off))
        rot = _matrices(q)
        sites = np.stack([frame.points(pos[:, j]) + rot @ model.site_pos[model.site(s).id] for s in (heel, toe)], axis=1)
        low = lowest_points(sites, contact_radii(model, (heel, toe)))
        heights.append(surfaces.height_above(low).min(axis=1))
    heights = np.stack(heights, axis=1)  # (m, 2) each foot's lowest point
    gap = heights - heights.min(axis=1, keepdims=True)
    return float(np.max(np.where(rest[rows], gap, 0.0)))


def _matrices(q: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotation matrices of (n, 4) unit quaternions w x y z."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                     np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
                     np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], -2)
