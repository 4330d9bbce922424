"""Results out: a saved path (.npz) sampled at a frame rate and written as BVH (`bvh`) or glTF binary (`gltf`).

`sampling` samples the optimized, plain or reference motion of a saved path (read by
`runner.saved_path.load_saved_path`); the writers take MuJoCo `qpos` samples and the loaded model
(offsets, geoms and the static scene come from the model).
`export_saved_path` is the whole of `dynsplines export`.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from solver.errors import InputError

__all__ = ["FORMATS", "ExportResult", "export_saved_path", "check_output_name", "prepare_export"]

#: output file extension -> format.
FORMATS = {".bvh": "BVH", ".glb": "glTF binary"}


@dataclass(frozen=True)
class ExportResult:
    """What `export_saved_path` wrote: path, format, which motion, fps [Hz], frames (the file's, rest frames
    included), joints (bodies), size [bytes], wall_time_s [s] (sampling and writing), and `check`: for a BVH
    on a clip's own skeleton, the file read back at the keyframes (`runner.capture.source_check.KeysOnSource`),
    else None; `notes`: lines to print after it (`runner.capture.source_export.root_taken_off`)."""

    path: Path
    format: str
    which: str
    fps: float
    frames: int
    joints: int
    size: int
    wall_time_s: float
    check: object = None
    notes: tuple = ()

    def describe(self) -> str:
        """One line: what was written, e.g. for `wrote ...`."""
        return (f"{self.path} ({self.format}, {self.which}: {self.frames} frames at {self.fps:g} fps, "
                f"{self.joints} joints, {self.size / 1024:.0f} KiB, {self.wall_time_s:.2f} s)")


def check_output_name(out: str | Path, option: str = "--to") -> str:
    """The format of output file `out` from its extension; InputError naming the choices otherwise."""
    suffix = Path(out).suffix.lower()
    if suffix not in FORMATS:
        given = f"extension {suffix!r}" if suffix else "no extension"
        raise InputError(f"{option} {out}: {given}; the output must end in one of {', '.join(FORMATS)} "
                         f"(e.g. {option} {Path(out).with_suffix('.glb').name})")
    return FORMATS[suffix]


def prepare_export(npz: str | Path, out: str | Path, which: str = "optimized", fps: float | None = None,
                   option: str = "--to"):
    """What every export needs: the output format, the saved path, its scene and the motion sampled.

    Returns:
        (format, SavedPath, MjModel, `runner.export.sampling.Motion`).
    Raises:
        InputError: unknown extension, unwritable folder, unreadable path or scene, a scene for another
            figure, unknown or absent motion, bad fps.
    """
    from runner.export.sampling import WHICH, default_fps, sample_motion
    from runner.files import check_writable_dir
    from runner.saved_path import load_saved_path
    from solver.layout import StateLayout
    from solver.model import load_model

    fmt = check_output_name(out, option)
    if which not in WHICH:
        raise InputError(f"--which {which!r}: unknown motion; choose one of {', '.join(WHICH)}")
    check_writable_dir(out, option)
    saved = load_saved_path(npz)
    model = load_model(saved.scene)
    if model.nq != saved.nq:
        raise InputError(f"{npz}: frames have {saved.nq} columns but the scene {saved.scene} has nq = {model.nq}; "
                         "the path was made for another figure")
    rate = default_fps(saved) if fps is None else float(fps)
    return fmt, saved, model, sample_motion(saved, which, rate, StateLayout.from_model(model).quat_slots)


def export_saved_path(npz: str | Path, out: str | Path, which: str = "optimized",
                      fps: float | None = None, option: str = "--to") -> ExportResult:
    """Sample motion `which` of saved path `npz` at `fps` [Hz] (default: the reference clip's rate, else
    30) and write it to `out` (.bvh on the figure's own skeleton, or .glb, chosen by the extension),
    atomically. `option` is the command-line option that named `out` (for messages). The source
    skeleton of a path made from a clip: `runner.capture.source_export`.

    Raises:
        InputError: unknown extension, unwritable folder, unreadable path or scene, unknown or absent
            motion, bad fps, or a failed write (an earlier file at `out` is then unchanged).
    """
    t0 = time.perf_counter()
    fmt, saved, model, motion = prepare_export(npz, out, which, fps, option)
    try:
        if fmt == "BVH":
            from runner.export.bvh import write_bvh

            joints = write_bvh(out, model, motion.qpos, motion.fps).count
        else:
            from runner.export.bvh import figure_skeleton
            from runner.export.gltf import Track, write_glb

            write_glb(out, model, [Track(which, motion.times, motion.qpos)])
            joints = figure_skeleton(model, head=False).count
    except OSError as e:
        raise InputError(f"cannot write {out}: {e.strerror or e}; an earlier file there is unchanged; free some "
                         f"space or choose another {option}") from None
    return ExportResult(Path(out), fmt, which, motion.fps, len(motion.times), joints, Path(out).stat().st_size,
                        time.perf_counter() - t0)
