"""A saved path written back onto the skeleton of the BVH clip it came from (`dynsplines export --to
FILE.bvh`, docs/export.md "Onto the source skeleton").

The file has the source's HIERARCHY verbatim (joint names, OFFSETs, channel order, units; a root with
rotation channels only gets position channels, which carry the path's root) and its frame rate, and
starts, like the source, with the source's leading rest frames (the synthetic T-pose of CMU's cgspeed
conversion; none in most files); frame k + rest is the path at t = k / fps. The skeleton is
read as the import read it (the roles, unit, axes and body frames the subject's figure records,
runner/capture/figure_record.py).

The motion is the source plus the path's change (motion displacement mapping, Bruderlin & Williams
1995; Witkin & Popovic 1995): the path's change relative to the capture as the figure has it is put onto
the source's own pose, so that where the path is the capture the file is the source. Per frame:

* **the capture as the figure has it** (the base): the source's pose at the export time (its local
  rotations and translations, the captured frame's own at a captured frame's time, else spherical
  linear interpolation between the neighbouring frames, `scipy.spatial.transform.Slerp`) retargeted onto
  the figure (`runner.capture.retarget.retarget`, with the body frames the subject's figure records), and
  the root where the path's reference has it (the saved path's `reference_qpos`: the captured hips
  moved by the import's root-height correction, `runner.capture.root_height.correct_root_height`, that
  stands the feet on the fitted surfaces; without a reference, the captured hips). The import's
  corrections of the capture (the knee and elbow hyperextension clamp, the repair of tracking glitches,
  the footplant of the keys) are not in the base, so they are part of the path's change and reach the
  file, where `mocap` names them.
* **a joint driving a figure body** (`runner.capture.body_frames.DRIVERS`: the hips, upper and lower legs,
  feet, chest, upper arms and forearms): with the figure joint into that body turned by q_path on the
  path and by q_base on the base, its change is D = q_base^-1 q_path, in the body's frame; in the
  driving joint's frame that is E = R_off D R_off^-1 (figure world = source world x R_off), and the
  joint's local rotation becomes L E (file axes: E' = A^T E A, A = skel.axes). The source joints
  between two driving joints (CMU's LowerBack and Spine below the chest, a hip offset joint such as
  LHipJoint, a clavicle) keep their local rotations, so the chain's composition changes by E exactly as
  the figure joint does, and where D is the identity every joint is the source's.
* **the root**: the path's root minus the base's, taken back from the scene's levelled frame into the
  capture's coordinates (the inverse of the rigid transform the scene records, `solver.capture_frame`),
  axes and unit, is added to the translation of the hips (or of the nearest joint above them that has
  position channels) in its parent's frame.
* **joints the figure does not have** (neck and head, toes, hands, fingers, end joints, static roots,
  and the inner joints above), and position channels but the root's: the source's, resampled as above.

Local rotations become each joint's Euler channels in its own order (R = R1 R2 R3 for channels listed
1 2 3, intrinsic: the BVH convention), unwrapped over time. `export_on_source` reads the file it wrote
back and measures it at the path's keyframes (runner/capture/source_check.py).
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from runner.capture.body_frames import DRIVERS
from runner.capture.bvh import POSITION_CHANNELS, BvhClip, read_bvh
from runner.capture.bvh_kinematics import rotate
from runner.capture.figure_record import clip_skeleton, figure_skeleton_digest, skeleton_digest
from runner.capture.retarget import check_figure
from runner.capture.skeleton import RecognisedSkeleton
from runner.capture.source_check import ON_FRAME, keys_on_source
from solver.capture_frame import CaptureFrame
from solver.errors import InputError
from solver.figure import Figure
from solver.quaternion import conj, mul, normalize

__all__ = ["source_clip", "root_correction", "source_motion", "source_bvh_text", "write_source_bvh",
           "export_on_source"]

_DECIMALS = 6


def source_clip(saved) -> BvhClip | None:
    """The BVH clip a saved path was made from: its embedded text (`clip_text`), else the file its `clip`
    field names (relative to the .npz); None for a path not made from a clip.

    Raises:
        InputError: the path names a clip that is neither embedded nor found (file named, with the fix).
    """
    arrays = saved.arrays
    text = str(arrays["clip_text"]) if "clip_text" in arrays else ""
    name = str(arrays["clip"]) if "clip" in arrays else ""
    if text:
        with tempfile.TemporaryDirectory(prefix="dynsplines-clip-") as tmp:
            path = Path(tmp) / (Path(name).name or "clip.bvh")
            path.write_text(text, encoding="utf-8")
            clip = read_bvh(path)
        return _renamed(clip, name or "the embedded clip")
    if not name:
        return None
    path = Path(name) if Path(name).is_absolute() else (Path(saved.source).parent / name).resolve()
    if not path.is_file():
        raise InputError(f"{saved.source}: the path was made from the clip {name} (relative to the .npz), which is "
                         f"not at {path}; put the clip back or give --skeleton figure")
    return read_bvh(path)


def _renamed(clip: BvhClip, source: str) -> BvhClip:
    from dataclasses import replace

    return replace(clip, source=source)


def _slerp_source(clip: BvhClip, first: int, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The source's local rotations (n, J, 4) (w x y z, file axes) and translations (n, J, 3) [units] at
    `times` [s] (t = 0 at frame `first`, the first after the rest frames): at a captured frame's time
    (within `ON_FRAME` of a frame) that frame's own values, copied; between frames slerp and linear."""
    from scipy.spatial.transform import Rotation, Slerp

    quat, pos = clip.local_quat[first:], clip.local_pos[first:]
    t_src = np.arange(len(quat)) * clip.frame_time
    t = np.clip(times, 0.0, t_src[-1])
    k = np.rint(t / clip.frame_time).astype(int)
    on = np.abs(t / clip.frame_time - k) < ON_FRAME
    out_q, out_p = quat[np.minimum(k, len(quat) - 1)].copy(), pos[np.minimum(k, len(pos) - 1)].copy()
    if not on.all():
        between = t[~on]
        for j in range(quat.shape[1]):
            rot = Rotation.from_quat(quat[:, j][:, [1, 2, 3, 0]])
            out_q[~on, j] = Slerp(t_src, rot)(between).as_quat()[:, [3, 0, 1, 2]]
            out_p[~on, j] = np.stack([np.interp(between, t_src, pos[:, j, c]) for c in range(3)], -1)
    return out_q, out_p


