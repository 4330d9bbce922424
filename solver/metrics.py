"""What the optimization bought, measured on the continuous path (dense sampling, default 1000 Hz).

These are the acceptance figures: penetration depth of the contact sites [mm], quaternion norm
deviation, knee/elbow hyperextension [deg], keyframe error. They use the true surfaces (no margin).

Physical plausibility (paper sec. 6, appendix A), from the contact-free inverse dynamics of the path
(`dynamics_series`, the engine the torque and root terms use, on the spline's Y, Y', Y''):

* joint torque: the 33 generalized forces of the 11 ball joints [N m] (the free root's 6 excluded).
  RMS = sqrt(mean over samples of sum over the 33 of tau^2), i.e. the RMS over time of the Euclidean
  norm of the joint-torque vector; peak = the largest torque magnitude |tau_j| (3-vector) of any one
  joint at any sample.
* root residual: the free root's generalized force, world force F [N] and torque T about the root's
  origin [N m]: the external wrench besides gravity the motion needs. In flight nothing but gravity
  acts, so it should be 0 (a figure at rest in the air needs F = m g). Flight is where the root term's
  indicator phi > 0.5 (`RootResidual.flight`: every contact site clear of every surface by about
  3 cm or more, with the default 5 cm contact distance); RMS and peak of |F| and |T| over the flight
  samples, and the flight duration [s], are reported per path (each path's own flight phases).
* on the ground (phi <= 0.5) the root residual is what the feet must supply: RMS and peak |F| over
  the ground samples in body weights (|F| / (m g), m the model's total mass), the check the
  contact-free root term does not make (large forces on the ground are its price).
* pelvis acceleration: peak over time of |x''| of the root position [m/s^2] (the spline's second
  derivative, world frame), gravity not included.
"""
from __future__ import annotations

import numpy as np

from solver.figure import Figure
from solver.frames import FrameSet
from solver.keyframes import Keyframes
from solver.layout import StateLayout
from solver.spline import interpolate
from solver.terms.bending import Hyperextension
from solver.terms.penetration import Penetration

#: [1/s] samples per second of a path's acceptance figures and of the peaks that bound it
#: (`solver.peak_bounds`): 1 ms resolves the 10-25 ms spikes beside keyframes a jolt shows.
SAMPLE_RATE = 1000.0


def sample_times(t0: float, t1: float, rate: float) -> np.ndarray:
    """(n,) times from t0 to t1 inclusive at `rate` samples per second [s]."""
    return np.linspace(t0, t1, int(round((t1 - t0) * rate)) + 1)


def keyframe_error(frames: FrameSet | tuple, keyframes: Keyframes, quat_slots) -> float:
    """Largest |Y(t_k) - keyframe value| over components the keyframes fix (`pose_error` at the keyframes)."""
    return pose_error(frames, keyframes.times, keyframes.values, keyframes.mask, quat_slots)


def pose_error(frames: FrameSet | tuple, times: np.ndarray, values: np.ndarray, mask: np.ndarray, quat_slots) -> float:
    """Largest |Y(t_k) - values[k]| over the components `mask` selects; 0 where it selects none.

    The path is evaluated by re-interpolating the frames (not read from the frame array), so this
    checks the spline too. Quaternions compare up to the sign of the whole quaternion (q and -q are
    one rotation; keyframes are hemisphere-aligned before interpolation).

    Args:
        frames: FrameSet or (frame times (m,) [s], values (m, nq)). times: (k,) [s]. values: (k, nq) the poses
            there. mask: (k, nq) bool. quat_slots: the quaternions' qpos indices ((s, 4) or flat).
    """
    ft, fv = (frames.times, frames.values) if isinstance(frames, FrameSet) else frames
    Y = interpolate(ft, fv, np.asarray(times, float))
    target = np.array(values, float)
    for slot in np.asarray(quat_slots).reshape(-1, 4):
        flip = np.nansum(Y[:, slot] * target[:, slot], axis=1) < 0
        target[np.ix_(flip, slot)] *= -1
    err = np.abs(Y - target)[np.asarray(mask, bool)]
    return float(err.max()) if err.size else 0.0


