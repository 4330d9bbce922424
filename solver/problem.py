"""The figure's objective from term names and weights (command line, keyframe files, API).

Term names: penetration (eq. 12), unit (eq. 9 f1), bending (sec. 5), smooth (covariant acceleration of
every quaternion plus the root's linear acceleration, eq. 9 f2), and, when the inverse-dynamics terms
are available, torque and root (sec. 6, appendix A). With a contact schedule (issue 11,
`solver.contacts.Contact`s: site, start, end, surface): planted (feet on their surface and not sliding
during a contact), clearance (swing feet keep 2 cm, every site min(2 cm, g T^2/8) in a flight of length T)
- both on by default - and cone
(the root wrench inside the friction cone of the feet in contact; needs the inverse dynamics, "all").
"""
from __future__ import annotations

import numpy as np

from solver.errors import InputError
from solver.figure import Figure
from solver.kinematic_tree import SiteKinematics
from solver.layout import StateLayout
from solver.objective import Objective
from solver.terms import CovariantAcceleration, Hyperextension, Penetration, UnitQuaternion

#: The terms used when none are chosen: the geometric terms of the paper's sec. 5.
DEFAULT_TERMS = ("penetration", "unit", "bending", "smooth")

#: Weight of each term when it is switched on without one (all renormalized, eq. 7, so each starts
#: at its weight). torque and root at 1: on run-and-step (`--terms all`) that keeps every bound of the
#: main job and gives RMS root force in flight 20 N against the plain spline's 625 N, RMS joint torque
#: 80 N m against 103 N m; 0.1 each also meets the acceptance figures but keeps less of the gain
#: (74 N, 93 N m) and lets the flight grow to 0.49 s (plain spline 0.25 s).
#: planted and clearance at 10: on run-and-step (127_33, its own contacts) weight 1 with 5 mm rest height
#: floated planted feet 7.6 mm (capture 2.4) and raised the joint-orientation error to 13.1 deg (plain
#: 10.2); weight 10 with the 2 mm contact margin: float 3.5 mm, joint error 10.7 deg (README "Contacts").
DEFAULT_WEIGHTS = {"penetration": 1.0, "unit": 1.0, "bending": 1.0, "smooth": 0.05, "torque": 1.0, "root": 1.0,
                   "planted": 10.0, "clearance": 10.0, "cone": 1.0}

#: The contact terms: they need a contact schedule. planted and clearance join the defaults when one is
#: known; cone (inverse dynamics) joins "all".
CONTACT_TERMS = ("planted", "clearance", "cone")
DEFAULT_CONTACT_TERMS = ("planted", "clearance")

#: Penalty-continuation bounds (`SolveOptions.limits`), in each term's `violation` unit, set inside the
#: acceptance bounds (penetration <= 1 mm, hyperextension <= 2 deg, |1 - |q|| <= 5 %) with headroom.
DEFAULT_LIMITS = {"penetration": 0.0005, "bending": float(np.radians(1.0)), "unit": 0.03,
                  # planted: max(|h - h0|, tau |v_t|) where a contact is fully on [m] (tau = 0.1 s: 2 cm
                  # or 20 cm/s); clearance: intrusion into the band (2 cm in swing cores, the lifted c_f in flights) [m].
                  # Peaks, so looser than the acceptance means (float <= 5 mm): with 1 cm / 5 mm the
                  # run-and-step solve still missed planted after 3 boosts (41 -> 25 -> 12 mm)
                  "planted": 0.02, "clearance": 0.01}


def _dynamics_terms():
    try:
        from solver.terms import dynamics  # noqa: F401
    except ImportError:
        return {}
    return {"torque": dynamics.JointTorque, "root": dynamics.RootResidual}


def term_names() -> list[str]:
    """Every term name this installation offers (the contact terms need a contact schedule; cone also
    the inverse dynamics)."""
    dyn = list(_dynamics_terms())
    cone = ["cone"] if dyn else []
    return ["penetration", "unit", "bending", "smooth", *dyn, "planted", "clearance", *cone]


def _needs_schedule(name: str) -> InputError:
    return InputError(f"objective term {name!r} needs a contact schedule (which site touches which surface "
                      "when): give the keyframe file a 'contacts' list (dynsplines mocap writes one) or pass "
                      "contacts=; or leave the term out")


#: Whether a contact schedule switches the contact terms on by default (planted and clearance; cone
#: joins "all"). On: with variable frames at every touch-down and lift-off (`SolveOptions.term_knots`),
#: the penetration weight CONTACT_PENETRATION_WEIGHT and the kinematics-only engine (`SiteKinematics`)
#: the solve with them takes 0.58-1.63x the evaluations and 1.05-2.62x the CPU time of the solve
#: without on the four inputs of README "Feet that plant" (run-and-step: 257 vs 336 evaluations; without
#: the frames 1633, penalty continuation boosting the penetration term four times because a spline with
#: one frame per keyframe interval cannot both hold a foot still and keep the other sites up).
CONTACT_TERMS_BY_DEFAULT = True

