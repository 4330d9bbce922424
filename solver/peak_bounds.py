"""The peak forces a motion may ask of the body: bounds of the no-jolt and force constraints (docs/dynamics.md).

A path with ballistic flights can buy them with a push-off and a landing no body makes (run-and-step
asked 6.8 body weights of ground force and 65 m/s^2 of pelvis acceleration where the capture needs 1.7
and 5.9). `PeakBounds` holds, for one problem, the largest
ground force and pelvis acceleration the optimized path may show: the larger of

* the plain spline's own peaks (the keyframes' motion, which the optimizer starts from), and
* the motion capture's peaks (when the keyframes were made from one): the same inverse dynamics on the
  retargeted capture after the low-pass filter biomechanics applies to captured kinematics before
  differentiating them - a 2nd-order Butterworth run forward and backward (4th order, zero phase lag)
  at 6 Hz, its design cutoff raised by Winter's two-pass correction 1 / 0.802 so that the -3 dB point of
  the two passes is 6 Hz (D. A. Winter, Biomechanics and Motor Control of Human Movement, 4th ed.,
  Wiley 2009, ch. 2 "Signal Processing", sec. 2.2.4: digital filtering of marker data).

The figures are those of `solver.metrics` (`dynamics_series`, `dynamics_metrics`): ground force = the
contact-free root force |F| on the samples where the flight indicator says the figure is on the ground,
in body weights |F| / (m g); pelvis acceleration = |x''| of the root position [m/s^2], gravity not
included; peaks over time at `solver.metrics.SAMPLE_RATE` samples per second.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from solver.errors import InputError
from solver.layout import StateLayout
from solver.lowpass import PADLEN, butter2, filtfilt2

__all__ = ["CUTOFF_HZ", "MIN_FRAMES", "PeakBounds", "capture_peaks", "filter_capture", "frame_derivatives", "peak_bounds"]

#: [Hz] the kinematics cutoff of the capture's low-pass filter (Winter 2009, ch. 2: 6 Hz for gait)
CUTOFF_HZ = 6.0
#: [frames] the fewest the filter takes: it extends the signal by `solver.lowpass.PADLEN` = 9 samples (scipy's
#: filtfilt default for the 2nd-order Butterworth's 3 coefficients) and needs more frames than that
MIN_FRAMES = PADLEN + 1
#: [1] Winter's correction of a two-pass (zero-lag) 2nd-order Butterworth: design at cutoff / 0.802 so that
#: the -3 dB frequency of the two passes is the cutoff ((2^(1/2) - 1)^(1/4) = 0.802)
TWO_PASS_CORRECTION = 0.802


@dataclass(frozen=True)
class PeakBounds:
    """The largest ground force and pelvis acceleration one problem's optimized path may show.

    Attributes:
        ground_force_bw: bound on the root force |F| / (m g) [body weights]: the larger of the plain
            spline's peak and the capture's peak on the ground.
        pelvis_acceleration_ms2: bound on |x''| of the root [m/s^2], the larger of the two peaks.
        plain_ground_force_bw: the plain spline's peak |F| / (m g) over all its samples (on the ground
            and in flight), so that the plain spline itself meets the bound.
        plain_pelvis_acceleration_ms2: the plain spline's peak [m/s^2].
        capture_ground_force_bw, capture_pelvis_acceleration_ms2: the filtered capture's peaks on the
            ground and over the keyframes' span, or None without a capture.
        cutoff_hz: the capture filter's cutoff [Hz].
    """

    ground_force_bw: float
    pelvis_acceleration_ms2: float
    plain_ground_force_bw: float
    plain_pelvis_acceleration_ms2: float
    capture_ground_force_bw: float | None = None
    capture_pelvis_acceleration_ms2: float | None = None
    cutoff_hz: float = CUTOFF_HZ

    def as_dict(self) -> dict:
        """The fields as a JSON-ready dict."""
        return asdict(self)

    def describe(self) -> str:
        """One line: the two bounds and where they come from."""
        cap = ("no capture" if self.capture_ground_force_bw is None else
               f"capture {self.capture_ground_force_bw:.2f} body wt, {self.capture_pelvis_acceleration_ms2:.1f} m/s^2 "
               f"(filtered at {self.cutoff_hz:g} Hz)")
        return (f"force bounds: ground {self.ground_force_bw:.2f} body wt, pelvis {self.pelvis_acceleration_ms2:.1f} "
                f"m/s^2 = max(plain {self.plain_ground_force_bw:.2f} body wt, {self.plain_pelvis_acceleration_ms2:.1f} "
                f"m/s^2; {cap})")


def filter_capture(times: np.ndarray, qpos: np.ndarray, layout: StateLayout,
                   cutoff_hz: float = CUTOFF_HZ) -> np.ndarray:
    """The capture's qpos low-pass filtered as biomechanics filters kinematics (module docstring).

    Quaternions are made continuous (no sign flips between frames), filtered component by component and
    normalized again; positions are filtered as they are.

    Args:
        times: (n,) evenly spaced frame times [s]. qpos: (n, nq) the retargeted capture.
        layout: the figure's `StateLayout` (its quaternion slots). cutoff_hz: [Hz] > 0.
    Returns:
        (n, nq) filtered qpos (the input unchanged where the frame rate is too low for the cutoff, i.e.
        the design frequency is at or above Nyquist: the capture holds nothing above it to remove).
    Raises:
        InputError: fewer than MIN_FRAMES frames,
            uneven frame times, or a cutoff that is not > 0.
    """
    times, qpos = np.asarray(times, float), np.array(qpos, float)
    if not (np.isfinite(cutoff_hz) and cutoff_hz > 0):
        raise InputError(f"the capture filter's cutoff is {cutoff_hz} Hz; it must be > 0")
    if len(times) < MIN_FRAMES:
        raise InputError(f"the capture has {len(times)} frames; its filtered peaks need at least {MIN_FRAMES}: give a "
                         "longer clip")
    dt = np.diff(times)
    if not np.allclose(dt, dt[0], rtol=1e-6, atol=1e-9) or dt[0] <= 0:
        raise InputError("the capture's frame times are not evenly spaced; the low-pass filter needs a fixed rate")
    for slot in layout.quat_slots:
        q = qpos[:, slot]
        flips = np.cumsum(np.r_[False, np.einsum("ij,ij->i", q[1:], q[:-1]) < 0]) % 2 == 1
        q[flips] *= -1.0
        qpos[:, slot] = q
    wn = cutoff_hz / TWO_PASS_CORRECTION / (0.5 / dt[0])
    if wn >= 1.0:
        return qpos
    out = filtfilt2(*butter2(wn), qpos)
    for slot in layout.quat_slots:
        out[:, slot] /= np.linalg.norm(out[:, slot], axis=1, keepdims=True)
    return out


def frame_derivatives(model, times: np.ndarray, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Velocities and accelerations of sampled frames by central differences, as biomechanics differentiates
    filtered kinematics (Winter 2009, ch. 2, sec. 2.2.5: finite differences of the filtered data).

    Velocities at the half steps by MuJoCo's `mj_differentiatePos` (a position: (q[i+1] - q[i]) / h_i; a ball
    joint: the rotation vector of q[i]^-1 q[i+1] over h_i, in the child's frame), and at the frames i = 1..n-2
    qvel_i = (v[i-1/2] + v[i+1/2]) / 2 and qacc_i = (v[i+1/2] - v[i-1/2]) / ((h_{i-1} + h_i) / 2). For a
    position this is a weighted mean of the second derivative at frames i-1, i, i+1 of any cubic spline
    through the frames (weights h_{i-1} / (3 (h_{i-1} + h_i)), 2/3, h_i / (3 (h_{i-1} + h_i)): the spline's
    moment equations, de Boor, A Practical Guide to Splines, ch. IV), so a spline whose acceleration is
    bounded at its frames has central differences within the same bound.

    Args:
        model: an MjModel. times: (n,) [s] increasing. qpos: (n, nq) (quaternions of any norm: MuJoCo
            normalizes them).
    Returns:
        (qvel, qacc), each (n - 2, nv) [m/s, rad/s; m/s^2, rad/s^2].
    Raises:
        InputError: fewer than 3 frames, qpos not (n, nq) or times not (n,) increasing.
    """
    import mujoco

    times, qpos = np.asarray(times, float), np.atleast_2d(np.asarray(qpos, float))
    if qpos.ndim != 2 or qpos.shape[1] != model.nq or len(qpos) < 3:
        raise InputError(f"the motion is {qpos.shape}; its derivatives need (n >= 3, nq = {model.nq}) frames")
    h = np.diff(times)
    if times.shape != (len(qpos),) or not np.all(h > 0):
        raise InputError(f"the frame times ({times.shape}) must be increasing, one per frame of the {len(qpos)}")
    half = np.empty((len(qpos) - 1, model.nv))
    for i in range(len(qpos) - 1):
        mujoco.mj_differentiatePos(model, half[i], h[i], qpos[i], qpos[i + 1])
    return 0.5 * (half[1:] + half[:-1]), (half[1:] - half[:-1]) / (0.5 * (h[1:] + h[:-1]))[:, None]