def _world(clip: BvhClip, local: np.ndarray, trans: np.ndarray, upto: int) -> tuple[np.ndarray, np.ndarray]:
    """World orientations (n, K, 4) and positions (n, K, 3) [units], file axes, of joint `upto` and its
    ancestors (indexed as the clip's joints, the others left zero) from local rotations and translations."""
    chain = [upto]
    while clip.parents[chain[-1]] >= 0:
        chain.append(int(clip.parents[chain[-1]]))
    q, p = np.zeros(local.shape), np.zeros(trans.shape)
    for j in reversed(chain):
        par = clip.parents[j]
        q[:, j] = local[:, j] if par < 0 else mul(q[:, par], local[:, j])
        p[:, j] = trans[:, j] if par < 0 else p[:, par] + rotate(q[:, par], trans[:, j])
    return q, p


def root_correction(clip: BvhClip, skel: RecognisedSkeleton, model, reference, times: np.ndarray) -> np.ndarray:
    """The reference's root correction c(t) at `times`, in the capture's coordinates [file units, axes].

    c = A^T (R^T (reference root - shift)) / unit - hips, at the reference's frames: the reference root
    taken back by the inverse of the scene's capture frame (x' = R x + shift, `solver.capture_frame`)
    and into the file's axes (A = skel.axes) and units, minus the source's own hips (forward kinematics
    of the clip). On the subject's own figure that is the per-frame height correction of the import
    (`runner.capture.root_height.correct_root_height`, a few mm, vertical in the levelled frame). Linear
    between the reference's frames, held before the first and after the last.

    Args:
        clip: the source clip. skel: its recognised skeleton. model: the scene (its figure and capture frame).
        reference: (times (r,) [s], qpos (r, nq)) the reference motion the path was made against (the
            saved path's `reference_times`, `reference_qpos`), or None.
        times: (n,) [s] the export times, 0 at the clip's first frame after its rest frames.
    Returns:
        (n, 3) c [file units] in file axes; zeros without a reference (fewer than 2 frames).
    Raises:
        InputError: the scene's capture frame is malformed.
    """
    times = np.asarray(times, float)
    if reference is None or len(reference[0]) < 2:
        return np.zeros((len(times), 3))
    ref_t, ref_q = np.asarray(reference[0], float), np.asarray(reference[1], float)
    adr = check_figure(Figure.from_model(model)).joints[0].qpos_slice.start
    back = CaptureFrame.from_model(model).inverse().points(ref_q[:, adr:adr + 3])
    ref_root = back @ skel.axes / skel.unit  # the reference root in the capture's coordinates, file axes
    local, trans = _slerp_source(clip, skel.rest_frames, ref_t)
    hips = skel.index(clip, "hips")
    c = ref_root - _world(clip, local, trans, hips)[1][:, hips]
    return np.stack([np.interp(times, ref_t, c[:, k]) for k in range(3)], axis=-1)


