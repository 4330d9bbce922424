"""How far a cleaned clip is from its capture, and whether the change adds a jolt (`dynsplines clean`).

* **Deviation**: the distance between each body's origin on the cleaned clip and on the capture (MuJoCo's
  forward kinematics, `xpos`), over every frame and body: mean and max [cm] (the field's mean per-joint
  position error, MPJPE, measured against the capture instead of a ground truth); and the angle between each
  joint's rotation on the cleaned clip and on the capture (the geodesic angle 2 acos |<q, q_ref>| of the local
  quaternions of every ball joint and of the free root, `runner.motion_metrics`' joint_orientation_deg), over every
  frame and joint: mean and max [deg] (the field's mean per-joint angle error, MPJAE).
* **The soles' edges**: how much deeper than the capture a sole's edge goes into a surface at the same frame
  (`solver.figure.Figure.soles`, the sole constraint's measure; 0 for a figure without them) [mm]: a foot
  rolled onto its edge.
* **The change's jolts**: the peak acceleration of the change, a_clean - a_capture (finite differences of
  both at the frame rate, `runner.jolts.differentiate`): the pelvis's [m/s^2] and the largest ball joint's
  [rad/s^2], beside the capture's own peaks after the 6 Hz low-pass filter (`runner.jolts.jolt_figures`):
  a change no harder than those adds no jolt the captured motion does not already have.
"""
from __future__ import annotations

import numpy as np

from solver.layout import StateLayout
from solver.quaternion import angle_between

__all__ = ["clean_figures"]


def _body_positions(model, qpos: np.ndarray) -> np.ndarray:
    """(n, nbody - 1, 3) [m] every body's origin but the world's (MuJoCo `mj_kinematics`)."""
    import mujoco

    data = mujoco.MjData(model)
    out = np.empty((len(qpos), model.nbody - 1, 3))
    for i, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        out[i] = data.xpos[1:]
    return out


def _joint_angles(model, clean: np.ndarray, capture: np.ndarray) -> np.ndarray:
    """(n, j) [deg] the angle between the cleaned clip's and the capture's rotation of each ball joint and of the
    free root (every quaternion of the state, `StateLayout.quat_slots`) at every frame (module docstring)."""
    q = StateLayout.from_model(model).quat_slots  # (j, 4) each rotation's qpos components
    return np.degrees(angle_between(clean[:, q], capture[:, q]))


def _sole_beyond_mm(model, clean: np.ndarray, capture: np.ndarray) -> float:
    """[mm] the most any sole edge goes deeper into a surface than on the capture at the same frame (module
    docstring); 0 without soles or surfaces."""
    from solver.figure import Figure
    from solver.surfaces import StaticSurfaces
    from solver.terms.penetration import Penetration

    soles = Figure.from_model(model).sole_sites
    if not soles or not StaticSurfaces.from_model(model).count:
        return 0.0
    pen = Penetration(model, sites=soles)
    return 1000.0 * float(np.maximum(0.0, pen.depths(clean) - pen.depths(capture)).max(initial=0.0))


def clean_figures(model, clean: np.ndarray, capture: np.ndarray, fps: float, capture_filtered: np.ndarray) -> dict:
    """The deviation of a cleaned clip from its capture and the change's peak accelerations (module docstring).

    Args:
        model: the scene's MjModel (a figure with a free root and ball joints). clean, capture: (n, nq)
            frames at i / fps, n >= 3. fps: [Hz] > 0. capture_filtered: (n, nq) the capture low-pass
            filtered at 6 Hz (`runner.jolts.filter_capture`).
    Returns:
        {"deviation_mean_cm", "deviation_max_cm", "angle_mean_deg", "angle_max_deg", "sole_mm", "change_pelvis_m_s2",
        "change_joint_rad_s2", "change_joint", "capture_pelvis_m_s2", "capture_joint_rad_s2"} (JSON-serializable floats
        and a name).
    Raises:
        InputError: shapes that do not fit the model or fewer than 3 frames (`runner.jolts.differentiate`).
    """
    from runner.jolts import _joints, differentiate, jolt_figures

    clean, capture = np.asarray(clean, float), np.asarray(capture, float)
    dev = np.linalg.norm(_body_positions(model, clean) - _body_positions(model, capture), axis=-1)
    angle = _joint_angles(model, clean, capture)
    da = differentiate(model, clean, fps)[1] - differentiate(model, capture, fps)[1]
    free, balls, _ = _joints(model)
    pelvis = float(np.linalg.norm(da[:, free:free + 3], axis=1).max()) if free is not None else float("nan")
    peaks = {name: float(np.linalg.norm(da[:, adr:adr + 3], axis=1).max()) for name, adr in balls.items()}
    worst = max(peaks, key=peaks.get, default="")
    own = jolt_figures(model, capture_filtered, fps)
    return {"deviation_mean_cm": 100.0 * float(dev.mean()), "deviation_max_cm": 100.0 * float(dev.max()),
            "angle_mean_deg": float(angle.mean()), "angle_max_deg": float(angle.max(initial=0.0)),
            "sole_mm": _sole_beyond_mm(model, clean, capture),
            "change_pelvis_m_s2": pelvis, "change_joint_rad_s2": peaks.get(worst, float("nan")), "change_joint": worst,
            "capture_pelvis_m_s2": own["peak_pelvis_acceleration_m_s2"],
            "capture_joint_rad_s2": own["peak_angular_acceleration_max_rad_s2"]}
