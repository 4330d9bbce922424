"""The figure's objective from term names and weights (command line, keyframe files, API).

Term names: penetration (eq. 12), unit (eq. 9 f1), bending (sec. 5), hinge and rom (sec. 5, docs/anatomy.md),
near (the departure from the plain spline through the keyframes, `solver.terms.near`), smooth (covariant
acceleration of every quaternion plus the root's linear acceleration, eq. 9 f2), and, when the inverse-dynamics terms
are available, torque and root (sec. 6, appendix A) and forces (the peak ground force and pelvis acceleration
within the plain spline's and the capture's, `solver.peak_bounds`; docs/dynamics.md). With a contact schedule (docs/contacts.md "The contact terms";
`solver.contacts.Contact`s: site, start, end, surface): planted (feet on their surface and not sliding
during a contact), clearance (swing feet keep 2 cm, every site min(2 cm, g T^2/8) in a flight of length T)
- both on by default - and cone
(the root wrench inside the friction cone of the feet in contact; needs the inverse dynamics, "all").
Every term is registered in `solver.terms.registry` (name, factory, default weight, what it needs); a
term registered there with `register_term` is accepted here and on the command line like these.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from solver.contact_schedule import ContactSchedule
from solver.errors import InputError
from solver.layout import StateLayout
from solver.objective import Objective
from solver.quadrature import DEFAULT_RATE
from solver.schedule_conflicts import ScheduleConflicts
from solver.surfaces import StaticSurfaces
from solver.terms.registry import DEFAULT_WEIGHTS, TermBuild, build_term, registered_terms, term_spec

__all__ = ["CONTACT_MARGIN", "CONTACT_PENETRATION_WEIGHT", "CONTACT_TERMS", "CONTACT_TERMS_BY_DEFAULT",
           "DEFAULT_CONTACT_TERMS", "DEFAULT_LIMITS", "DEFAULT_TERMS", "DEFAULT_WEIGHTS", "MARGIN", "NEAR_KEYFRAME",
           "Problem", "default_limits", "figure_objective", "figure_problem", "keyframe_conflicts", "make_problem",
           "parse_terms", "term_names"]

#: The terms used when none are chosen: the geometric terms of the paper's sec. 5, with the anatomical
#: limits (hinge, rom: docs/anatomy.md) and the departure from the plain spline (near: docs/corpus.md
#: "Near the plain spline").
DEFAULT_TERMS = ("penetration", "unit", "bending", "smooth", "hinge", "rom", "near")

#: Weight of each built-in term when it is switched on without one: DEFAULT_WEIGHTS, defined with the
#: registrations in `solver.terms.registry` (a registered term's own: its `TermSpec.default_weight`).

#: The contact terms: they need a contact schedule. planted and clearance join the defaults when one is
#: known, with near_sites (the contact sites near the plain spline's, `solver.terms.near_sites`); cone
#: (inverse dynamics) joins "all".
CONTACT_TERMS = ("planted", "clearance", "cone")
DEFAULT_CONTACT_TERMS = ("planted", "clearance", "near_sites")

#: Penalty-continuation bounds (`SolveOptions.limits`), in each term's `violation` unit, set inside the
#: acceptance bounds (penetration <= 1 mm, hyperextension <= 2 deg, |1 - |q|| <= 5 %) with headroom.
DEFAULT_LIMITS = {"penetration": 0.0005, "bending": float(np.radians(1.0)), "unit": 0.03,
                  # planted: max(|h - h0|, tau |v_t|) where a contact is fully on [m] (tau = 0.1 s: 2 cm
                  # or 20 cm/s); clearance: intrusion into the band (2 cm in swing cores, the lifted c_f in flights) [m].
                  # Peaks, so looser than the acceptance means (float <= 5 mm): with 1 cm / 5 mm the
                  # run-and-step solve still missed planted after 3 boosts (41 -> 25 -> 12 mm)
                  "planted": 0.02, "clearance": 0.01}


def term_names() -> list[str]:
    """Every registered term name (`solver.terms.registry`), built-ins first; the contact terms need a
    contact schedule."""
    return [spec.name for spec in registered_terms()]


def _needs_schedule(name: str) -> InputError:
    return InputError(f"objective term {name!r} needs a contact schedule (which site touches which surface "
                      "when): give the keyframe file a 'contacts' list (dynsplines mocap writes one) or pass "
                      "contacts=; or leave the term out")


#: Whether a contact schedule switches the contact terms on by default (planted and clearance; cone
#: joins "all"). On: with variable frames at every touch-down and lift-off (`SolveOptions.term_knots`),
#: the penetration weight CONTACT_PENETRATION_WEIGHT and the kinematics-only engine (`SiteKinematics`)
#: the solve with them costs about as many evaluations as the solve without (docs/benchmarks.md "Contact
#: terms on four inputs"). The frames at touch-down and lift-off matter: a spline with one frame per
#: keyframe interval cannot both hold a foot still and keep the other sites up, and penalty continuation
#: then boosts the penetration term round after round (docs/contacts.md "The contact terms").
CONTACT_TERMS_BY_DEFAULT = True

#: The penetration term's weight with the planted term on (DEFAULT_WEIGHTS' 1 otherwise). The weights
#: are renormalized by the plain spline's integrals (eq. 7), and the plain spline's feet go 10 cm into
#: the floor or a step, so at weight 1 a planted foot held at the surface buys mm of depth for almost
#: nothing: penalty continuation would boost the weight to 100 in two extra rounds; starting at 100
#: meets the same bounds in one (docs/contacts.md "The contact terms").
CONTACT_PENETRATION_WEIGHT = 100.0


def parse_terms(spec: str | None, weights: dict[str, float] | None = None, contacts=(),
                assume_schedule: bool = False) -> dict[str, float]:
    """Term weights from a command-line list ("all", or "penetration,unit,...") and overrides.

    Args:
        spec: None (the default terms; with a contact schedule also planted and clearance), "all"
            (every term; the contact terms, cone included, only with a schedule), or a comma-separated
            list of term names (the contact terms need a schedule; leave them out of the list to switch
            them off).
        weights: {name: weight} overrides (a name here also switches the term on).
        contacts: the contact schedule (`ContactSchedule` or contacts), if any (only whether it is empty
            matters here).
        assume_schedule: choose as if a non-empty schedule were known (check a spec before the
            contacts are: `mocap` and `batch` detect each clip's own).
    Returns:
        {name: weight >= 0}.
    Raises:
        InputError: unknown term (lists the valid ones), a contact term without a schedule, a weight
            that is not a number, negative or non-finite.
    """
    valid = term_names()
    have = assume_schedule or bool(len(contacts or ()))
    if spec is None:
        chosen = {t.name: t.default_weight for t in registered_terms()
                  if t.default and (not t.contacts or (have and CONTACT_TERMS_BY_DEFAULT))}
    else:
        all_ = [t.name for t in registered_terms() if not t.contacts or (have and CONTACT_TERMS_BY_DEFAULT)]
        names = all_ if spec.strip() == "all" else [s.strip() for s in spec.split(",") if s.strip()]
        chosen = {}
        for n in names:
            if n not in valid:
                raise InputError(f"unknown objective term {n!r}; valid terms: {', '.join(valid)} (or 'all')")
            if term_spec(n).contacts and not have:
                raise _needs_schedule(n)
            chosen[n] = term_spec(n).default_weight
    if "planted" in chosen and "penetration" in chosen:
        chosen["penetration"] = CONTACT_PENETRATION_WEIGHT
    for n, w in (weights or {}).items():
        if n not in valid:
            raise InputError(f"unknown objective term {n!r} in a weight; valid terms: {', '.join(valid)}")
        if term_spec(n).contacts and not have:
            raise _needs_schedule(n)
        try:
            if isinstance(w, bool):
                raise TypeError
            w = float(w)
        except (TypeError, ValueError):
            raise InputError(f"weight of term {n!r} is {w!r}; give a number >= 0, e.g. {n}=0.5") from None
        if not np.isfinite(w) or w < 0:
            raise InputError(f"weight of term {n!r} is {w}; weights must be finite and >= 0")
        chosen[n] = w
    if not chosen:
        raise InputError(f"no objective terms chosen; valid terms: {', '.join(valid)}")
    return chosen


#: [m] the penetration term's margin, and with the planted term on (then also the height a planted site
#: rests at): a planted site sits at the margin, and motion capture's planted sites sit about 2 mm up
#: (the float metric counts it), so with the planted term the margin is 2 mm. A schedule alone (a
#: keyframe file's contacts, without the contact terms) changes nothing.
MARGIN, CONTACT_MARGIN = 0.005, 0.002


def figure_objective(model, weights: dict[str, float], t0: float, t1: float, rate: float = 400.0,
                     margin: float | None = None, contacts=(), conflicts: ScheduleConflicts | None = None,
                     plain=None, peaks=None, airborne=None) -> Objective:
    """The objective for a figure in a scene.

    Args:
        model: MjModel of the scene with the figure (loaded once by the caller).
        weights: {term name: lambda_j} from `parse_terms`.
        t0, t1: [s] the keyframe interval. rate: quadrature points per second.
        margin: [m] clearance the penetration term keeps from surfaces (and the rest height of a
            planted site, so that the two terms agree); default MARGIN, CONTACT_MARGIN with the planted
            term on.
        contacts: the contact schedule (a `ContactSchedule`, or objects with site, start, end,
            surface), for planted, clearance and cone.
        conflicts: what keyframes contradict in the schedule (`keyframe_conflicts`), for the planted
            and clearance terms (default none).
        plain: the plain spline's FrameSet, whose own joint angles the anatomical terms allow
            (`TermBuild.plain`; default none: the published ranges alone).
        peaks: the forces term's `solver.peak_bounds.PeakBounds` (default: the plain spline's own, with
            `plain`; without either, the peaks of the path the solve starts from, `PeakForces.prepare`).
        airborne: ((start, end), ...) [s] where the capture flies (`capture_airborne`), for the
            clearance term: its flights follow the capture's; None: every gap of the schedule is a flight.
    Returns:
        Objective (scales 1; `solve` renormalizes if asked).
    Raises:
        InputError: unknown term, a contact term without a schedule, a bad contact, or the scene lacks
            what a term needs (contact sites, surfaces).
    """
    found = StaticSurfaces.from_model(model)  # the schedule checked once, against this scene
    contacts = ContactSchedule.of(contacts or (), surfaces=found.names if found.count else None)
    if margin is None:
        margin = CONTACT_MARGIN if contacts and weights.get("planted", 0) > 0 else MARGIN
    specs = [term_spec(name) for name in weights]
    if peaks is None and plain is not None and weights.get("forces", 0) > 0:
        from solver.peak_bounds import peak_bounds

        peaks = peak_bounds(model, plain)  # the plain spline's own peaks (no capture)
    for spec in specs:
        if spec.contacts and not contacts:
            raise _needs_schedule(spec.name)
    # one engine (site positions and velocities, and the inverse dynamics if a term reads forces) shared
    # by every term that reads it: the `PathContext` runs its forward pass once per evaluation and the
    # objective its reverse pass once for the sum of the terms' gradients
    build = TermBuild(model, (float(t0), float(t1)), margin, contacts, forces=any(s.forces for s in specs),
                      conflicts=conflicts, plain=plain, peaks=peaks, airborne=airborne)
    terms = [build_term(spec, build) for spec in specs]
    return Objective(terms, np.array([weights[s.name] for s in specs], float), t0, t1, rate)


#: [s] `keyframe_conflicts` with a path: a swinging site is also checked this close to each keyframe
#: (the keyframe fixes the path there to within a few mm: 127_33's toe grazes the fitted step's edge
#: 1 mm up 6 ms after a keyframe, which no weight of the clearance term could lift 2 cm)
NEAR_KEYFRAME = (-0.01, -0.005, 0.005, 0.01)


def keyframe_conflicts(objective: Objective, times, qpos, path=None) -> ScheduleConflicts:
    """Keyframes that contradict the contact schedule, from the objective's planted and clearance terms
    (`Planted.conflicts`, `Planted.slides`, `Clearance.lower_lifts`, `Clearance.conflicts`): a query,
    the terms are not changed. Build the objective with the result (`figure_objective(...,
    conflicts=)`, as `figure_problem` does) to leave the contacts and swings concerned out of the terms'
    `violation` (keyframes are met exactly, so penalty continuation could not reach the bound there).

    Args:
        objective: from `figure_objective`. times: (k,) keyframe times [s]. qpos: (k, nq) keyframe
            poses (free components filled, e.g. `FrameSet.from_keyframes(...).values[is_keyframe]`).
        path: optional path(t) -> (n, nq) of the plain spline: then the clearance term is also checked
            NEAR_KEYFRAME around each keyframe (reported as that keyframe).
    Returns:
        ScheduleConflicts; its `found`: [(kind, keyframe index, site, distance [m]), ...]: "planted": the
        site's height above its plant height; "sliding": two keyframes in one contact (ends included)
        hold the site this far apart along the ground; "clearance": how far inside the clearance band.
    """
    times, qpos = np.asarray(times, float), np.asarray(qpos, float)
    out = ScheduleConflicts()
    for term in objective.terms:
        if term.name == "planted":
            out = out.merged(term.conflicts(times, qpos)).merged(term.slides(times, qpos))
            if path is not None:
                out = out.merged(term.held(times, qpos, path))
        if term.name == "clearance":
            out = out.merged(_clearance_conflicts(term, times, qpos, path))
    return out


def _clearance_conflicts(term, times, qpos, path) -> ScheduleConflicts:
    """`keyframe_conflicts` of the clearance term: the lift ceilings at the keyframes (the plain spline
    near them is lower), the keyframes, then with `path` the plain spline NEAR_KEYFRAME around them
    (more than half the bound inside the band), reported as their keyframe (the largest distance)."""
    got = term.lower_lifts(times, qpos)
    got = got.merged(term.conflicts(times, qpos, given=got))
    found = {(k, site): d for _, k, site, d in got.found}
    if path is not None:
        near = (times[:, None] + np.asarray(NEAR_KEYFRAME)).ravel()
        owner = np.repeat(np.arange(len(times)), len(NEAR_KEYFRAME))
        keep = (near > times[0]) & (near < times[-1])
        more = term.conflicts(near[keep], np.asarray(path(near[keep])), given=got,
                              tolerance=0.5 * DEFAULT_LIMITS["clearance"])
        for _, i, site, d in more.found:
            key = (int(owner[keep][i]), site)
            found[key] = max(found.get(key, 0.0), d)
        got = got.merged(more)
    return got.with_found(("clearance", k, site, d) for (k, site), d in sorted(found.items()))


def figure_problem(model, weights: dict[str, float], keyframes, rate: float = 400.0, contacts=(), peaks=None,
                   airborne=None):
    """The objective and the plain spline's frames for keyframes of a figure, with the keyframes that
    contradict the contact schedule found (`keyframe_conflicts`) and the contact terms built with what
    they excuse: what `solver.animate`, the command line and the benchmarks solve.

    Args:
        model: MjModel of the scene. weights: {term: lambda_j} (`parse_terms`). keyframes: Keyframes
            (values (k, nq), times (k,) [s]). rate: quadrature points per second. contacts: the
            schedule (`ContactSchedule`, or contacts). peaks: the forces term's `PeakBounds` (default:
            the plain spline's own). airborne: the capture's flights for the clearance term
            (`figure_objective`).
    Returns:
        (objective, initial, conflicts): Objective, FrameSet (the plain spline's frames), and the
        `keyframe_conflicts` value (`ScheduleConflicts`; `.found` lists the conflicts).
    Raises:
        InputError: as `figure_objective`.
    """
    from solver.frames import FrameSet

    layout = StateLayout.from_model(model)
    t0, t1 = keyframes.times[0], keyframes.times[-1]
    initial = FrameSet.from_keyframes(keyframes, layout.quat_slots)
    if peaks is None and weights.get("forces", 0) > 0:  # once, for both objectives below
        from solver.peak_bounds import peak_bounds

        peaks = peak_bounds(model, initial)
    objective = figure_objective(model, weights, t0, t1, rate=rate, contacts=contacts, plain=initial, peaks=peaks,
                                 airborne=airborne)
    conflicts = keyframe_conflicts(objective, keyframes.times, initial.values[initial.is_keyframe], path=initial.path)
    if conflicts.excuses:  # the contact terms built again, with what the keyframes excuse
        objective = figure_objective(model, weights, t0, t1, rate=rate, contacts=contacts, conflicts=conflicts,
                                     plain=initial, peaks=peaks, airborne=airborne)
    return objective, initial, conflicts


def default_limits(weights: dict[str, float]) -> tuple:
    """`SolveOptions.limits` for the chosen terms: ((name, tolerance), ...) from DEFAULT_LIMITS (a
    registered term's own: its `TermSpec.limit`)."""
    out = []
    for n in weights:
        limit = DEFAULT_LIMITS.get(n, term_spec(n).limit if n in term_names() else None)
        if limit is not None and weights[n] > 0:
            out.append((n, limit))
    return tuple(out)


@dataclass(frozen=True)
class Problem:
    """Everything that defines one figure solve, built once (`make_problem`) and read by the solver, the
    command line, the benchmarks and the outputs alike (read-only).

    Attributes:
        model: mujoco.MjModel of the scene with the figure (loaded once by the caller; not modified).
        keyframes: Keyframes, values (k, nq) with nq = model.nq, times (k,) [s].
        contacts: the contact schedule the objective uses (`ContactSchedule`; empty: none).
        weights: {term name: lambda_j} of the chosen terms (`parse_terms`), read-only.
        limits: ((term name, tolerance), ...): the penalty-continuation bounds of the chosen terms
            (`default_limits`), in each term's `violation` unit.
        rate: quadrature points per second [1/s].
        objective: the Objective (eq. 1; scales 1, `solve` renormalizes by eq. 7).
        initial: FrameSet of the plain spline through the keyframes, (k, nq) values.
        conflicts: `ScheduleConflicts` (`keyframe_conflicts`): what keyframes contradict in the contact
            schedule, excused from the bounds; its `found`: ((kind, keyframe index, site, distance [m]), ...).
        figure: the model's `solver.figure.Figure` (contact sites, feet, flexion axes, segments, masses).
        force_bounds: the forces term's `solver.peak_bounds.PeakBounds` (peak ground force and pelvis
            acceleration: the larger of the plain spline's and the filtered capture's), or None when the
            term is not chosen.
        capture: None or (times (n,) [s], qpos (n, nq)): the motion capture the keyframes came from.
        airborne: None or ((start, end), ...) [s]: the flights given or found on the capture.
    """

    model: object = field(repr=False)
    keyframes: object
    contacts: tuple
    weights: Mapping[str, float]
    limits: tuple
    rate: float
    objective: Objective = field(repr=False)
    initial: object = field(repr=False)
    conflicts: ScheduleConflicts = field(default_factory=ScheduleConflicts)
    figure: object = field(default=None, repr=False)
    force_bounds: object = None
    capture: tuple | None = field(default=None, repr=False)
    airborne: tuple | None = None

    @property
    def terms(self) -> tuple[str, ...]:
        """The chosen term names, in the objective's order."""
        return tuple(self.weights)


def capture_airborne(model, times, qpos) -> tuple[tuple[float, float], ...]:
    """The intervals [s] where a motion in the model's scene is airborne: every contact site's lowest
    point (`solver.contacts.contact_points`) above the flight metric's 3 cm over the surface under it
    (`solver.terms.clearance.airborne_intervals`; `solver.motion_metrics` "flight_time_s").

    Args:
        model: MjModel of the scene with the figure. times: (n,) increasing frame times [s], n >= 2.
        qpos: (n, nq) the motion (the retargeted capture).
    Returns:
        ((start, end), ...) [s], sorted and disjoint.
    Raises:
        InputError: shapes that disagree (`airborne_intervals`).
    """
    from solver.contacts import contact_points, site_heights
    from solver.terms.clearance import airborne_intervals

    qpos = np.atleast_2d(np.asarray(qpos, float))
    if qpos.shape[1] != int(model.nq):
        raise InputError(f"capture qpos has {qpos.shape[1]} components but the model has nq = {model.nq}")
    return airborne_intervals(times, site_heights(model, contact_points(model, qpos)))


def make_problem(model, keyframes, terms: str | list[str] | tuple[str, ...] | None = None,
                 weights: dict[str, float] | None = None, contacts=(), rate: float | None = None,
                 capture=None, airborne=None) -> Problem:
    """The one factory of a figure's `Problem`, from what the command line and the Python API have.

    Args:
        model: mujoco.MjModel of a scene holding the figure (free root, ball joints, the contact sites).
        keyframes: Keyframes of the figure's qpos, values (k, nq), times (k,) [s].
        terms: None (the default terms: the geometric terms of sec. 5, plus planted and clearance with a
            contact schedule), "all", a comma-separated string or a list of names (`term_names()`).
        weights: {term name: lambda_j >= 0} overriding the default weights; a name here also switches
            the term on.
        contacts: the contact schedule (`solver.contacts.Contact`s), e.g. a keyframe file's.
        rate: quadrature points per second [1/s]; default `solver.animate.DEFAULT_RATE` (400).
        capture: None, or (times (n,) [s] on the keyframes' clock, qpos (n, nq)): the retargeted motion
            capture the keyframes were made from, whose filtered peaks join the forces term's bounds
            (`solver.peak_bounds`; only read when the term is chosen) and whose flights (every site above
            the flight height, `capture_airborne`) are the clearance term's (docs/contacts.md "The
            contact terms"; only read when the term is chosen).
        airborne: ((start, end), ...) [s], the flights of the motion the keyframes came from (a keyframe
            file's "flights"), used instead of the capture's; None: the capture's, or without a capture
            every gap of the schedule is a flight.
    Returns:
        Problem.
    Raises:
        InputError: `keyframes` is not Keyframes or does not fit the model (nq), an unknown term, a bad
            weight, a contact term without a schedule, a bad rate, a scene without what a term needs.
    """
    from solver.keyframes import Keyframes

    if not isinstance(keyframes, Keyframes):
        raise InputError(f"keyframes must be a solver.Keyframes, got {type(keyframes).__name__}")
    nq = int(getattr(model, "nq", -1))
    if keyframes.values.shape[1] != nq:
        raise InputError(f"{keyframes.source}: keyframes have {keyframes.values.shape[1]} qpos components but "
                         f"the model has nq = {nq}; are they for this scene's figure?")
    if terms is not None and not isinstance(terms, str):
        terms = ",".join(terms)
    rate = DEFAULT_RATE if rate is None else float(rate)
    if not np.isfinite(rate) or rate <= 0:
        raise InputError(f"rate must be > 0 quadrature points per second, got {rate}")
    contacts = ContactSchedule.of(contacts or ())  # checked once; a file's schedule keeps its labels
    chosen = parse_terms(terms, weights, contacts)
    peaks = None
    if chosen.get("forces", 0) > 0:
        from solver.frames import FrameSet
        from solver.peak_bounds import peak_bounds

        plain = FrameSet.from_keyframes(keyframes, StateLayout.from_model(model).quat_slots)
        peaks = peak_bounds(model, plain, capture)
    if airborne is None and capture is not None and chosen.get("clearance", 0) > 0:
        airborne = capture_airborne(model, *capture)
    objective, initial, conflicts = figure_problem(model, chosen, keyframes, rate=rate, contacts=contacts,
                                                   peaks=peaks, airborne=airborne)
    from solver.figure import Figure

    return Problem(model, keyframes, contacts, MappingProxyType(dict(chosen)), default_limits(chosen), rate,
                   objective, initial, conflicts, Figure.from_model(model), peaks, capture,
                   _flights(model, airborne, capture))


def _flights(model, airborne, capture) -> tuple | None:
    """((start, end), ...) [s]: the flights given, else the capture's (`capture_airborne`), else None."""
    if airborne is None and capture is not None:
        airborne = capture_airborne(model, *capture)
    return None if airborne is None else tuple((float(a), float(b)) for a, b in airborne)