def source_motion(clip: BvhClip, model, qpos: np.ndarray, times: np.ndarray, reference=None) -> tuple[np.ndarray, ...]:
    """The source skeleton's local rotations and translations for a figure motion: the source plus the
    motion's change relative to the capture as the figure has it (module docstring).

    Args:
        clip: the source clip. model: the scene (its figure, made for the clip's skeleton, and the
            transform from the capture's coordinates to the scene's that it records). qpos: (n, nq)
            the motion, in the scene. times: (n,) [s] its sample times, 0 at the clip's first frame
            after its rest frames.
        reference: (times (r,) [s], qpos (r, nq)) the reference the path was made against (the saved
            path's `reference_times`, `reference_qpos`), whose root is the base's; None: the captured hips.
    Returns:
        local: (n, J, 4) unit local rotations (w x y z) in file axes; trans: (n, J, 3) local
        translations [file units]. Where `qpos` is the base, the source's own values.
    Raises:
        InputError: the skeleton cannot be recognised, the figure is not the one the retargeting drives,
            or the scene's capture frame is malformed.
    """
    from dataclasses import replace

    from runner.capture.retarget import retarget
    from solver.layout import StateLayout

    skel, frames, _ = clip_skeleton(clip, model)
    figure = check_figure(Figure.from_model(model))
    adr = figure.joints[0].qpos_slice.start
    back = CaptureFrame.from_model(model).inverse()
    times = np.asarray(times, float)
    path = back.root(np.asarray(qpos, float), adr)  # the motion in the capture's coordinates
    local, trans = _slerp_source(clip, skel.rest_frames, times)
    sampled = replace(clip, local_quat=local, local_pos=trans, raw=None)
    base = retarget(sampled, skel, frames, figure, StateLayout.from_model(model))  # capture's coordinates
    local = local.copy()
    for joint in figure.joints:
        body = figure.joint_bodies[joint.name][1]
        j = skel.index(clip, DRIVERS[body])
        q = slice(joint.qpos_slice.stop - 4, joint.qpos_slice.stop)  # a free joint's quaternion follows its position
        change = mul(conj(normalize(base[:, q])), normalize(path[:, q]))  # D, in the body's frame
        off = np.broadcast_to(frames.offsets[body], change.shape)
        e = mul(mul(off, change), conj(off))  # E = R_off D R_off^-1, in the driving joint's frame
        e[:, 1:] = e[:, 1:] @ skel.axes  # into the file's axes: E' = A^T E A
        local[:, j] = normalize(mul(local[:, j], e))
    root = base[:, adr:adr + 3]
    if reference is not None and len(reference[0]) >= 2:
        ref_t = np.asarray(reference[0], float)
        ref_root = back.points(np.asarray(reference[1], float)[:, adr:adr + 3])
        root = np.stack([np.interp(times, ref_t, ref_root[:, k]) for k in range(3)], axis=-1)
    move = (path[:, adr:adr + 3] - root) @ skel.axes / skel.unit  # [file units], file axes
    _move_hips(clip, skel, local, trans, move, skel.index(clip, "hips"))
    return local, trans