def _series(model, frame_times, frames, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """|F| / (m g) [body weights], |x''| [m/s^2] and the flight flag (n,) each, of the natural cubic
    spline through (frame_times, frames) at times t (n,): the figures of `solver.metrics.dynamics_series`
    (flight: the root term's indicator phi > 0.5) at any times."""
    from solver.figure import Figure
    from solver.spline import interpolate
    from solver.terms.dynamics import RootResidual, _free_joint, make_engine

    Y, Y1, Y2 = (interpolate(frame_times, frames, t, nu) for nu in (0, 1, 2))
    sites = Figure.from_model(model).contact_sites
    engine = make_engine(model, tuple(sites))
    root = RootResidual(model, sites=sites, engine=engine)
    motion = root.tmap.motion(Y, Y1, Y2)
    res = engine.forward(Y, motion.qvel, motion.qacc)
    phi, _ = root.flight(res.sites[:, root.site_index])
    weight = float(np.sum(model.body_mass) * np.linalg.norm(model.opt.gravity))
    force = np.linalg.norm(res.tau[:, root.root_dofs[:3]], axis=1) / weight
    adr = int(model.jnt_qposadr[_free_joint(model, root.layout)])
    return force, np.linalg.norm(Y2[:, adr:adr + 3], axis=1), phi > 0.5


def _peaks(model, frame_times, frames, window=None, flight_too: bool = False) -> tuple[float, float]:
    """(peak ground force [body weights], peak pelvis acceleration [m/s^2]) of the natural cubic spline
    through (frame_times, frames), at `SAMPLE_RATE` samples per second and at the frame times (where the
    spline's x'', linear between them, peaks), over `window` = (t0, t1) (default all); with flight_too
    the force peak is over every sample, not only those on the ground."""
    from solver.metrics import SAMPLE_RATE, sample_times

    frame_times, frames = np.asarray(frame_times, float), np.asarray(frames, float)
    t0, t1 = (frame_times[0], frame_times[-1]) if window is None else window
    t = np.union1d(sample_times(t0, t1, SAMPLE_RATE), frame_times[(frame_times >= t0) & (frame_times <= t1)])
    force, acc, flight = _series(model, frame_times, frames, t)
    force = force if flight_too else force[~flight]
    return (float(force.max()) if force.size else float("nan"), float(acc.max()) if acc.size else float("nan"))


def capture_peaks(model, times, qpos, t_span, cutoff_hz: float = CUTOFF_HZ) -> tuple[float | None, float | None]:
    """The filtered capture's peak ground force [body weights] and pelvis acceleration [m/s^2] over
    t_span (module docstring; the capture filtered over its whole length, the spline through all its frames,
    so that its natural end conditions lie at the capture's ends, not inside the span).

    Args:
        model: MjModel of the scene. times: (n,) frame times [s], the keyframes' clock. qpos: (n, nq)
            the retargeted capture. t_span: (t0, t1) [s] the keyframes' span.
    Returns:
        (force, acceleration); force None when the capture is never on the ground in the span.
    Raises:
        InputError: as `filter_capture`, or fewer than 4 capture frames in the span.
    """
    times = np.asarray(times, float)
    smooth = filter_capture(times, qpos, StateLayout.from_model(model), cutoff_hz)
    inside = int(((times >= t_span[0]) & (times <= t_span[1])).sum())
    if inside < 4:
        raise InputError(f"the keyframes span {t_span[0]:g}..{t_span[1]:g} s, which holds {inside} frames "
                         "of the capture; its force peaks need at least 4")
    force, acc = _peaks(model, times, smooth, window=t_span)
    return (None if not np.isfinite(force) else force), acc


def peak_bounds(model, plain, capture=None, cutoff_hz: float = CUTOFF_HZ) -> PeakBounds:
    """The `PeakBounds` of one problem: the larger of the plain spline's and the filtered capture's peaks.

    Args:
        model: MjModel of the scene (figure with a free root and ball joints).
        plain: the plain spline's `FrameSet` (times (k,) [s], values (k, nq)).
        capture: None, or (times (n,) [s] on the keyframes' clock, qpos (n, nq)) of the retargeted
            motion capture the keyframes were made from.
        cutoff_hz: the capture filter's cutoff [Hz].
    Raises:
        InputError: a model the analytic inverse dynamics does not support, or a capture as
            `capture_peaks` refuses it.
    """
    pf, pa = _peaks(model, plain.times, plain.values, flight_too=True)
    cf = ca = None
    if capture is not None:
        cf, ca = capture_peaks(model, capture[0], capture[1], (plain.times[0], plain.times[-1]), cutoff_hz)
    force = max(pf, cf if cf is not None else -np.inf)
    acc = max(pa, ca if ca is not None else -np.inf)
    return PeakBounds(float(force), float(acc), pf, pa, cf, ca, float(cutoff_hz))
