"""The orientation keyframe file of `dynsplines orient` (JSON) and its result (.npz).

Keyframe file (JSON):
    {"times": [0, 0.8, ...], "quaternions": [[w, x, y, z], ...]}
times in seconds, strictly increasing; quaternions need not be unit (they are normalized, as MuJoCo does).

Output (.npz): frame_times (m,) [s], frames (m, 4) - the path is the natural cubic spline through them -,
keyframe_times (k,), keyframes (k, 4) (normalized, hemisphere-aligned), wall_time_s, objective_trace,
and the summary numbers (form, energy [1/s^3], max_norm_deviation, estimated_gap (relative; NaN for the paper
form), tol (0: fixed rounds), converged_to_tol (1, 0; -1 without a tolerance), message).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from runner.files import atomic_output
from solver.errors import InputError


def read_keyframes(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read an orientation keyframe file.

    Args:
        path: JSON file {"times": [k numbers], "quaternions": [k lists of 4 numbers (w x y z)]}.
    Returns:
        times (k,) [s], quaternions (k, 4) as given (validated by `solver.paper.orient.check_keyframes`).
    Raises:
        InputError: missing or unreadable file, invalid JSON, missing or malformed field; the message
            names the file, the field and the value.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"keyframe file {path} does not exist")
    try:
        data = json.loads(path.read_text(encoding="utf-8-sig"))
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text file; expected JSON") from None
    except json.JSONDecodeError as e:
        raise InputError(f"{path}: invalid JSON at line {e.lineno} column {e.colno}: {e.msg}") from None
    if not isinstance(data, dict):
        raise InputError(f'{path}: expected a JSON object {{"times": [...], "quaternions": [...]}}, '
                         f"got {type(data).__name__}")
    for key in ("times", "quaternions"):
        if key not in data:
            raise InputError(f"{path}: missing field {key!r}; the file needs \"times\" and \"quaternions\" "
                             f"(it has: {', '.join(map(repr, data)) or 'nothing'})")
    times, quats = data["times"], data["quaternions"]
    if not isinstance(times, list) or not all(_is_number(t) for t in times):
        raise InputError(f"{path}: field 'times' must be a list of numbers [s], got {_short(times)}")
    if not isinstance(quats, list):
        raise InputError(f"{path}: field 'quaternions' must be a list of [w, x, y, z], got {_short(quats)}")
    for i, q in enumerate(quats):
        if not isinstance(q, list) or len(q) != 4 or not all(_is_number(c) for c in q):
            raise InputError(f"{path}: quaternions[{i}] is {_short(q)}; expected 4 numbers [w, x, y, z]")
    if len(times) != len(quats):
        raise InputError(f"{path}: {len(times)} times but {len(quats)} quaternions; give one time per quaternion")
    return np.asarray(times, dtype=float), np.asarray(quats, dtype=float).reshape(-1, 4)


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _short(v) -> str:
    s = json.dumps(v)
    return s if len(s) <= 60 else s[:57] + "..."


def write_result(path: str | Path, result) -> None:
    """Write an OrientResult as .npz atomically (temporary file in the same folder, then rename)."""
    fr = result.frames
    with atomic_output(path, suffix=".npz") as tmp:
        np.savez(
            tmp,
            frame_times=fr.times,
            frames=fr.values,
            keyframe_times=result.keyframe_times,
            keyframes=result.keyframes,
            is_keyframe=fr.is_keyframe,
            wall_time_s=np.float64(result.wall_time_s),
            objective_trace=result.objective_trace,
            form=np.str_(result.form),
            weights=np.asarray(result.weights),
            energy=np.float64(result.energy),
            energy_initial=np.float64(result.energy_initial),
            max_norm_deviation=np.float64(result.max_norm_deviation),
            estimated_gap=np.float64(result.estimated_gap),
            tol=np.float64(result.tol),
            converged_to_tol=np.int8(-1 if result.converged_to_tol is None else int(result.converged_to_tol)),
            message=np.str_(result.solution.message),
        )

