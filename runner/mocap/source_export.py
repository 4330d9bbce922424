"""A saved path written back onto the skeleton of the BVH clip it came from (`dynsplines export --to
FILE.bvh`, docs/export.md "Onto the source skeleton").

The file has the source's HIERARCHY verbatim (joint names, OFFSETs, channel order, units) and its frame
rate, and starts, like the source, with the source's synthetic T-pose frame; frame k + 1 is the path
at t = k / fps. Per joint:

* **modelled** (the joint that drives a figure body, `runner.mocap.retarget.BONE_MAP`: Hips, the
  UpLegs, Legs, Feet, Spine1, Arms, ForeArms): its world orientation is the figure body's times the
  inverse rest offset (`rest_offsets`: figure world = source world x R_off, so source world = figure
  world x R_off^-1). A merged chain is split back by keeping the source's inner joints and solving the
  last one: with LowerBack and Spine resampled from the source, Spine1's local rotation is the one
  whose composition with them gives the torso's world orientation; likewise LHipJoint before the
  thigh, LeftShoulder before the arm. The root translation is the path's root position minus the
  reference's height correction c(t) (`root_correction`: the import stands the captured feet on the
  fitted surfaces by moving the root at most 3 cm up or down per frame, `runner.mocap.contacts.
  correct_root_height`; the export takes that off again). Both are taken back from the scene's levelled
  frame into the capture's coordinates first (the inverse of the rigid transform the scene records,
  `solver.capture_frame`; docs/mocap.md), so the file lies where the source does: the reference itself
  exports to the source's root path, and an optimized path to it at its keyframes.
* **not modelled** (neck and head, toes, hands, fingers, thumbs, and the inner joints above): the
  source's local rotations, resampled to the export times (spherical linear interpolation between the
  neighbouring captured frames, `scipy.spatial.transform.Slerp`; at the captured times, the source's own).

Local rotations become each joint's Euler channels in its own order (R = R1 R2 R3 for channels listed
1 2 3, intrinsic: the BVH convention), unwrapped over time.
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from runner.mocap.bvh import POSITION_CHANNELS, BvhClip, read_bvh
from runner.mocap.retarget import BONE_MAP, BVH_TO_MUJOCO, UNIT_TO_METRES, check_figure, check_skeleton, rest_offsets
from runner.mocap.subject_figure import figure_skeleton_digest, skeleton_digest
from solver.capture_frame import CaptureFrame
from solver.errors import InputError
from solver.figure import Figure
from solver.quaternion import conj, mul, normalize

__all__ = ["source_clip", "root_correction", "source_motion", "source_bvh_text", "write_source_bvh", "export_on_source"]

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


def _slerp_source(clip: BvhClip, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The source's local rotations (n, J, 4) (w x y z, BVH axes) and translations (n, J, 3) [units] at
    `times` [s] (t = 0 at the first frame after the T-pose), slerp and linear between captured frames."""
    from scipy.spatial.transform import Rotation, Slerp

    quat, pos = clip.local_quat[1:], clip.local_pos[1:]
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


def root_correction(clip: BvhClip, model, reference, times: np.ndarray) -> np.ndarray:
    """The reference's root correction c(t) at `times`, in the capture's coordinates [BVH units].

    c = R^T (reference root - T(captured root)) at the reference's frames, with T: x' = R x + shift the
    scene's capture frame (`solver.capture_frame`), i.e. the reference root taken back to the capture's
    coordinates minus the clip's own root (its `Hips` translation); on the subject's own figure that is
    the per-frame height correction of the import (`runner.mocap.contacts.correct_root_height`, a few
    mm, vertical in the levelled frame). Linear between the reference's frames, held before the first and
    after the last.

    Args:
        clip: the source clip. model: the scene (its figure and capture frame).
        reference: (times (r,) [s], qpos (r, nq)) the reference motion the path was made against (the
            saved path's `reference_times`, `reference_qpos`), or None.
        times: (n,) [s] the export times, 0 at the clip's first frame after the T-pose.
    Returns:
        (n, 3) c [BVH units] in BVH axes; zeros without a reference (fewer than 2 frames).
    Raises:
        InputError: the scene's capture frame is malformed.
    """
    times = np.asarray(times, float)
    if reference is None or len(reference[0]) < 2:
        return np.zeros((len(times), 3))
    ref_t, ref_q = np.asarray(reference[0], float), np.asarray(reference[1], float)
    adr = check_figure(Figure.from_model(model)).joints[0].qpos_slice.start
    back = CaptureFrame.from_model(model).inverse().points(ref_q[:, adr:adr + 3])
    ref_root = back @ BVH_TO_MUJOCO / UNIT_TO_METRES  # the reference root in the capture's coordinates, BVH axes
    _, trans = _slerp_source(clip, ref_t)
    c = ref_root - trans[:, 0]
    return np.stack([np.interp(times, ref_t, c[:, k]) for k in range(3)], axis=-1)