def _root_carrier(clip: BvhClip, skel: RecognisedSkeleton) -> int | None:
    """The hips or the nearest joint above them with position channels, whose channels carry the root's path;
    None where none has them (the file's root stands at its OFFSET: the export gives it position channels)."""
    k = skel.index(clip, "hips")
    while k >= 0 and clip.names[k] not in skel.position_joints:
        k = int(clip.parents[k])
    return k if k >= 0 else None


def _move_hips(clip: BvhClip, skel: RecognisedSkeleton, local, trans, move: np.ndarray, hips: int) -> None:
    """Move the hips by `move` (n, 3) [file units, file axes] in place: add it, in the parent's frame, to
    the translation in `trans` of the hips or of the nearest joint above them with position channels
    (the joints between them and the hips are not turned by the path: none drives a figure body), or, where
    none has them, of the file's root (`source_bvh_text` then writes its position channels)."""
    k = _root_carrier(clip, skel)
    k = int(np.flatnonzero(np.asarray(clip.parents) < 0)[0]) if k is None else k
    par = int(clip.parents[k])
    if par < 0:
        trans[:, k] = trans[:, k] + move
    else:
        q, _ = _world(clip, local, trans, par)
        trans[:, k] = trans[:, k] + rotate(conj(q[:, par]), move)


def _euler(q: np.ndarray, order: str) -> np.ndarray:
    """(n, 3) angles [deg] of (n, 4) w x y z rotations for intrinsic `order` (e.g. "ZYX"), unwrapped."""
    import warnings

    from scipy.spatial.transform import Rotation

    with warnings.catch_warnings():  # gimbal lock: scipy sets the third angle to 0, still the same rotation
        warnings.simplefilter("ignore", UserWarning)
        ang = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_euler(order.upper(), degrees=True)
    return np.degrees(np.unwrap(np.radians(ang), axis=0))


def source_bvh_text(clip: BvhClip, text: str, model, qpos: np.ndarray, times: np.ndarray, fps: float,
                    reference=None) -> str:
    """The BVH file of a figure motion on the source skeleton (module docstring).

    Args:
        clip: the source clip, parsed. text: its file's text (the HIERARCHY and rest frames are copied).
        model: the scene. qpos: (n, nq). times: (n,) [s]. fps: [Hz] the samples' rate.
        reference: (times, qpos) of the reference the path was made against, or None (`source_motion`).
    """
    local, trans = source_motion(clip, model, qpos, times, reference)
    skel = clip_skeleton(clip, model)[0]
    first, added = skel.rest_frames, _root_carrier(clip, skel) is None
    cols = [trans[:, 0, k] for k in range(3)] if added else []  # a root without position channels gets them
    for j, chans in enumerate(clip.channels):
        rot = [c[0] for c in chans if c.endswith("rotation")]
        angles = dict(zip(rot, _euler(local[:, j], "".join(rot)).T, strict=True)) if rot else {}
        for c in chans:
            if c in POSITION_CHANNELS:
                cols.append(trans[:, j, POSITION_CHANNELS.index(c)])
            else:
                cols.append(angles[c[0]])
    rows = np.stack(cols, axis=1) + 0.0
    lines = text.splitlines()
    m = next(i for i, ln in enumerate(lines) if ln.split()[:1] == ["MOTION"])
    data = [ln for ln in lines[m + 1:] if ln.strip()]
    same_rate = abs(fps * clip.frame_time - 1.0) < 1e-6
    fmt = f"{{:.{_DECIMALS}f}}"
    frame_time = data[1].split(":", 1)[1].strip() if same_rate else f"{1.0 / fps:.9f}"
    head, rest = lines[:m], [ln.strip() for ln in data[2:2 + first]]
    if added:  # the root's CHANNELS line and rest frames with its position (its OFFSET) first
        c = next(i for i, ln in enumerate(head) if ln.split()[:1] == ["CHANNELS"])
        tok, indent = head[c].split(), head[c][:len(head[c]) - len(head[c].lstrip())]
        line = " ".join(["CHANNELS", str(int(tok[1]) + 3), *POSITION_CHANNELS, *tok[2:]])
        head = head[:c] + [indent + line] + head[c + 1:]
        rest = [" ".join([fmt.format(v) for v in clip.offsets[0]] + [ln]) for ln in rest]
    out = head + ["MOTION", f"Frames: {len(rows) + first}", f"Frame Time: {frame_time}"] + rest
    out += [" ".join(fmt.format(v) for v in row) for row in rows]
    return "\n".join(out) + "\n"


