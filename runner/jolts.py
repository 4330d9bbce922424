"""Jolts: how hard a sampled motion accelerates the pelvis and each ball joint, and the joint torque it asks
for, measured the way an independent checker would (docs/corpus.md "Bounds").

The motion is given as frames sampled at a fixed rate (the capture's, 120 Hz for the CMU clips), as the
motion metrics sample a path (`runner.motion_metrics`); nothing of the spline or the objective is used:

* velocities at the half steps by MuJoCo's `mj_differentiatePos` (positions: (q[i+1] - q[i]) fps; a ball
  joint: the rotation vector of q[i]^-1 q[i+1] times fps, in the child's frame), and at the frames i = 1..n-2
  the central differences qvel_i = (v[i-1/2] + v[i+1/2]) / 2, qacc_i = (v[i+1/2] - v[i-1/2]) fps. For a
  position that is the second difference (q[i+1] - 2 q[i] + q[i-1]) fps^2; for a ball joint it is the
  angular acceleration of its relative rotation on SO(3) (the child-frame rate of its angular velocity,
  whose norm is the world-frame one's);
* torques by MuJoCo's inverse dynamics `mj_inverse` at those frames, contacts and every other constraint
  disabled (`solver.inverse_dynamics_mujoco.constraint_free_copy`): tau = M(q) qacc + c(q, qvel).

A captured motion is low-pass filtered before it is differentiated (Winter, Biomechanics and Motor Control
of Human Movement, 4th ed., 2009, ch. 2: a 2nd-order Butterworth run forward and backward, 4th order with
zero lag, at 6 Hz; `filter_capture`, from `solver.peak_bounds`). The figures (`jolt_figures`):

* peak_pelvis_acceleration_m_s2: max over frames of |x''| of the root's position [m/s^2], gravity not
  included; peak_pelvis_acceleration_t_s: when [s from frame 0];
* peak_angular_acceleration_rad_s2: per ball joint, max over frames of |alpha| [rad/s^2] (..._t_s: when);
  peak_angular_acceleration_max_rad_s2 the largest of them, at peak_angular_acceleration_joint;
* rms_joint_torque_Nm: sqrt(mean over frames of the sum over the joints' degrees of freedom of tau^2)
  [N m], every joint but the free root (the RMS over time of the joint-torque vector's norm, as
  `solver.metrics`'s figure at 1000 Hz on the spline).
"""
from __future__ import annotations

import numpy as np

from solver.errors import InputError
from solver.peak_bounds import CUTOFF_HZ, filter_capture, frame_derivatives

__all__ = ["CUTOFF_HZ", "differentiate", "filter_capture", "inverse_torques", "jolt_figures", "worst_joint_ratio"]

#: [rad/s^2] the peak below which a joint's reference counts as still (`worst_joint_ratio`): a thousandth of
#: what a slow walk's ankle shows at 120 Hz, so a joint the reference never moves still gets a finite ratio
STILL_RAD_S2 = 1e-3


def differentiate(model, qpos: np.ndarray, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """Velocities and accelerations of frames sampled at a fixed rate by central differences (module
    docstring; `solver.peak_bounds.frame_derivatives` at the times i / fps).

    Args:
        model: an MjModel. qpos: (n, nq) frames at times i / fps (quaternions of any norm: MuJoCo
            normalizes them). fps: [Hz] > 0.
    Returns:
        (qvel, qacc), each (n - 2, nv), at the frames 1..n-2 [MuJoCo units: m/s, rad/s; m/s^2, rad/s^2].
    Raises:
        InputError: fewer than 3 frames, qpos not (n, nq), or fps not > 0.
    """
    qpos = np.atleast_2d(np.asarray(qpos, float))
    if qpos.ndim != 2 or qpos.shape[1] != model.nq or len(qpos) < 3:
        raise InputError(f"the motion is {qpos.shape}; its jolt figures need (n >= 3, nq = {model.nq}) frames")
    if not (np.isfinite(fps) and fps > 0):
        raise InputError(f"the frame rate is {fps!r}; it must be a positive number of frames per second")
    return frame_derivatives(model, np.arange(len(qpos)) / fps, qpos)


def inverse_torques(model, qpos: np.ndarray, qvel: np.ndarray, qacc: np.ndarray) -> np.ndarray:
    """(n, nv) generalized forces [N, N m] of MuJoCo's `mj_inverse` with every constraint (contacts
    included) disabled: M(q) qacc + c(q, qvel) - passive forces, per frame.

    Args:
        model: an MjModel (not changed). qpos: (n, nq). qvel, qacc: (n, nv).
    """
    import mujoco

    from solver.inverse_dynamics_mujoco import constraint_free_copy

    m = constraint_free_copy(model)
    data = mujoco.MjData(m)
    out = np.empty((len(qpos), m.nv))
    for i in range(len(qpos)):
        data.qpos[:], data.qvel[:], data.qacc[:] = qpos[i], qvel[i], qacc[i]
        mujoco.mj_inverse(m, data)
        out[i] = data.qfrc_inverse
    return out


def _joints(model):
    """(root dof address or None, {ball joint name: dof address}, dof indices of every non-free joint)."""
    import mujoco

    free, balls, dofs = None, {}, []
    for j in range(model.njnt):
        t, adr = int(model.jnt_type[j]), int(model.jnt_dofadr[j])
        if t == int(mujoco.mjtJoint.mjJNT_FREE):
            free = adr if free is None else free
            continue
        width = 3 if t == int(mujoco.mjtJoint.mjJNT_BALL) else 1
        if width == 3:
            balls[mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) or f"joint{j}"] = adr
        dofs += range(adr, adr + width)
    return free, balls, np.array(dofs, int)