def source_motion(clip: BvhClip, model, qpos: np.ndarray, times: np.ndarray, reference=None) -> tuple[np.ndarray, ...]:
    """The source skeleton's local rotations and root translation for a figure motion (module docstring).

    Args:
        clip: the source clip (CMU skeleton). model: the scene (its figure, and the transform from the
            capture's coordinates to the scene's that it records). qpos: (n, nq) the motion, in the scene.
        times: (n,) [s] its sample times, 0 at the clip's first frame after the T-pose.
        reference: (times (r,) [s], qpos (r, nq)) the reference the path was made against, whose root
            correction is taken off the root (`root_correction`); None: none (the root as the path has it).
    Returns:
        local: (n, J, 4) unit local rotations (w x y z) in BVH axes; root: (n, 3) root translation [BVH
        units]; trans: (n, J, 3) the source's local translations, resampled [BVH units].
    Raises:
        InputError: the clip is not the CMU skeleton, the figure not the one the retargeting drives, or
            the scene's capture frame is malformed.
    """
    check_skeleton(clip)
    figure = check_figure(Figure.from_model(model))
    qpos = CaptureFrame.from_model(model).inverse().root(qpos, figure.joints[0].qpos_slice.start)
    local, pos = _slerp_source(clip, np.asarray(times, float))
    fig_world = _figure_world(model, figure, qpos)
    off = rest_offsets(clip, figure)
    # the source world orientation each modelled joint must have, in BVH axes (R_bvh = M^T R M)
    target = {}
    for body, (joint, _) in BONE_MAP.items():
        q = mul(fig_world[body], np.broadcast_to(conj(off[body]), fig_world[body].shape))
        q = np.array(q)
        q[:, 1:] = q[:, 1:] @ BVH_TO_MUJOCO  # v_bvh = M^T v_mujoco
        target[clip.index(joint)] = normalize(q)
    world = np.empty_like(local)
    for j, par in enumerate(clip.parents):
        if j in target:
            local[:, j] = target[j] if par < 0 else normalize(mul(conj(world[:, par]), target[j]))
        world[:, j] = local[:, j] if par < 0 else normalize(mul(world[:, par], local[:, j]))
    root = qpos[:, figure.joints[0].qpos_slice][:, :3] @ BVH_TO_MUJOCO / UNIT_TO_METRES
    return local, root - root_correction(clip, model, reference, times), pos


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
        clip: the source clip, parsed. text: its file's text (the HIERARCHY and T-pose frame are copied).
        model: the scene. qpos: (n, nq). times: (n,) [s]. fps: [Hz] the samples' rate.
        reference: (times, qpos) of the reference the path was made against, or None (`source_motion`).
    """
    local, root, trans = source_motion(clip, model, qpos, times, reference)
    cols = []
    for j, chans in enumerate(clip.channels):
        rot = [c[0] for c in chans if c.endswith("rotation")]
        angles = dict(zip(rot, _euler(local[:, j], "".join(rot)).T, strict=True)) if rot else {}
        for c in chans:
            if c in POSITION_CHANNELS:
                k = POSITION_CHANNELS.index(c)
                cols.append(root[:, k] if j == 0 else trans[:, j, k])
            else:
                cols.append(angles[c[0]])
    rows = np.stack(cols, axis=1) + 0.0
    lines = text.splitlines()
    m = next(i for i, ln in enumerate(lines) if ln.split()[:1] == ["MOTION"])
    data = [ln for ln in lines[m + 1:] if ln.strip()]
    same_rate = abs(fps * clip.frame_time - 1.0) < 1e-6
    frame_time = data[1].split(":", 1)[1].strip() if same_rate else f"{1.0 / fps:.9f}"
    out = lines[:m] + ["MOTION", f"Frames: {len(rows) + 1}", f"Frame Time: {frame_time}", data[2].strip()]
    fmt = f"{{:.{_DECIMALS}f}}"
    out += [" ".join(fmt.format(v) for v in row) for row in rows]
    return "\n".join(out) + "\n"


def write_source_bvh(out: str | Path, saved, model, qpos: np.ndarray, times: np.ndarray, fps: float) -> BvhClip:
    """Write a motion of saved path `saved` onto its source skeleton (`source_bvh_text`), atomically; the
    root correction of the path's reference (`root_correction`) is taken off the root.

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
    reference = (saved.reference_times, saved.reference_qpos) if saved.has_reference else None
    body = source_bvh_text(clip, text, model, qpos, times, fps, reference)
    with atomic_output(out) as tmp:
        Path(tmp).write_text(body, encoding="utf-8")
    return clip


def export_on_source(npz, out, which: str = "optimized", fps: float | None = None, required: bool = False):
    """`dynsplines export PATH.npz --to FILE.bvh` onto the source skeleton (module docstring).

    Args:
        npz: the saved path. out: the .bvh file. which: the motion. fps: [Hz] (None: the clip's rate).
        required: `--skeleton source` was given: a path without a clip is an error (else None is returned,
            and the caller writes the figure's skeleton).
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
        clip = write_source_bvh(out, saved, model, motion.qpos, motion.times, motion.fps)
    except OSError as e:
        raise InputError(f"cannot write {out}: {e.strerror or e}; an earlier file there is unchanged; free some "
                         "space or choose another --to") from None
    return ExportResult(Path(out), "BVH on the source skeleton", which, motion.fps, len(motion.times) + 1,
                        len(clip.names), Path(out).stat().st_size, time.perf_counter() - t0)