def write_source_bvh(out: str | Path, saved, model, qpos: np.ndarray, times: np.ndarray, fps: float,
                     clip: BvhClip | None = None, as_solved: bool = False) -> tuple[BvhClip, int]:
    """Write a motion of saved path `saved` onto its source skeleton (`source_bvh_text`), atomically; the
    root is moved as the path's root is from its reference's (`source_motion`: the reference's root-height
    correction taken off), unless `as_solved` (from the captured hips: the feet where the solve put them on
    the scene's surfaces). `clip`: the path's source clip if already read (`source_clip`), else it is read.

    Returns:
        (the source clip (its joints are the file's), the frames written: the motion's and the source's
        leading rest frames).
    Raises:
        InputError: the path was not made from a BVH clip, or its clip is missing (`source_clip`).
    """
    from runner.files import atomic_output

    clip = clip or source_clip(saved)
    if clip is None:
        raise InputError(f"{saved.source}: the path was not made from a BVH clip, so it has no source skeleton; "
                         "give --skeleton figure")
    text = str(saved.arrays["clip_text"]) if str(saved.arrays.get("clip_text", "")) else Path(clip.source).read_text(encoding="utf-8-sig")
    reference = (saved.reference_times, saved.reference_qpos) if saved.has_reference and not as_solved else None
    body = source_bvh_text(clip, text, model, qpos, times, fps, reference)
    with atomic_output(out) as tmp:
        Path(tmp).write_text(body, encoding="utf-8")
    return clip, len(qpos) + clip_skeleton(clip, model)[0].rest_frames