#: The penetration term's weight with the planted term on (DEFAULT_WEIGHTS' 1 otherwise). The weights
#: are renormalized by the plain spline's integrals (eq. 7), and the plain spline's feet go 10 cm into
#: the floor or a step, so at weight 1 a planted foot held at the surface buys mm of depth for almost
#: nothing: penalty continuation then boosted the weight to 100 in two extra rounds (run-and-step: 485
#: evaluations; starting at 100: 257, the same bounds).
CONTACT_PENETRATION_WEIGHT = 100.0


def parse_terms(spec: str | None, weights: dict[str, float] | None = None, contacts=()) -> dict[str, float]:
    """Term weights from a command-line list ("all", or "penetration,unit,...") and overrides.

    Args:
        spec: None (the default terms; with a contact schedule also planted and clearance), "all"
            (every term; the contact terms, cone included, only with a schedule), or a comma-separated
            list of term names (the contact terms need a schedule; leave them out of the list to switch
            them off).
        weights: {name: weight} overrides (a name here also switches the term on).
        contacts: the contact schedule, if any (only whether it is empty matters here).
    Returns:
        {name: weight >= 0}.
    Raises:
        InputError: unknown term (lists the valid ones), a contact term without a schedule, a weight
            that is not a number, negative or non-finite.
    """
    valid = term_names()
    have = bool(len(contacts or ()))
    if spec is None:
        chosen = {n: DEFAULT_WEIGHTS[n] for n in DEFAULT_TERMS}
        if have and CONTACT_TERMS_BY_DEFAULT:
            chosen.update({n: DEFAULT_WEIGHTS[n] for n in DEFAULT_CONTACT_TERMS})
    else:
        all_ = [n for n in valid if n not in CONTACT_TERMS or (have and CONTACT_TERMS_BY_DEFAULT)]
        names = all_ if spec.strip() == "all" else [s.strip() for s in spec.split(",") if s.strip()]
        chosen = {}
        for n in names:
            if n not in valid:
                raise InputError(f"unknown objective term {n!r}; valid terms: {', '.join(valid)} (or 'all')")
            if n in CONTACT_TERMS and not have:
                raise _needs_schedule(n)
            chosen[n] = DEFAULT_WEIGHTS.get(n, 1.0)
    if "planted" in chosen and "penetration" in chosen:
        chosen["penetration"] = CONTACT_PENETRATION_WEIGHT
    for n, w in (weights or {}).items():
        if n not in valid:
            raise InputError(f"unknown objective term {n!r} in a weight; valid terms: {', '.join(valid)}")
        if n in CONTACT_TERMS and not have:
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
                     margin: float | None = None, contacts=()) -> Objective:
    """The objective for a figure in a scene.

    Args:
        model: MjModel of the scene with the figure (loaded once by the caller).
        weights: {term name: lambda_j} from `parse_terms`.
        t0, t1: [s] the keyframe interval. rate: quadrature points per second.
        margin: [m] clearance the penetration term keeps from surfaces (and the rest height of a
            planted site, so that the two terms agree); default MARGIN, CONTACT_MARGIN with the planted
            term on.
        contacts: the contact schedule (objects with site, start, end, surface), for planted,
            clearance and cone.
    Returns:
        Objective (scales 1; `solve` renormalizes if asked).
    Raises:
        InputError: unknown term, a contact term without a schedule, a bad contact, or the scene lacks
            what a term needs (contact sites, surfaces).
    """
    layout = StateLayout.from_model(model)
    contacts = tuple(contacts or ())
    if margin is None:
        margin = CONTACT_MARGIN if contacts and weights.get("planted", 0) > 0 else MARGIN
    factories = {
        "penetration": lambda: Penetration(model, margin=margin),
        "unit": lambda: UnitQuaternion(layout.quat_slots),
        "bending": lambda: Hyperextension(layout, Figure.from_model(model).flexion_axes),
        "smooth": lambda: _named(CovariantAcceleration(layout.quat_slots, layout.linear_index), "smooth"),
    }
    for name in CONTACT_TERMS:
        if name in weights and not contacts:
            raise _needs_schedule(name)
    dyn = _dynamics_terms()
    engine = None
    if dyn and any(n in weights for n in ("torque", "root", *CONTACT_TERMS)):
        from solver.terms.dynamics import make_engine

        # one vectorized forward pass (site positions, velocities, inverse dynamics) at all points,
        # shared by every term that reads it, and one reverse pass for the sum of their gradients; the
        # kinematics alone (`SiteKinematics`, about half the cost) when no term reads the forces
        forces = any(n in weights for n in ("torque", "root", "cone"))
        engine = make_engine(model) if forces else SiteKinematics(model, Figure.from_model(model).contact_sites)
        factories["torque"] = lambda: dyn["torque"](model, engine=engine)  # (called only if forces)
        factories["root"] = lambda: dyn["root"](model, engine=engine)
        factories["penetration"] = lambda: Penetration(model, margin=margin, engine=engine)
    if contacts:
        from solver.terms.clearance import Clearance
        from solver.terms.contact import Planted

        span = (float(t0), float(t1))
        factories["planted"] = lambda: Planted(model, contacts, rest_height=margin, t_span=span, engine=engine)
        factories["clearance"] = lambda: Clearance(model, contacts, t_span=span, engine=engine)
        if engine is not None:
            from solver.terms.contact_wrench import FrictionCone

            factories["cone"] = lambda: FrictionCone(model, contacts, engine=engine, t_span=span)
    terms, w = [], []
    for name, weight in weights.items():
        if name not in factories:
            raise InputError(f"unknown objective term {name!r}; valid terms: {', '.join(factories)}")
        terms.append(factories[name]())
        w.append(weight)
    return Objective(terms, np.array(w), t0, t1, rate)


