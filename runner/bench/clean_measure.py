"""The figures of a cleaned clip, measured the same way for `dynsplines clean` and its peer (`bench clean`,
`batch --mode clean`, `bench corpus --mode clean`): penetration (1000 Hz, `solver.metrics.path_metrics`),
float and skate in contact (`runner.motion_metrics`), deviation from the capture and the change's peak
accelerations against the 6 Hz capture's (`runner.clean_metrics`), all at the capture's frames of the
saved path that `dynsplines clean` writes (docs/saved-path.md)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["clean_figures_of", "clean_result_figures", "saved_capture"]


def saved_capture(saved_npz: Path):
    """(model, times (n,) [s], capture qpos (n, nq), contacts) of the saved path of a clean: the scene's
    MjModel, the retargeted capture and its contact schedule.

    Raises:
        OSError, KeyError: the file is missing or not a saved path of `dynsplines clean`.
    """
    from runner.saved_path import contacts_from_array, resolve_scene
    from solver.model import load_model

    z = np.load(saved_npz)
    model = load_model(resolve_scene(str(z["scene"]), saved_npz))
    return model, z["reference_times"], z["reference_qpos"], contacts_from_array(z["contacts"])


def clean_figures_of(saved_npz: Path, qpos: np.ndarray) -> dict:
    """The figures of one cleaned clip `qpos` (n, nq) at the capture frames of the saved path `saved_npz`.

    Returns:
        {"penetration_mm", "float_mm" (float of the sites in contact), "skate_mm" (skate in contact
        [mm/frame]), and `runner.clean_metrics.clean_figures`' deviation [cm] and peak accelerations}.
    Raises:
        OSError, KeyError: as `saved_capture`.
    """
    from runner.clean_metrics import clean_figures
    from runner.jolts import filter_capture
    from runner.motion_metrics import motion_metrics
    from solver.layout import StateLayout
    from solver.metrics import path_metrics

    model, times, ref, contacts = saved_capture(saved_npz)
    fps = 1.0 / float(np.mean(np.diff(times)))
    smooth = filter_capture(times, ref, StateLayout.from_model(model))
    feet = motion_metrics(model, qpos, fps, ref, contacts)["path"]
    pen = path_metrics(model, times, qpos, None, dynamics=False)["max_penetration_mm"]
    return {"penetration_mm": pen, "float_mm": feet["float_contact_mm"], "skate_mm": feet["skate_contact_mm"],
            **clean_figures(model, qpos, ref, fps, smooth)}


def clean_result_figures(result: dict) -> dict:
    """The figures of a clean from `runner.clean.process_clean`'s result: `clean_figures_of` its saved path's
    cleaned clip, "displacement_frames", "cpu_s" (the whole command's CPU time [s], `cpu_time_s`) and
    "solve_cpu_s" (the clean's own from the retargeted capture and its contacts [s], `solve_cpu_s`).

    Raises:
        OSError, KeyError: the saved path it names is missing or not a clean's.
    """
    npz = Path(result["outputs"]["save_path"])
    f = clean_figures_of(npz, np.load(npz)["path_qpos"])
    return f | {"displacement_frames": int(result["displacement_frames"]), "cpu_s": float(result["cpu_time_s"]),
                "solve_cpu_s": float(result["solve_cpu_s"])}
