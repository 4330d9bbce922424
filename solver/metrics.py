"""What the optimization bought, measured on the continuous path (dense sampling, default 1000 Hz).

These are the acceptance figures: penetration depth of the contact sites [mm], quaternion norm
deviation, knee/elbow hyperextension [deg], keyframe error. They use the true surfaces (no margin).
"""
from __future__ import annotations

import numpy as np

from solver.frames import FrameSet
from solver.keyframes import Keyframes
from solver.layout import StateLayout
from solver.spline import interpolate
from solver.terms.bending import Hyperextension
from solver.terms.penetration import CONTACT_SITES, Penetration


def sample_times(t0: float, t1: float, rate: float) -> np.ndarray:
    """(n,) times from t0 to t1 inclusive at `rate` samples per second [s]."""
    return np.linspace(t0, t1, int(round((t1 - t0) * rate)) + 1)


def keyframe_error(frames: FrameSet | tuple, keyframes: Keyframes, quat_slots) -> float:
    """Largest |Y(t_k) - keyframe value| over components the keyframes fix.

    The path is evaluated by re-interpolating the frames (not read from the frame array), so this
    checks the spline too. Quaternions compare up to the sign of the whole quaternion (q and -q are
    one rotation; keyframes are hemisphere-aligned before interpolation).
    """
    times, values = (frames.times, frames.values) if isinstance(frames, FrameSet) else frames
    Y = interpolate(times, values, keyframes.times)
    target = keyframes.values.copy()
    for slot in np.asarray(quat_slots).reshape(-1, 4):
        flip = np.nansum(Y[:, slot] * target[:, slot], axis=1) < 0
        target[np.ix_(flip, slot)] *= -1
    err = np.abs(Y - target)[keyframes.mask]
    return float(err.max()) if err.size else 0.0


def path_metrics(model, frame_times, frames, keyframes: Keyframes | None = None, rate: float = 1000.0,
                 sites=CONTACT_SITES) -> dict:
    """Acceptance figures of a path (the natural cubic spline through frames).

    Args:
        model: MjModel of the scene. frame_times: (m,) [s]. frames: (m, nq).
        keyframes: to report the keyframe error (optional). rate: samples per second.
    Returns:
        dict with max_penetration_mm, penetration_mm_by_site {site: mm}, max_norm_deviation (max over
        time and quaternions of |1 - |q||), max_hyperextension_deg {joint: deg} and overall,
        keyframe_error (if keyframes given), samples.
    """
    layout = StateLayout.from_model(model)
    t = sample_times(frame_times[0], frame_times[-1], rate)
    Y = interpolate(frame_times, frames, t)
    pen = Penetration(model, sites=sites, margin=0.0)
    depth = pen.depths(Y, margin=0.0) * 1000.0  # (n, k) mm
    norms = np.linalg.norm(Y[:, layout.quat_slots], axis=-1)
    out = {
        "samples": len(t),
        "rate_hz": rate,
        "max_penetration_mm": float(depth.max()),
        "penetration_mm_by_site": dict(zip(sites, depth.max(axis=0).round(3).tolist())),
        "max_norm_deviation": float(np.abs(1.0 - norms).max()),
    }
    try:
        bend = Hyperextension(layout)
        hyper = np.degrees(np.maximum(0.0, -bend.angles(Y))).max(axis=0)
        out["max_hyperextension_deg_by_joint"] = dict(zip(bend.joint_names, hyper.round(3).tolist()))
        out["max_hyperextension_deg"] = float(hyper.max())
    except Exception:  # a figure without knees/elbows
        out["max_hyperextension_deg"] = float("nan")
    if keyframes is not None:
        out["keyframe_error"] = keyframe_error((frame_times, frames), keyframes, layout.quat_slots)
    return out
