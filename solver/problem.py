"""One figure problem, from one spec: the reference motion and the constraints' inputs.

The optimized path is the least change to a reference motion - the plain spline through the keyframes
- that meets the figure's constraints (docs/design.md, `solver.least_change`). What defines one problem
is a `ProblemSpec` (keyframes, contact schedule, flights, the motion capture the keyframes came from,
whether the force bounds are on); `build_problem` checks it against the model once and returns the
`Problem` every caller solves: keyframe files, clips, batch and the benchmarks alike.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from solver.contact_schedule import ContactSchedule
from solver.errors import InputError

__all__ = ["TERM_SETS", "Problem", "ProblemSpec", "build_problem", "capture_airborne", "forces_of"]

#: the constraint sets of `--terms` (and a keyframe file's "terms"): "default" the figure's constraints
#: (penetration, planted feet, clearance, hinge, range of motion, no jolts); "all" the force bounds too
#: (`solver.constraints.forces`).
TERM_SETS = ("default", "all")


def forces_of(terms, where: str = "terms") -> bool:
    """Whether a `--terms` value (or a keyframe file's "terms") switches the force bounds on.

    Args:
        terms: None or "default" (no), "all" (yes). where: what to name in an error (the option or the
            file and field).
    Returns:
        bool.
    Raises:
        InputError: any other value (the weighted terms of the penalty method are gone: the constraints
            are always on, the force bounds with "all").
    """
    if terms is None or terms == "default":
        return False
    if terms == "all":
        return True
    raise InputError(f"{where} is {terms!r}; give 'all' (the constraints and the force bounds) or 'default' "
                     "(the constraints): every constraint is on, none is a weighted term (docs/design.md)")


@dataclass(frozen=True)
class ProblemSpec:
    """What defines one figure problem (read-only; `build_problem` checks it against a model).

    Attributes:
        keyframes: Keyframes of the figure's qpos, values (k, nq), times (k,) [s].
        contacts: the contact schedule (`solver.contacts.Contact`s, or a `ContactSchedule`); () none.
        forces: also the force bounds (no wrench in flight, the friction cone, the peak ground force).
        capture: None, or (times (n,) [s] on the keyframes' clock, qpos (n, nq)): the retargeted motion
            capture the keyframes were made from: its filtered peaks join the no-jolt and force bounds
            (`solver.peak_bounds`) and its flights are the problem's (`capture_airborne`).
        airborne: ((start, end), ...) [s] where the motion flies (a keyframe file's "flights"), used
            instead of the capture's; None: the capture's, else the schedule's gaps.
        bounds: constraints of your own, each a callable make(t) -> `solver.Constraint` given the quadrature
            times t (n,) [s] (docs/design.md "A constraint of your own"); () none.
    """

    keyframes: object
    contacts: tuple = ()
    forces: bool = False
    capture: tuple | None = field(default=None, repr=False)
    airborne: tuple | None = None
    bounds: tuple = ()


@dataclass(frozen=True)
class Problem:
    """One figure problem, built once (`build_problem`) and read by the solver, the command line, the
    benchmarks and the outputs alike (read-only).

    Attributes:
        model: mujoco.MjModel of the scene with the figure (loaded once by the caller; not modified).
        keyframes: Keyframes, values (k, nq) with nq = model.nq, times (k,) [s].
        contacts: the contact schedule (`ContactSchedule`; empty: none).
        forces: whether the force bounds are on (`ProblemSpec.forces`).
        initial: FrameSet of the plain spline through the keyframes (the reference motion), (k, nq).
        figure: the model's `solver.figure.Figure` (contact sites, feet, flexion axes, segments, masses).
        force_bounds: `solver.peak_bounds.PeakBounds` (peak ground force and pelvis acceleration: the
            larger of the plain spline's and the filtered capture's), or None without the force bounds.
        capture: None or (times (n,) [s], qpos (n, nq)): the motion capture the keyframes came from.
        airborne: None or ((start, end), ...) [s]: the flights given or found on the capture.
        bounds: the constraints of the caller's own (`ProblemSpec.bounds`).
    """

    model: object = field(repr=False)
    keyframes: object
    contacts: tuple
    forces: bool
    initial: object = field(repr=False)
    figure: object = field(default=None, repr=False)
    force_bounds: object = None
    capture: tuple | None = field(default=None, repr=False)
    airborne: tuple | None = None
    bounds: tuple = ()

    @property
    def terms(self) -> str:
        """The constraint set, as `--terms` names it: "all" with the force bounds, else "default"."""
        return "all" if self.forces else "default"


def capture_airborne(model, times, qpos) -> tuple[tuple[float, float], ...]:
    """The intervals [s] where a motion in the model's scene is airborne: the lowest point of every contact
    site of the model's figure (`solver.contacts.contact_points`) above the flight metric's 3 cm over the
    surface under it (`solver.contacts.airborne_intervals`; `runner.motion_metrics` "flight_time_s").

    Args:
        model: MjModel of the scene with the figure. times: (n,) increasing frame times [s], n >= 2.
        qpos: (n, nq) the motion (the retargeted capture).
    Returns:
        ((start, end), ...) [s], sorted and disjoint.
    Raises:
        InputError: shapes that disagree (`airborne_intervals`).
    """
    from solver.contacts import airborne_intervals, contact_points, site_heights

    qpos = np.atleast_2d(np.asarray(qpos, float))
    if qpos.shape[1] != int(model.nq):
        raise InputError(f"capture qpos has {qpos.shape[1]} components but the model has nq = {model.nq}")
    return airborne_intervals(times, site_heights(model, contact_points(model, qpos)))


def build_problem(model, spec: ProblemSpec) -> Problem:
    """The one factory of a figure's `Problem`.

    Args:
        model: mujoco.MjModel of a scene holding the figure (free root, ball joints, the contact sites).
        spec: ProblemSpec.
    Returns:
        Problem.
    Raises:
        InputError: `spec` is not a ProblemSpec, keyframes that are not Keyframes or do not fit the model
            (nq), a bad contact (unknown site or surface), a capture that does not fit the model.
    """
    from solver.figure import Figure
    from solver.frames import FrameSet
    from solver.keyframes import Keyframes
    from solver.layout import StateLayout
    from solver.surfaces import StaticSurfaces

    if not isinstance(spec, ProblemSpec):
        raise InputError(f"spec must be a solver.ProblemSpec, got {type(spec).__name__}")
    keyframes = spec.keyframes
    if not isinstance(keyframes, Keyframes):
        raise InputError(f"keyframes must be a solver.Keyframes, got {type(keyframes).__name__}")
    nq = int(getattr(model, "nq", -1))
    if keyframes.values.shape[1] != nq:
        raise InputError(f"{keyframes.source}: keyframes have {keyframes.values.shape[1]} qpos components but "
                         f"the model has nq = {nq}; are they for this scene's figure?")
    found = StaticSurfaces.from_model(model)
    figure = Figure.from_model(model)
    contacts = ContactSchedule.of(spec.contacts or (), figure.contact_sites, found.names if found.count else None)
    initial = FrameSet.from_keyframes(keyframes, StateLayout.from_model(model).quat_slots)
    peaks = None
    if spec.forces:
        from solver.peak_bounds import peak_bounds

        peaks = peak_bounds(model, initial, spec.capture)
    airborne = spec.airborne
    if airborne is None and spec.capture is not None:
        airborne = capture_airborne(model, *spec.capture)
    airborne = None if airborne is None else tuple((float(a), float(b)) for a, b in airborne)
    return Problem(model, keyframes, contacts, bool(spec.forces), initial, figure, peaks,
                   spec.capture, airborne, tuple(spec.bounds))
