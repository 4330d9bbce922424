"""A saved path written back onto the skeleton of the BVH clip it came from (`dynsplines export --to
FILE.bvh`, docs/export.md "Onto the source skeleton").

The file has the source's HIERARCHY verbatim (joint names, OFFSETs, channel order, units) and its frame
rate, and starts, like the source, with the source's leading rest frames (the synthetic T-pose of CMU's
cgspeed conversion; none in most files); frame k + rest is the path at t = k / fps. The skeleton is
read as the import read it (the roles, unit, axes and body frames the subject's figure records,
runner/mocap/figure_record.py). Per joint:

* **driving a figure body** (`runner.mocap.body_frames.DRIVERS`: the hips, upper and lower legs, feet,
  chest, upper arms and forearms): its world orientation is the figure body's times the inverse body
  offset (figure world = source world x R_off, so source world = figure world x R_off^-1). A merged
  chain is split back by keeping the source's inner joints and solving the last one: with the spine
  joints below the chest resampled from the source, the chest's local rotation is the one whose
  composition with them gives the torso's world orientation; likewise a hip offset joint before the
  thigh, a clavicle before the arm. At a keyframe, where the path is the reference and the reference
  the retargeted source, this gives every source joint back. The hips' world position is the path's root
  position minus the reference's height correction c(t) (`root_correction`: the import stands the
  captured feet on the fitted surfaces by moving the root at most 3 cm up or down per frame,
  `runner.mocap.contacts.correct_root_height`; the export takes that off again), written into the
  position channels of the hips (or of the nearest joint above them that has some) given the source's
  joints above. Both are taken back from the scene's levelled frame into the capture's coordinates first
  (the inverse of the rigid transform the scene records, `solver.capture_frame`; docs/mocap.md), so
  the file lies where the source does.
* **not modelled** (neck and head, toes, hands, fingers, and the inner joints above; any position
  channels but those above): the source's local rotations and translations, resampled to the export
  times (spherical linear interpolation between the neighbouring captured frames,
  `scipy.spatial.transform.Slerp`; at the captured times, the source's own).

Local rotations become each joint's Euler channels in its own order (R = R1 R2 R3 for channels listed
1 2 3, intrinsic: the BVH convention), unwrapped over time.
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from runner.mocap.body_frames import DRIVERS
from runner.mocap.bvh import POSITION_CHANNELS, BvhClip, read_bvh
from runner.mocap.figure_record import clip_skeleton, figure_skeleton_digest, skeleton_digest
from runner.mocap.kinematics import file_world, forward, rotate
from runner.mocap.retarget import check_figure
from runner.mocap.skeleton import RecognisedSkeleton
from solver.capture_frame import CaptureFrame
from solver.errors import InputError
from solver.figure import Figure
from solver.quaternion import conj, mul, normalize

__all__ = ["source_clip", "root_correction", "source_motion", "keyframes_on_source", "source_bvh_text",
           "write_source_bvh", "export_on_source"]

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
    `times` [s] (t = 0 at frame `first`, the first after the rest frames), slerp and linear between
    captured frames."""
    from scipy.spatial.transform import Rotation, Slerp

    quat, pos = clip.local_quat[first:], clip.local_pos[first:]
    t_src = np.arange(len(quat)) * clip.frame_time
    t = np.clip(times, 0.0, t_src[-1])
    out_q = np.empty((len(t), quat.shape[1], 4))
    for j in range(quat.shape[1]):
        rot = Rotation.from_quat(quat[:, j][:, [1, 2, 3, 0]])
        out_q[:, j] = Slerp(t_src, rot)(t).as_quat()[:, [3, 0, 1, 2]]
    out_p = np.stack([np.stack([np.interp(t, t_src, pos[:, j, k]) for k in range(3)], -1)
                      for j in range(pos.shape[1])], 1)
    return out_q, out_p


