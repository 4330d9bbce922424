"""The bounds the capture witnesses (solver.constraint_set, "What the keyframes force"): no jolts, each joint's
peak acceleration against the larger of the plain spline's and the capture's low-pass filtered at 6 Hz
(Winter, Biomechanics and Motor Control of Human Movement, 2009), and effort, the RMS joint torque against
the same two; and the paths they are measured on, the plain spline and the capture at the quadrature points.
"""
from __future__ import annotations

import numpy as np

from solver.constraints.acceleration import AccelerationBound
from solver.constraints.base import RELATIVE_TOLERANCE
from solver.constraints.effort import TorqueRMS, rms_torque
from solver.kinematics import TangentMap
from solver.layout import StateLayout
from solver.path_state import PathState
from solver.peak_bounds import filter_capture
from solver.spline import interpolate

__all__ = ["MIN_PEAK", "capture_accelerations", "capture_effort", "capture_state", "filtered_capture", "jolt_columns",
           "reference_state"]

#: [m/s^2 or rad/s^2] the no-jolt limit of a column no reference path accelerates: a limit > 0 (the bound's
#: smooth form divides by it), far below any motion
MIN_PEAK = 1e-6


def reference_state(model, reference, plain, engine) -> PathState:
    """The plain spline (the reference) at the quadrature points, as an evaluation sees a path."""
    Y1, Y2 = interpolate(plain.times, plain.values, reference.t, (1, 2))
    return PathState(reference.t, reference.qpos, Y1, Y2, TangentMap.from_layout(StateLayout.from_model(model)), engine)


def capture_state(model, reference, capture, engine) -> PathState:
    """The capture (times, qpos) as a path at the quadrature points (the natural spline through its frames)."""
    Y, Y1, Y2 = interpolate(np.asarray(capture[0], float), np.asarray(capture[1], float), reference.t, (0, 1, 2))
    return PathState(reference.t, Y, Y1, Y2, TangentMap.from_layout(StateLayout.from_model(model)), engine)


def filtered_capture(model, reference, capture) -> tuple:
    """The capture ((times, qpos)) low-pass filtered (`solver.peak_bounds.filter_capture`, 6 Hz) as a path at
    the quadrature points: the natural spline through all its frames, (Y, Y1, Y2), each (n, nq) [qpos units and
    their rates]; what both bounds below are measured on, made once per problem."""
    times, qpos = np.asarray(capture[0], float), np.asarray(capture[1], float)
    smooth = filter_capture(times, qpos, StateLayout.from_model(model))
    return interpolate(times, smooth, reference.t, (0, 1, 2))


def jolt_columns(layout: StateLayout) -> tuple[np.ndarray, list, np.ndarray]:
    """The columns the no-jolt bounds hold: each free joint's linear acceleration [m/s^2] and each ball joint's
    angular acceleration [rad/s^2]. Returns (dofs (j, 3) their `qvel` indices, labels (j,), linear (j,) bool)."""
    free = [j for j in layout.joints if j.kind == "free"]
    balls = [j for j in layout.joints if j.kind == "ball"]
    dofs = [[f.dofadr, f.dofadr + 1, f.dofadr + 2] for f in free] + [[b.dofadr + i for i in range(3)] for b in balls]
    labels = [f"{f.name} (linear)" for f in free] + [b.name for b in balls]
    return np.array(dofs, int).reshape(-1, 3), labels, np.arange(len(labels)) < len(free)


def capture_accelerations(model, reference, filtered) -> AccelerationBound:
    """The no-jolt bounds (`solver.constraints.acceleration`) on `jolt_columns`: the reference's peaks and, with
    the filtered capture (`filtered_capture`; None: none), its peaks over the same span, joint by joint."""
    layout = StateLayout.from_model(model)
    dofs, labels, linear = jolt_columns(layout)
    peaks = np.linalg.norm(reference.qacc[:, dofs], axis=-1).max(axis=0)
    if filtered is not None:
        qacc = TangentMap.from_layout(layout).motion(*filtered).qacc
        peaks = np.maximum(peaks, np.linalg.norm(qacc[:, dofs], axis=-1).max(axis=0))
    peaks = np.maximum(peaks, MIN_PEAK)
    return AccelerationBound(len(reference.t), dofs, peaks, RELATIVE_TOLERANCE * peaks, labels, linear=linear)


def capture_effort(model, reference, plain, filtered, engine) -> list:
    """[the effort bound] (`solver.constraints.effort`): the larger of the plain spline's RMS joint torque and
    the filtered capture's (`filtered_capture`) over the same span, with the no-jolt bounds' relative tolerance;
    [] for a figure whose joints carry no torque in either (no joints besides the root: nothing to bound)."""
    layout = StateLayout.from_model(model)
    dofs = np.array([j.dofadr + i for j in layout.joints if j.kind != "free" for i in range(j.nv)], int)
    w = reference.weights
    captured = PathState(reference.t, *filtered, TangentMap.from_layout(layout), engine)
    bound = max(rms_torque(reference_state(model, reference, plain, engine).tau, w, dofs),
                rms_torque(captured.tau, w, dofs))
    return [TorqueRMS(w, dofs, bound, RELATIVE_TOLERANCE * bound)] if bound > 0 else []