def jolt_figures(model, qpos: np.ndarray, fps: float) -> dict:
    """The jolt figures of the module docstring for one sampled motion.

    Args:
        model: the scene's MjModel (a figure with a free root and ball joints). qpos: (n, nq) frames at
            i / fps, n >= 3 (a capture: filtered first, `filter_capture`). fps: [Hz] > 0.
    Returns:
        a JSON-serializable dict: peak_pelvis_acceleration_m_s2 (NaN without a free root),
        peak_pelvis_acceleration_t_s, peak_angular_acceleration_rad_s2 {joint: peak},
        peak_angular_acceleration_t_s {joint: s}, peak_angular_acceleration_max_rad_s2 and _joint (NaN and
        "" without ball joints), rms_joint_torque_Nm; times [s] from frame 0.
    Raises:
        InputError: as `differentiate`.
    """
    qpos = np.atleast_2d(np.asarray(qpos, float))
    qvel, qacc = differentiate(model, qpos, fps)
    times = np.arange(1, len(qpos) - 1) / fps
    free, balls, dofs = _joints(model)
    out = {"peak_pelvis_acceleration_m_s2": float("nan"), "peak_pelvis_acceleration_t_s": float("nan")}
    if free is not None:
        a = np.linalg.norm(qacc[:, free:free + 3], axis=1)
        out.update(peak_pelvis_acceleration_m_s2=float(a.max()), peak_pelvis_acceleration_t_s=float(times[a.argmax()]))
    peaks, when = {}, {}
    for name, adr in balls.items():
        a = np.linalg.norm(qacc[:, adr:adr + 3], axis=1)
        peaks[name], when[name] = float(a.max()), float(times[a.argmax()])
    worst = max(peaks, key=peaks.get, default="")
    out.update(peak_angular_acceleration_rad_s2=peaks, peak_angular_acceleration_t_s=when,
               peak_angular_acceleration_max_rad_s2=peaks[worst] if worst else float("nan"),
               peak_angular_acceleration_joint=worst)
    tau = inverse_torques(model, qpos[1:-1], qvel, qacc)[:, dofs]
    out["rms_joint_torque_Nm"] = float(np.sqrt(np.mean(np.sum(tau * tau, axis=1)))) if dofs.size else 0.0
    return out


def worst_joint_ratio(path: dict, plain: dict, capture: dict | None = None) -> tuple[str, float] | None:
    """The ball joint whose peak angular acceleration is largest against the larger of the plain spline's
    and the capture's at that joint, and that ratio (dimensionless).

    Args:
        path, plain, capture: {joint: peak [rad/s^2]} (`jolt_figures`' peak_angular_acceleration_rad_s2) of
            the optimized path, the plain spline and the filtered capture (None: the plain spline's alone).
    Returns:
        (joint, path[j] / max(plain[j], capture[j], STILL_RAD_S2)), or None when no joint is in all of them.
    """
    ratios = {j: path[j] / max(plain[j], capture[j] if capture else 0.0, STILL_RAD_S2)
              for j in path if j in plain and (capture is None or j in capture)}
    if not ratios:
        return None
    j = max(ratios, key=ratios.get)
    return j, float(ratios[j])