def _figure_world(model, figure: Figure, qpos: np.ndarray) -> dict[str, np.ndarray]:
    """{body: (n, 4)} world orientation of every figure body (MuJoCo axes) for (n, nq) qpos."""
    world = {}
    for b, body in enumerate(figure.bodies):
        bid = int(figure.body_ids[b])
        joint = next(j for j in figure.joints if figure.joint_bodies[j.name][1] == body)
        q = normalize(qpos[:, joint.qpos_slice][:, -4:])  # a free joint's quaternion follows its position
        if figure.parents[b] < 0:
            world[body] = q
        else:
            frame = np.broadcast_to(model.body_quat[bid], q.shape)
            world[body] = normalize(mul(mul(world[figure.bodies[figure.parents[b]]], frame), q))
    return world


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
    (`runner.mocap.contacts.correct_root_height`, a few mm, vertical in the levelled frame). Linear
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
    """The source skeleton's local rotations and translations for a figure motion (module docstring).

    Args:
        clip: the source clip. model: the scene (its figure, made for the clip's skeleton, and the
            transform from the capture's coordinates to the scene's that it records). qpos: (n, nq)
            the motion, in the scene. times: (n,) [s] its sample times, 0 at the clip's first frame
            after its rest frames.
        reference: (times (r,) [s], qpos (r, nq)) the reference the path was made against, whose root
            correction is taken off the root (`root_correction`); None: none (the root as the path has it).
    Returns:
        local: (n, J, 4) unit local rotations (w x y z) in file axes; trans: (n, J, 3) local
        translations [file units]: the source's, resampled, but where the hips' position is solved.
    Raises:
        InputError: the skeleton cannot be recognised, the figure is not the one the retargeting drives,
            or the scene's capture frame is malformed.
    """
    skel, frames, _ = clip_skeleton(clip, model)
    figure = check_figure(Figure.from_model(model))
    qpos = CaptureFrame.from_model(model).inverse().root(qpos, figure.joints[0].qpos_slice.start)
    local, trans = _slerp_source(clip, skel.rest_frames, np.asarray(times, float))
    fig_world = _figure_world(model, figure, qpos)
    target = {}  # the source world orientation each driving joint must have, in file axes (R = A^T R' A)
    for body, role in DRIVERS.items():
        q = np.array(mul(fig_world[body], np.broadcast_to(conj(frames.offsets[body]), fig_world[body].shape)))
        q[:, 1:] = q[:, 1:] @ skel.axes
        target[skel.index(clip, role)] = normalize(q)
    world = np.empty_like(local)
    for j, par in enumerate(clip.parents):
        if j in target:
            local[:, j] = target[j] if par < 0 else normalize(mul(conj(world[:, par]), target[j]))
        world[:, j] = local[:, j] if par < 0 else normalize(mul(world[:, par], local[:, j]))
    hips = skel.index(clip, "hips")
    root = qpos[:, figure.joints[0].qpos_slice][:, :3] @ skel.axes / skel.unit
    _place_hips(clip, skel, local, trans, root - root_correction(clip, skel, model, reference, times), hips)
    return local, trans


def keyframes_on_source(clip: BvhClip, model, reference, times: np.ndarray) -> np.ndarray:
    """(K, J) [m] how far each source joint is, at the keyframe times, from the clip's own: the keyframes'
    values at those times (`Reference.keyed`, which a path meets exactly there) written onto the source
    skeleton (`source_motion`, the import's root-height correction and levelling taken off) against the
    clip's forward kinematics.
    What is left is what the import's other clean-up changed: the knee and elbow hyperextension clamp and
    the footplant (docs/mocap.md, "Back onto the source skeleton").

    Args:
        clip: the source clip. model: the scene (the subject's own figure). reference: the clip's
            `runner.mocap.retarget.Reference`. times: (K,) [s] keyframe times, on the reference's frames.
    """
    skel, _, _ = clip_skeleton(clip, model)
    times = np.asarray(times, float)
    frames = np.clip(np.rint(times / reference.frame_time).astype(int), 0, reference.count - 1)
    keyed = reference.keyed().qpos[frames]  # the keyframes' values: the capture with its resting feet planted
    local, trans = source_motion(clip, model, keyed, times, (reference.times, reference.qpos))
    _, out = forward(clip.parents, local, trans)
    _, src = file_world(clip)
    return np.linalg.norm(out - src[skel.rest_frames + frames], axis=-1) * skel.unit


