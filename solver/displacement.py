"""Clean a captured clip: the least change to the capture itself, as a motion displacement.

    q(t) = c(t) + d(t)

c is the retargeted capture, the natural cubic spline through every one of its frames (C2, so its
accelerations are defined everywhere: `solver.reference.ReferenceMotion.from_samples`), and d is the
displacement, a natural cubic spline through its own frames that the least change optimizes
(`solver.least_change`): motion displacement mapping (Bruderlin & Williams, "Motion signal processing",
SIGGRAPH 1995; Witkin & Popovic, "Motion warping", SIGGRAPH 1995; Lee & Shin, "A hierarchical approach
to interactive motion editing for human-like figures", SIGGRAPH 1999), with the edit posed as the least
change that meets the constraints (Gleicher, "Motion editing with spacetime constraints", I3D 1997).

* **The reference motion is the capture** (D measures the change of the capture's own accelerations and
  pose), and the constraints are the figure's (`solver.constraint_set`) with the capture's contacts and
  flights; the capture is their witness (the no-jolt and effort bounds against the 6 Hz capture, the
  unit-norm bound between frames at least the capture's own: `_capture_limits`).
* **The pose part measures how far the body's parts move** (`solver.reference.equal_mass_matrices`: the
  mass matrix of the figure with its mass spread equally over its bodies, so every body counts alike, as
  the field's mean per-joint position error does), and it prices every change slower than the captured
  movement's own band (`CORRECTION_TIME`). A clean is judged by how far it departs from the capture, and
  a planted foot's slide can be undone anywhere over its contact: priced by the joint angles alike (the
  keyed path's pose part), or with a quarter second's correction time, the least change moved a planted
  foot 12-14 cm sideways on a clip whose capture slides it 4 cm (83_02).
* **The pins** are the displacement's keyframes, d = 0 exactly: any frames the user names (each on the
  capture frame nearest it) and, with `pin_ends`, the clip's first and last; every other capture frame is
  a variable frame (below). Where no constraint asks for a change D's minimum is d = 0: the capture comes back exactly.
* **Quaternions are displaced additively in R^4, each about its own frame.** A displacement frame's
  quaternion slot holds a unit quaternion p moved on its sphere (`solver.manifold`, three rotation
  variables, as a frame of a keyed path) around that capture frame's own orientation e_i, and the
  displacement there is p - e_i (d's anchors, `anchors`: the spline through them is the capture's own in
  that slot). So d = 0 where p = e_i, c + d = p at every capture frame (a unit quaternion: the cleaned
  clip's frames are the frames' values), the variables are rotation vectors the preconditioner prices by
  the joint's inertia, and between frames c + d is the frames' spline, which MuJoCo normalizes (the
  unit-norm bound keeps it near unit, as between the frames of a keyed path). Anchored at one orientation
  for the whole clip (its mean), a joint turning far from it could not be displaced about every axis (at
  180 degrees not at all) and the sum left the unit sphere: on 05_09 the unit-norm limit was raised by
  0.12 at the right ankle, over 66 points.
* **The displacement has a frame at every capture frame** (`LeastChange.grid`), each a quadrature
  point: d lives in the capture's own spline space (c + d is the natural spline through its samples,
  `clean_solution`), its acceleration, as c's, linear between frames, so a bound met at the frames
  holds between them; and d can undo the capture's frame-to-frame slide as a per-frame clean does,
  which frames two or more points apart, off the capture's frames, cannot.
* **The feet are measured at the capture's frames**, where the clip is written and judged
  (`solver.constraint_set.figure_constraints`' `frames`): a planted mean over a contact's frames, of the
  heights' positive part, and the slide per frame, within the clean's skate bound
  (`solver.foot_bounds.CLEAN_SKATE`). At 30 fps the midpoint rule gave a running contact's last
  frame, the foot 2-4 cm up, half its weight in the float figure, and 2 mm of slide over a 3-frame contact
  was 0.55 mm a frame.
* **The quadrature is Simpson's rule on the capture's frame intervals** (`solver.quadrature.simpson_points`: the
  frames and the midpoints between them). c + d is a cubic between two frames, so the rule integrates D's
  acceleration part exactly under a constant mass matrix, and the frames, where its acceleration peaks, are
  points. The keyed path's midpoint rule at `LeastChangeOptions.rate` (200 points a second) plus the frames
  spent 7 points on every interval of a 30 fps capture for nothing the bounds measure; the clean then cost
  2.5 times as much on Bandai Namco's 30 fps clips, with the same bounds held. Where a frame interval is
  long for the motion, it is split into 2, 4 or 8 panels of the rule (`frame_panels`): the penetration
  constraint holds the deepest point of a site's cubic between two points, and that cubic must follow the
  site's path to within the margin its tolerance leaves under the 1 mm bound.
* The solver sees the displacement's frames; the capture enters as a fixed base motion at the
  quadrature points (`AugmentedLagrangian.base`: the path is c + d with its first and second
  derivatives), so every constraint and gradient is the keyed path's, with the same dPath/dP.

`clean_solution` turns the solved displacement into the cleaned clip at the capture's frames (a
FrameSet through every frame: c + d sampled there) beside the capture itself.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from solver.capture_bounds import jolt_columns
from solver.change import MeasureOfChange
from solver.constraint_set import ANGLE_RESOLUTION, PENETRATION_TOLERANCE, TOLERANCES, figure_constraints
from solver.constraints.acceleration import AccelerationBound
from solver.constraints.base import RELATIVE_TOLERANCE
from solver.contact_schedule import ContactSchedule
from solver.errors import InputError
from solver.figure import Figure
from solver.foot_bounds import CAPTURE_RESOLUTION
from solver.frames import FrameSet
from solver.inverse_dynamics import InverseDynamics
from solver.kinematics import TangentMap
from solver.lagrangian import AugmentedLagrangian
from solver.layout import StateLayout
from solver.least_change import STANDARD_GRAVITY, LeastChange, LeastChangeOptions, solve_least_change
from solver.path_state import PathState
from solver.peak_bounds import CUTOFF_HZ, filter_capture, frame_derivatives
from solver.quadrature import simpson_points
from solver.reference import ReferenceMotion, equal_mass_matrices
from solver.solution import Solution
from solver.spline import interpolate

__all__ = ["CORRECTION_TIME", "CUBIC_ERROR", "FEET", "MAX_PANELS", "Displacement", "anchors", "build_displacement",
           "clean_solution", "frame_panels", "pin_frames", "solve_displacement", "still_peaks"]

#: [s] the duration that divides a correction priced by its pose from one priced by its acceleration (the
#: measure of change's omega = pi / CORRECTION_TIME = 2 pi CUTOFF_HZ): the band of the captured movement
#: itself, below the 6 Hz cutoff that the no-jolt bound filters the capture at (Winter 2009). A change
#: within that band is priced by how far it moves the body's parts, a faster one by its acceleration
CORRECTION_TIME = 1.0 / (2.0 * CUTOFF_HZ)

#: what a clean asks of a foot in contact: "planted", it slides no more than the pins force (Kovar, Schreiner
#: & Gleicher, "Footskate cleanup for motion capture editing", SCA 2002: a planted foot stays put), or
#: "captured", no more than the capture slides there (only penetration, float and flight are cleaned)
FEET = ("planted", "captured")


@dataclass
class Displacement:
    """A built clean: the least-change problem of the displacement and the capture it displaces.

    Attributes:
        lc: the `LeastChange` (its `plain` d = 0 at every capture frame, the pins fixed; `al.base` the capture
            less the anchors' spline at the quadrature points).
        times: (n,) [s] the capture's frame times. qpos: (n, nq) the retargeted capture.
        anchor: (n, nq) the displacement's zero as its frames hold it at each capture frame (`anchors`).
        pins: (k,) indices of the capture frames pinned (d = 0 there).
        capture_frames: FrameSet through every capture frame (the pins its keyframes): the capture as a path.
        panels: (n - 1,) Simpson panels of each capture frame interval (`frame_panels`).
    """

    lc: LeastChange = field(repr=False)
    times: np.ndarray
    qpos: np.ndarray = field(repr=False)
    anchor: np.ndarray
    pins: np.ndarray
    capture_frames: FrameSet = field(repr=False)
    panels: np.ndarray = field(repr=False)


def anchors(qpos: np.ndarray, quat_slots: np.ndarray) -> np.ndarray:
    """The displacement's zero as its frames hold it, at each capture frame: 0 on the linear components, and
    in each quaternion slot the capture's own orientation there, normalized (module docstring).

    Args:
        qpos: (n, nq) the capture. quat_slots: (s, 4) qpos indices of the quaternions.
    Returns:
        (n, nq) the anchors.
    """
    qpos = np.asarray(qpos, float)
    out = np.zeros_like(qpos)
    for slot in np.asarray(quat_slots, int).reshape(-1, 4):
        out[:, slot] = qpos[:, slot] / np.linalg.norm(qpos[:, slot], axis=1, keepdims=True)
    return out


def pin_frames(times: np.ndarray, pins=(), ends: bool = False) -> np.ndarray:
    """The capture frames pinned: the one nearest each time of `pins` and, with `ends`, the first and last.

    Args:
        times: (n,) [s] the capture's frame times. pins: times [s] inside the clip. ends: pin the first and
            last frame too.
    Returns:
        (k,) sorted distinct frame indices.
    Raises:
        InputError: a pin outside the clip.
    """
    times = np.asarray(times, float)
    idx = {0, len(times) - 1} if ends else set()
    half = 0.5 * float(np.min(np.diff(times)))
    for p in pins:
        if not (times[0] - half <= float(p) <= times[-1] + half):
            raise InputError(f"--pin {float(p):g}: outside the clip's {times[0]:g}..{times[-1]:g} s; give a time in it")
        idx.add(int(np.argmin(np.abs(times - float(p)))))
    return np.array(sorted(idx), int)


def build_displacement(model, times, qpos, *, pins=(), pin_ends: bool = False, contacts=(), flights=None,
                       correction_time: float = CORRECTION_TIME, feet: str = "planted") -> Displacement:
    """Build the clean of a retargeted capture (module docstring).

    Args:
        model: mujoco.MjModel of the scene with the figure. times: (n,) [s] increasing frame times, n >= 4.
        qpos: (n, nq) the retargeted capture. pins: times [s] where d = 0 (`pin_frames`). pin_ends: the
            first and last frame too (else they are the displacement's variable frames).
        contacts: the capture's contact schedule (`Contact`s). flights: ((start, end), ...) [s] where every
            site is clear (None: the schedule's gaps).
        correction_time: [s] the measure of change's pose part prices changes slower than this
            (omega = pi / correction_time, `solver.change`). feet: one of FEET: each slide limit is what
            the pins force ("planted") or the capture's own slide over that contact ("captured").
    Returns:
        Displacement.
    Raises:
        InputError: shapes that do not fit the model, fewer than 4 frames, more than
            `solver.quadrature.MAX_QUADRATURE_POINTS` points, a pin outside the clip, an unknown `feet`.
    """
    if feet not in FEET:
        raise InputError(f"feet {feet!r}: not one of {', '.join(FEET)}; give one of them")
    times, qpos = np.asarray(times, float), np.asarray(qpos, float)
    if qpos.ndim != 2 or qpos.shape[1] != model.nq or len(times) != len(qpos):
        raise InputError(f"capture qpos {qpos.shape} and times ({len(times)},) do not fit the model (nq = {model.nq})")
    if len(times) < 4 or np.any(np.diff(times) <= 0):
        raise InputError(f"a clean needs at least 4 capture frames at increasing times, got {len(times)}")
    layout = StateLayout.from_model(model)
    figure, tmap = Figure.from_model(model), TangentMap.from_layout(layout)
    pinned = pin_frames(times, pins, pin_ends)
    is_pin = np.zeros(len(times), bool)
    is_pin[pinned] = True
    capture_frames = FrameSet(times, qpos, np.ones(qpos.shape, bool), is_pin)
    anchor = anchors(qpos, layout.quat_slots)  # d = 0: every capture frame a frame of d, the pins fixed
    plain = FrameSet(times, anchor, np.repeat(is_pin[:, None], qpos.shape[1], axis=1), is_pin)
    t0, t1 = float(times[0]), float(times[-1])
    engine = InverseDynamics(model, figure.surface_sites)  # the effort bound of a capture needs the torques
    # every capture frame a point, the pins among them, and each panel's midpoint; more panels where the sites need them
    panels = frame_panels(times, qpos, tmap, engine)
    t, w = simpson_points(times, panels)
    reference = ReferenceMotion.from_samples(model, times, qpos, t, w)
    schedule = ContactSchedule.of(contacts or (), figure.contact_sites)
    flights = tuple(schedule.flights()) if flights is None else tuple(flights)
    # the planted limits' tolerance is penetration's, 1 mm less a capture's 0.1 mm resolution, not the keyed path's
    # 2 mm: a foot met within it floats at most FLOAT_LIMIT + 0.9 mm over its contact, inside a clean's 3 mm float bound
    # (docs/corpus.md "Cleaning the corpus") by the margin the bound's own measure needs (searched first, three unseen
    # cleans met every pair within a whole 1 mm and floated 3.00-3.01 mm; 83_02's, within 2 mm, 3.31 mm); the feet
    # measured at the capture's frames, as the bounds measure them (`figure_constraints`' frames)
    constraints, relaxations = figure_constraints(model, figure, reference, capture_frames, tuple(schedule), flights,
                                                  engine, capture=(times, qpos),
                                                  planted_tolerance=PENETRATION_TOLERANCE, frames=times,
                                                  no_jolt=_change_bound(reference, model, times, qpos))
    change = MeasureOfChange(reference, tmap, omega=np.pi / correction_time,
                             pose=equal_mass_matrices(model, reference.qpos))
    d0 = float(np.sum(model.body_mass)) * STANDARD_GRAVITY ** 2 * (t1 - t0)
    Y1, Y2 = interpolate(times, qpos, t, (1, 2))
    A0, A1, A2 = interpolate(times, anchor, t, (0, 1, 2))  # c - A: 0 in the quaternion slots, c elsewhere
    al = AugmentedLagrangian(change, constraints, tmap, engine, d0, base=(reference.qpos - A0, Y1 - A1, Y2 - A2))
    _capture_limits(al, plain, feet)
    knots = np.array([x for c in schedule for x in (c.start, c.end)], float)
    lc = LeastChange(model, layout, figure, plain, al, tuple(relaxations), knots, grid=times)
    return Displacement(lc, times, qpos, anchor, pinned, capture_frames, panels)


#: [m] the most the cubic between two quadrature points may miss a site's path by: the margin the penetration
#: constraint's tolerance leaves under its 1 mm bound for that cubic (`solver.constraint_set.PENETRATION_TOLERANCE`)
CUBIC_ERROR = TOLERANCES["penetration"] - PENETRATION_TOLERANCE
#: [panels] the most Simpson panels a frame interval is split into: points a sixteenth of a frame apart (2 ms at
#: 30 fps), the cubic's miss there 16^-3 of one panel's (4 cm between two points comes within 0.01 mm)
MAX_PANELS = 8


def frame_panels(times: np.ndarray, qpos: np.ndarray, tmap: TangentMap, engine) -> np.ndarray:
    """(m - 1,) Simpson panels of each capture frame interval (`simpson_points`): one, doubled while the cubic
    Hermite curve between two consecutive points (each site's position and velocity there: the curve whose
    deepest point the penetration constraint holds, `solver.constraints.penetration`) misses a site of
    `engine` at their midpoint by more than CUBIC_ERROR on the capture's own path, up to MAX_PANELS.

    The cubic's miss at the midpoint is h^4 |p''''| / 384 on a smooth path p over h (Burden & Faires, Numerical
    Analysis, 9th ed., thm. 3.9), so each doubling divides it by 16. A capture's frame interval is short enough
    on a clip of a body's motion (0.04 mm at 30 fps on a Bandai Namco walk) but not on one whose joints turn by
    tens of degrees from one frame to the next (poses estimated from video: 4.3 mm at 25 fps, 42 mm at 30 fps),
    where a heel's path between two points dipped 1 mm into the floor while the cubic held it out. A clean
    moves the capture by centimetres, not its motion's shape, so the panels that serve the capture serve it.

    Args:
        times: (m,) [s] the capture's frame times, increasing. qpos: (m, nq) its frames. tmap: TangentMap.
        engine: the sites' `InverseDynamics` (its `forward` and `site_velocities`).
    """
    panels = np.ones(len(times) - 1, int)
    while True:
        t, _ = simpson_points(times, panels)
        mid = 0.5 * (t[:-1] + t[1:])
        p, v = _sites(times, qpos, np.r_[t, mid], tmap, engine)
        n, h = len(t), np.diff(t)[:, None, None]
        cubic = 0.5 * (p[: n - 1] + p[1:n]) + h / 8.0 * (v[: n - 1] - v[1:n])  # the Hermite curve at the midpoint
        miss = np.linalg.norm(cubic - p[n:], axis=-1).max(axis=1)  # (n - 1,) [m]
        grow = np.zeros(len(panels), bool)
        grow[np.searchsorted(times, mid[miss > CUBIC_ERROR]) - 1] = True
        grow &= panels < MAX_PANELS
        if not grow.any():
            return panels
        panels[grow] *= 2


def _sites(times: np.ndarray, qpos: np.ndarray, t: np.ndarray, tmap: TangentMap, engine) -> tuple[np.ndarray, np.ndarray]:
    """(positions, velocities), each (len(t), k, 3) [m, m/s], of the engine's sites on the natural spline through
    the capture's frames at `t` [s]."""
    Y, Y1 = interpolate(times, qpos, t, 0), interpolate(times, qpos, t, 1)
    state = PathState(t, Y, Y1, np.zeros_like(Y), tmap, engine)
    return state.sites, state.site_velocities


class ChangeAcceleration(AccelerationBound):
    """No new jolt in a clean: the change's acceleration, not the path's, is bounded,

        |a_j(t) - a_c,j(t)| <= A_j   at every point,

    a_c the capture's own acceleration (the reference's `qacc`, noise and all: a clean keeps it) and A_j the
    peak of the capture low-pass filtered at 6 Hz (`solver.peak_bounds.filter_capture`, Winter 2009) by
    central differences at its frames (`_change_bound`): a correction accelerates no joint harder than the
    captured motion itself does (`AccelerationBound`'s smooth form, on the figure's `jolt_columns`). The limit
    is (1 - RELATIVE_TOLERANCE) A_j with tolerance RELATIVE_TOLERANCE A_j, so a change that meets it within its
    tolerance stays within A_j itself.

    Args:
        qacc: (n, nv) the capture's acceleration at the n points. columns: `jolt_columns` of the figure's
            layout, (dofs (j, 3), labels (j,), linear (j,)). peaks: (j,) A_j > 0 [m/s^2 or rad/s^2].
    """

    def __init__(self, qacc: np.ndarray, columns: tuple, peaks: np.ndarray):
        dofs, labels, linear = columns
        peaks = np.asarray(peaks, float)  # the limit and its tolerance inside A_j: met within tolerance, <= A_j
        super().__init__(len(qacc), dofs, (1.0 - RELATIVE_TOLERANCE) * peaks, RELATIVE_TOLERANCE * peaks, labels,
                         linear=linear)
        self._ref = np.asarray(qacc, float)[:, self.dofs]  # (n, j, 3)

    def _accelerations(self, state):
        return state.motion.qacc[:, self.dofs] - self._ref


def _change_bound(reference: ReferenceMotion, model, times, qpos) -> ChangeAcceleration:
    """The clean's no-jolt bound (`ChangeAcceleration`), the figure's in its place: the 6 Hz capture's peaks by
    central differences at its frames (`solver.peak_bounds.frame_derivatives`), the measure of the acceptance
    figures: the change's own central differences are weighted means of its spline's accelerations at the
    frames, so a change within the bound there shows at most these peaks by that measure (at 30 fps the
    spline's peaks of the filtered capture run 12-21 % above them).

    A joint's peak is at least what the filtered capture can resolve, `still_peaks`: a joint the capture holds
    still (a seated subject's ankles, 0.36 rad/s^2) had a limit the clean could not move it by, and a heel's
    3.17 mm slide was certified out of reach where 2.3 rad/s^2 at the ankle meets it."""
    layout = StateLayout.from_model(model)
    columns = jolt_columns(layout)
    smooth = filter_capture(times, qpos, layout)
    qacc = frame_derivatives(model, times, smooth)[1]
    peaks = np.maximum(np.linalg.norm(qacc[:, columns[0]], axis=-1).max(axis=0), still_peaks(columns[2]))
    return ChangeAcceleration(reference.qacc, columns, peaks)


def still_peaks(linear: np.ndarray) -> np.ndarray:
    """(j,) [m/s^2 or rad/s^2] the least peak the capture filtered at CUTOFF_HZ resolves for each jolt column
    (`linear` (j,) bool: a position's, else a rotation's): the peak acceleration of a CUTOFF_HZ sinusoid of the
    capture's resolution, resolution x (2 pi CUTOFF_HZ)^2 (0.14 m/s^2 for 0.1 mm, 2.5 rad/s^2 for 0.1 deg). A
    peak below it is below the capture's resolution, not a movement the capture shows."""
    return np.where(np.asarray(linear, bool), CAPTURE_RESOLUTION, ANGLE_RESOLUTION) * (2.0 * np.pi * CUTOFF_HZ) ** 2


def _capture_limits(al: AugmentedLagrangian, plain: FrameSet, feet: str) -> None:
    """Set the limits the capture witnesses, on `plain` (d = 0: the capture's own path).

    * Each slide limit (`solver.constraint_set` made it for a keyed path: what the keyframes force plus half
      of what a known path slides beyond that). "planted": what the pins force, no allowance: a foot in
      contact stays where it is put (the capture's contacts start and end with the site still moving and its
      marker noise adds speed, 16_23's resting heel 0.1-0.5 m/s frame to frame: planting them moves more of
      the body than a halved slide would). "captured": the capture's own slide over that contact, neither
      more nor less.
    * The unit-norm limit at each point: at least the capture's own (`solver.constraints.unit`). Between
      two capture frames c + d is the spline through the displacement's frames, whose quaternions are the
      cleaned frames' own: a joint that turns far from one frame to the next shortens the chord, and only a
      change of the pose at those frames could lengthen it. The clip is written at its frames, where every
      quaternion is unit; a capture at 30 fps whose elbow turns 50 degrees between two frames dips to 0.9
      there (bvh_test1), which the least change would otherwise spend a search on and report out of reach.
    """
    from solver.spline_basis import SplineBasis

    state = al.state(SplineBasis(plain.times, al.t), plain.values)
    for c in al.constraints:
        if c.name == "slide":
            c.limit = c.measure(state) if feet == "captured" else np.array(c.forced, float)
        elif c.name == "unit":
            c.limit = np.maximum(c.limit, c.measure(state))


def solve_displacement(disp: Displacement, options: LeastChangeOptions | None = None, *, should_stop=None,
                       progress=None) -> Solution:
    """Solve the displacement (`solve_least_change` on `disp.lc`; its arguments and Solution, whose frames
    are the displacement's: `clean_solution` makes the cleaned clip of it)."""
    return solve_least_change(disp.lc, options, should_stop=should_stop, progress=progress)


def cleaned_qpos(disp: Displacement, frames: FrameSet, times: np.ndarray | None = None) -> np.ndarray:
    """(n, nq) the cleaned clip c + d at `times` [s] (None: the capture's frames, where c is the capture's
    own frames exactly), d from the displacement's `frames`; quaternions as the sum has them."""
    if times is None:
        return disp.qpos + (frames.path(disp.times) - disp.anchor)
    t = np.asarray(times, float)
    return interpolate(disp.times, disp.qpos - disp.anchor, t, 0) + frames.path(t)


def clean_solution(disp: Displacement, solution: Solution) -> Solution:
    """The Solution of the cleaned clip: `frames` through every capture frame with the cleaned values
    (c + d there), `initial` the capture's own frames, both with the pins and the clip's ends as their
    keyframes; the rest (rounds, status, certificate, relaxations) the displacement's solve's.

    The cleaned path between the capture's frames is the natural spline through those samples: it equals
    c + d where d's frames lie on capture frames (both are then cubic splines with knots at the frames)
    and differs by d's interpolation error between them otherwise.
    """
    cap = disp.capture_frames
    keys = cap.is_keyframe.copy()
    keys[[0, -1]] = True
    frames = FrameSet(cap.times, cleaned_qpos(disp, solution.frames), cap.fixed, keys)
    return replace(solution, frames=frames, initial=FrameSet(cap.times, cap.values, cap.fixed, keys))