def dynamics_series(model, frame_times, frames, rate: float = SAMPLE_RATE, sites=None,
                    flight_threshold: float = 0.5) -> dict:
    """Inverse dynamics along a path (the natural cubic spline through frames), sampled densely.

    Args:
        model: MjModel of the scene (figure with a free root and ball joints, static surfaces).
        frame_times: (m,) [s]. frames: (m, nq). rate: samples per second [1/s].
        sites: contact sites for the flight indicator (default: the figure's). flight_threshold: phi above which a sample is
            in flight (phi in [0, 1]; 0.5: the indicator's midpoint, where a site is as much up as down).
    Returns:
        dict of arrays over n samples: t (n,) [s]; joint_torque (n, 33) [N m] (ball-joint DOFs in
        qvel order, child-frame components); joint_names (11,) and joint_torque_norm (n, 11) [N m]
        (|tau_j| per ball joint); root_force (n, 3) [N] (world); root_torque (n, 3) [N m] (root
        frame); phi (n,) the flight indicator in [0, 1]; flight (n,) bool; pelvis_acceleration (n, 3)
        [m/s^2] (the root position's second derivative, world); body_weight_N (m g of the model).
    Raises:
        InputError: a model the analytic inverse dynamics does not support (see `make_engine`).
    """
    from solver.terms.dynamics import JointTorque, RootResidual, make_engine

    layout = StateLayout.from_model(model)
    t = sample_times(frame_times[0], frame_times[-1], rate)
    Y, Y1, Y2 = (interpolate(frame_times, frames, t, nu) for nu in (0, 1, 2))
    sites = Figure.from_model(model).contact_sites if sites is None else tuple(sites)
    engine = make_engine(model, tuple(sites))
    torque = JointTorque(model, engine=engine)
    root = RootResidual(model, sites=sites, engine=engine)
    mo = torque.tmap.motion(Y, Y1, Y2)
    res = engine.forward(Y, mo.qvel, mo.qacc)
    phi, _ = root.flight(res.sites[:, root.site_index])
    balls = [j for j in layout.joints if j.kind == "ball"]
    dofs = np.array([j.dofadr + i for j in balls for i in range(3)], int)
    tau = res.tau[:, dofs]
    wrench = res.tau[:, root.root_dofs]
    return {
        "t": t,
        "joint_torque": tau,
        "joint_names": [j.name for j in balls],
        "joint_torque_norm": np.linalg.norm(tau.reshape(len(t), -1, 3), axis=-1),
        "root_force": wrench[:, :3],
        "root_torque": wrench[:, 3:],
        "phi": phi,
        "flight": phi > flight_threshold,
        "pelvis_acceleration": Y2[:, :3],
        "body_weight_N": float(np.sum(model.body_mass) * np.linalg.norm(model.opt.gravity)),
    }


def dynamics_metrics(series: dict) -> dict:
    """Summary figures of `dynamics_series` (definitions: module docstring).

    Returns:
        dict: rms_joint_torque_Nm, peak_joint_torque_Nm, peak_joint_torque_joint, flight_s,
        rms_root_force_flight_N, peak_root_force_flight_N, rms_root_torque_flight_Nm,
        peak_root_torque_flight_Nm (NaN without flight samples), rms_root_force_ground_bw,
        peak_root_force_ground_bw (body weights, NaN without ground samples; only when the series has
        body_weight_N), peak_pelvis_acceleration_ms2 (when the series has pelvis_acceleration).
    """
    t, tau, fl = series["t"], series["joint_torque"], series["flight"]
    norms = series["joint_torque_norm"]
    j = int(np.argmax(norms.max(axis=0)))
    F = np.linalg.norm(series["root_force"][fl], axis=1)
    T = np.linalg.norm(series["root_torque"][fl], axis=1)
    dt = (t[-1] - t[0]) / max(1, len(t) - 1)

    def rms(x):
        return float(np.sqrt(np.mean(x * x))) if x.size else float("nan")

    def peak(x):
        return float(x.max()) if x.size else float("nan")

    return {
        "rms_joint_torque_Nm": float(np.sqrt(np.mean((tau * tau).sum(axis=1)))),
        "peak_joint_torque_Nm": float(norms.max()),
        "peak_joint_torque_joint": series["joint_names"][j],
        "flight_s": float(fl.sum() * dt),
        "rms_root_force_flight_N": rms(F),
        "peak_root_force_flight_N": peak(F),
        "rms_root_torque_flight_Nm": rms(T),
        "peak_root_torque_flight_Nm": peak(T),
    } | _ground_and_pelvis(series, rms, peak)