#: [s] `keyframe_conflicts` with a path: a swinging site is also checked this close to each keyframe
#: (the keyframe fixes the path there to within a few mm: 127_33's toe grazes the fitted step's edge
#: 1 mm up 6 ms after a keyframe, which no weight of the clearance term could lift 2 cm)
NEAR_KEYFRAME = (-0.01, -0.005, 0.005, 0.01)


def keyframe_conflicts(objective: Objective, times, qpos, path=None) -> list[tuple[str, int, str, float]]:
    """Keyframes that contradict the contact schedule, from the objective's planted and clearance terms
    (`Planted.conflicts`, `Planted.slides`, `Clearance.conflicts`); the contacts and swings concerned are left out of
    the terms' `violation` (keyframes are met exactly, so penalty continuation could not reach the
    bound there).

    Args:
        objective: from `figure_objective`. times: (k,) keyframe times [s]. qpos: (k, nq) keyframe
            poses (free components filled, e.g. `FrameSet.from_keyframes(...).values[is_keyframe]`).
        path: optional path(t) -> (n, nq) of the plain spline: then the clearance term is also checked
            NEAR_KEYFRAME around each keyframe (reported as that keyframe).
    Returns:
        [(kind, keyframe index, site, distance [m]), ...]: "planted": the site's height above its plant
        height; "sliding": two keyframes in one contact hold the site this far apart along the ground
        (`Planted.slides`); "clearance": how far inside the clearance band.
    """
    times, qpos = np.asarray(times, float), np.asarray(qpos, float)
    out = []
    for term in objective.terms:
        if term.name == "planted":
            out += [(term.name, *c) for c in term.conflicts(times, qpos, excuse=True)]
        if term.name == "clearance":
            term.lower_lifts(times, qpos)  # keyframes only: the plain spline near them is lower
            found = {(k, site): d for k, site, d in term.conflicts(times, qpos, excuse=True)}
            if path is not None:  # near a keyframe: more than half the bound inside the band
                near = (times[:, None] + np.asarray(NEAR_KEYFRAME)).ravel()
                owner = np.repeat(np.arange(len(times)), len(NEAR_KEYFRAME))
                keep = (near > times[0]) & (near < times[-1])
                for i, site, d in term.conflicts(near[keep], np.asarray(path(near[keep])), excuse=True,
                                                 tolerance=0.5 * DEFAULT_LIMITS["clearance"]):
                    key = (int(owner[keep][i]), site)
                    found[key] = max(found.get(key, 0.0), d)
            out += [("clearance", k, site, d) for (k, site), d in sorted(found.items())]
        if term.name == "planted":
            out += [("sliding", *c) for c in term.slides(times, qpos, excuse=True)]
    return out


def figure_problem(model, weights: dict[str, float], keyframes, rate: float = 400.0, contacts=()):
    """The objective and the plain spline's frames for keyframes of a figure, with the keyframes that
    contradict the contact schedule found and excused (`keyframe_conflicts`): what `solver.animate`,
    the command line and the benchmarks solve.

    Args:
        model: MjModel of the scene. weights: {term: lambda_j} (`parse_terms`). keyframes: Keyframes
            (values (k, nq), times (k,) [s]). rate: quadrature points per second. contacts: the schedule.
    Returns:
        (objective, initial, conflicts): Objective, FrameSet (the plain spline's frames), and the
        `keyframe_conflicts` list.
    Raises:
        InputError: as `figure_objective`.
    """
    from solver.frames import FrameSet

    layout = StateLayout.from_model(model)
    objective = figure_objective(model, weights, keyframes.times[0], keyframes.times[-1], rate=rate, contacts=contacts)
    initial = FrameSet.from_keyframes(keyframes, layout.quat_slots)
    conflicts = keyframe_conflicts(objective, keyframes.times, initial.values[initial.is_keyframe], path=initial.path)
    return objective, initial, conflicts


def default_limits(weights: dict[str, float]) -> tuple:
    """`SolveOptions.limits` for the chosen terms: ((name, tolerance), ...) from DEFAULT_LIMITS."""
    return tuple((n, DEFAULT_LIMITS[n]) for n in weights if n in DEFAULT_LIMITS and weights[n] > 0)


def _named(term, name):
    term.name = name
    return term