def export_on_source(npz, out, which: str = "optimized", fps: float | None = None, required: bool = False,
                     as_solved: bool = False, clip: BvhClip | None = None):
    """`dynsplines export PATH.npz --to FILE.bvh` onto the source skeleton (module docstring).

    Args:
        npz: the saved path. out: the .bvh file. which: the motion. fps: [Hz] (None: the clip's rate).
        required: `--skeleton source` was given: a path without a clip is an error (else None is returned,
            and the caller writes the figure's skeleton).
        as_solved: keep the reference's root-height correction (`write_source_bvh`; `--root-height solved`).
        clip: the path's source clip as the run that made it parsed it (`runner.capture.clip.Capture.clip`),
            or None: parsed from the path's embedded text or its file (`source_clip`). The file written is
            read back all the same.
    Returns:
        `runner.export.ExportResult` (its frames the file's, rest frames included; its `check` the file read
        back at the path's keyframes, `runner.capture.source_check.KeysOnSource`), or None (no clip, not required).
    Raises:
        InputError: as `runner.export.prepare_export`; a missing clip; a failed write.
    """
    import time

    from runner.export import ExportResult, prepare_export

    t0 = time.perf_counter()
    fmt, saved, model, motion = prepare_export(npz, out, which, fps)
    if fmt != "BVH":
        raise InputError(f"--to {out}: --skeleton source writes BVH only; give a .bvh file or --skeleton figure")
    clip = clip if clip is not None else source_clip(saved)
    if clip is None:
        if required:
            raise InputError(f"{npz}: the path was not made from a BVH clip, so it has no source skeleton; "
                             "give --skeleton figure")
        return None
    if figure_skeleton_digest(model) != skeleton_digest(clip):
        # another figure (the shipped one, a hand-made file's): its bone lengths and root path are not the
        # source's, so on the source skeleton its planted feet would slide
        if required:
            raise InputError(f"{npz}: the path's figure is not the subject's own figure of {Path(clip.source).name} "
                             "(made with --figure default or a hand-made file), so its motion does not fit the source "
                             "skeleton; give --skeleton figure, or redo the clip with --figure subject")
        return None
    try:
        clip, frames = write_source_bvh(out, saved, model, motion.qpos, motion.times, motion.fps, clip, as_solved)
    except OSError as e:
        raise InputError(f"cannot write {out}: {e.strerror or e}; an earlier file there is unchanged; free some "
                         "space or choose another --to") from None
    notes = tuple(filter(None, [root_taken_off(clip, model, motion.qpos, motion.times, out)]))
    check = None
    if saved.keyframe_times is not None and len(saved.keyframe_times):
        skel = clip_skeleton(clip, model)[0]
        command = saved.options.get("command") or {}
        held = command.get("pins") if command.get("mode") == "clean" else None  # a clean's ends are free (a
        # saved path from before the pins were recorded: every keyframe held, as it was checked then)
        check = keys_on_source(clip, out, skel.rest_frames, skel.unit, saved.keyframe_times, float(motion.times[0]),
                               motion.fps, held)
    return ExportResult(Path(out), "BVH on the source skeleton", which, motion.fps, frames, len(clip.names),
                        Path(out).stat().st_size, time.perf_counter() - t0, check, notes)


def root_taken_off(clip: BvhClip, model, qpos: np.ndarray, times: np.ndarray, written: str | Path) -> str | None:
    """The line to print where the written file's hips are further from the path's root than a scene fitted to
    the capture's feet moves them (`runner.capture.root_height.ROOT_CORRECTION_MAX`, 3 cm): the export took off
    a larger root-height correction, which the import made all the same (its warning: a site far inside a
    surface, or a scene that does not fit), so there the file's feet are the capture's, not where the summary
    measured the path. Measured on the file read back (`read_bvh`, bvhio): its hips' world positions against
    the path's root taken back into the capture's coordinates. None otherwise.

    Args:
        clip: the source clip. model: the scene. qpos: (n, nq) the motion written, at `times` (n,) [s] (0 at the
            clip's first frame after its rest frames). written: the BVH file written."""
    from runner.capture.root_height import ROOT_CORRECTION_MAX

    skel = clip_skeleton(clip, model)[0]
    adr = check_figure(Figure.from_model(model)).joints[0].qpos_slice.start
    solved = CaptureFrame.from_model(model).inverse().points(np.asarray(qpos)[:, adr:adr + 3]) @ skel.axes / skel.unit
    back = read_bvh(written)
    hips = skel.index(back, "hips")
    rest = skel.rest_frames
    size = np.linalg.norm(_world(back, back.local_quat[rest:], back.local_pos[rest:], hips)[1][:, hips] - solved,
                          axis=1) * skel.unit
    i = int(np.argmax(size)) if len(size) else 0
    if not len(size) or size[i] <= ROOT_CORRECTION_MAX:
        return None
    return (f"the file's hips are up to {1000 * size[i]:.0f} mm ({times[i]:.2f} s) from the path's root, read back: "
            f"the root-height correction taken off (--root-height source) is beyond the {1000 * ROOT_CORRECTION_MAX:.0f} "
            "mm of a scene that fits the capture's feet, so there the file's feet are as far in or above the surfaces as "
            "the capture's, not where the summary measured the path; --root-height solved writes the motion as solved")