def _ground_and_pelvis(series: dict, rms, peak) -> dict:
    out = {}
    if "body_weight_N" in series:
        G = np.linalg.norm(series["root_force"][~series["flight"]], axis=1) / series["body_weight_N"]
        out["rms_root_force_ground_bw"] = rms(G)
        out["peak_root_force_ground_bw"] = peak(G)
    if "pelvis_acceleration" in series:
        out["peak_pelvis_acceleration_ms2"] = peak(np.linalg.norm(series["pelvis_acceleration"], axis=1))
    return out


def path_metrics(model, frame_times, frames, keyframes: Keyframes | None = None, rate: float = SAMPLE_RATE,
                 sites=None, dynamics: bool = True) -> dict:
    """Acceptance figures of a path (the natural cubic spline through frames).

    Args:
        model: MjModel of the scene. frame_times: (m,) [s]. frames: (m, nq).
        keyframes: to report the keyframe error (optional). rate: samples per second.
        sites: the contact sites to measure (default: the figure's, `Figure.contact_sites`).
        dynamics: also report the inverse-dynamics figures (`dynamics_metrics`; skipped, without an
            error, for a model the analytic engine does not support).
    Returns:
        dict with max_penetration_mm, penetration_mm_by_site {site: mm}, sole_mm_by_site {the figure's soles'
            edge sites (`Figure.sole_sites`; {} without): mm in a surface}, max_norm_deviation (max over
        time and quaternions of |1 - |q||), max_hyperextension_deg {joint: deg} and overall,
        keyframe_error (if keyframes given), samples, and the `dynamics_metrics` keys.
    """
    layout = StateLayout.from_model(model)
    figure = Figure.from_model(model)
    sites = figure.contact_sites if sites is None else tuple(sites)
    t = sample_times(frame_times[0], frame_times[-1], rate)
    Y = interpolate(frame_times, frames, t)
    soles = tuple(s for s in figure.sole_sites if s not in sites)  # the soles' edges, points
    both = Penetration(model, sites=sites + soles, margin=0.0).depths(Y, margin=0.0) * 1000.0  # (n, k + e) mm
    depth, edges = both[:, :len(sites)], both[:, len(sites):]
    norms = np.linalg.norm(Y[:, layout.quat_slots], axis=-1)
    out = {
        "samples": len(t),
        "rate_hz": rate,
        "max_penetration_mm": float(depth.max()),
        "penetration_mm_by_site": dict(zip(sites, depth.max(axis=0).round(3).tolist())),
        "sole_mm_by_site": dict(zip(soles, edges.max(axis=0).round(3).tolist())),
        "max_norm_deviation": float(np.abs(1.0 - norms).max()),
    }
    try:
        bend = Hyperextension(layout, figure.flexion_axes)
        hyper = np.degrees(np.maximum(0.0, -bend.angles(Y))).max(axis=0)
        out["max_hyperextension_deg_by_joint"] = dict(zip(bend.joint_names, hyper.round(3).tolist()))
        out["max_hyperextension_deg"] = float(hyper.max())
    except Exception:  # a figure without knees/elbows
        out["max_hyperextension_deg"] = float("nan")
    if keyframes is not None:
        out["keyframe_error"] = keyframe_error((frame_times, frames), keyframes, layout.quat_slots)
    if dynamics:
        from solver.errors import InputError

        try:
            out.update(dynamics_metrics(dynamics_series(model, frame_times, frames, rate, sites)))
        except InputError:  # a model the analytic inverse dynamics does not support
            pass
    return out