def _place_hips(clip: BvhClip, skel: RecognisedSkeleton, local, trans, hips_world: np.ndarray, hips: int) -> None:
    """Set, in `trans`, the translation of the hips, or of the nearest joint above them with position
    channels, so that the hips are at `hips_world` (n, 3) [file units] given the joints above."""
    k = hips
    while clip.names[k] not in skel.position_joints:
        k = int(clip.parents[k])
    q, p = _world(clip, local, trans, hips)
    below = p[:, hips] - p[:, k]  # from joint k to the hips (zero if k is the hips)
    at_k = hips_world - below
    par = int(clip.parents[k])
    trans[:, k] = at_k if par < 0 else rotate(conj(q[:, par]), at_k - p[:, par])


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
    first = clip_skeleton(clip, model)[0].rest_frames
    cols = []
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
    frame_time = data[1].split(":", 1)[1].strip() if same_rate else f"{1.0 / fps:.9f}"
    out = lines[:m] + ["MOTION", f"Frames: {len(rows) + first}", f"Frame Time: {frame_time}"]
    out += [ln.strip() for ln in data[2:2 + first]]
    fmt = f"{{:.{_DECIMALS}f}}"
    out += [" ".join(fmt.format(v) for v in row) for row in rows]
    return "\n".join(out) + "\n"


def write_source_bvh(out: str | Path, saved, model, qpos: np.ndarray, times: np.ndarray, fps: float,
                     as_solved: bool = False) -> BvhClip:
    """Write a motion of saved path `saved` onto its source skeleton (`source_bvh_text`), atomically; the
    root correction of the path's reference (`root_correction`) is taken off the root, unless `as_solved`
    (the root as the path has it: the feet where the solve put them on the scene's surfaces).

    Returns:
        the source clip (its joints are the file's).
    Raises:
        InputError: the path was not made from a BVH clip, or its clip is missing (`source_clip`).
    """
    from runner.files import atomic_output

    clip = source_clip(saved)
    if clip is None:
        raise InputError(f"{saved.source}: the path was not made from a BVH clip, so it has no source skeleton; "
                         "give --skeleton figure")
    text = str(saved.arrays["clip_text"]) if str(saved.arrays.get("clip_text", "")) else Path(clip.source).read_text()
    reference = (saved.reference_times, saved.reference_qpos) if saved.has_reference and not as_solved else None
    body = source_bvh_text(clip, text, model, qpos, times, fps, reference)
    with atomic_output(out) as tmp:
        Path(tmp).write_text(body, encoding="utf-8")
    return clip


def export_on_source(npz, out, which: str = "optimized", fps: float | None = None, required: bool = False,
                     as_solved: bool = False):
    """`dynsplines export PATH.npz --to FILE.bvh` onto the source skeleton (module docstring).

    Args:
        npz: the saved path. out: the .bvh file. which: the motion. fps: [Hz] (None: the clip's rate).
        required: `--skeleton source` was given: a path without a clip is an error (else None is returned,
            and the caller writes the figure's skeleton).
        as_solved: keep the reference's root-height correction (`write_source_bvh`; `--root-height solved`).
    Returns:
        `runner.export.ExportResult`, or None (no clip, not required).
    Raises:
        InputError: as `runner.export.prepare_export`; a missing clip; a failed write.
    """
    import time

    from runner.export import ExportResult, prepare_export

    t0 = time.perf_counter()
    fmt, saved, model, motion = prepare_export(npz, out, which, fps)
    if fmt != "BVH":
        raise InputError(f"--to {out}: --skeleton source writes BVH only; give a .bvh file or --skeleton figure")
    clip = source_clip(saved)
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
        clip = write_source_bvh(out, saved, model, motion.qpos, motion.times, motion.fps, as_solved)
    except OSError as e:
        raise InputError(f"cannot write {out}: {e.strerror or e}; an earlier file there is unchanged; free some "
                         "space or choose another --to") from None
    return ExportResult(Path(out), "BVH on the source skeleton", which, motion.fps, len(motion.times) + 1,
                        len(clip.names), Path(out).stat().st_size, time.perf_counter() - t0)
