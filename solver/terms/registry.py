"""The term registry: every objective term's name, factory, default weight and what it needs.

`solver.problem` builds the figure's objective from names (`parse_terms`, `figure_objective`), and the
command line lists and accepts exactly the registered names (`--terms`, `term_names()`). A new term is
a `Term` subclass in a module of its own plus one call:

    register_term("toy", lambda build: ToyTerm(build.layout), default_weight=1.0)

after which `solver.animate(..., terms="toy,...")` and `dynsplines animate ... --terms toy,...` use it.
A factory receives a `TermBuild` (the model, its layout, the keyframe interval, the contact schedule
and the shared engine) and returns the term; the term's `name` must be the registered one.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from solver.errors import InputError
from solver.layout import StateLayout
from solver.terms.base import Term

#: Weight of each built-in term when it is switched on without one (all renormalized, eq. 7, so each
#: starts at its weight). torque and root at 1: on run-and-step (`--terms all`) that keeps every bound of
#: the default run and gives RMS root force in flight 20 N against the plain spline's 625 N, RMS joint
#: torque 80 N m against 103 N m; 0.1 each also meets the acceptance figures but keeps less of the gain
#: (74 N, 93 N m) and lets the flight grow to 0.49 s (plain spline 0.25 s).
#: planted and clearance at 10: on run-and-step (127_33, its own contacts) weight 1 with 5 mm rest height
#: floated planted feet 7.6 mm (capture 2.4) and raised the joint-orientation error to 13.1 deg (plain
#: 10.2); weight 10 with the 2 mm contact margin: float 3.5 mm, joint error 10.7 deg (docs/contacts.md "The contact terms").
#: hinge and rom at 100: zero on the plain spline (they allow what it shows), so not renormalized (eq. 7);
#: at 10 the tuning clips (run-and-step, 127_33, 16_23, 35_17 keyed every 0.25 s) needed a penalty boost
#: and 14-50 % more evaluations; at 100 none did, at 4 % more evaluations than without the terms
#: (docs/anatomy.md).
#: forces: zero on the plain spline (its bounds allow the plain spline's peaks), so not renormalized:
#: the weight is in 1 / (body weight^2 s) (docs/dynamics.md). Chosen on two tuning clips with --terms all
#: (run-and-step; 35_17 keyed every 0.25 s): at 1000 both end within both bounds after one or two boosts;
#: at 10^4 and 10^5 run-and-step also needed boosts of penetration and clearance, and more evaluations.
FORCES_WEIGHT = 1000.0
#: near: the departure from the plain spline (`solver.terms.near`), zero on the plain spline; without a
#: contact schedule its weight prices one rad^2 of mean squared departure summed over the joints, with one
#: it and near_sites (`solver.terms.near_sites`) take the planted term's eq. 7 scale, so weight 1 prices a
#: departure at a tenth of an equal planted violation (docs/corpus.md "Near the plain spline": chosen on
#: the tuning clips).
DEFAULT_WEIGHTS = {"penetration": 1.0, "unit": 1.0, "bending": 1.0, "smooth": 0.05, "torque": 1.0, "root": 1.0,
                   "planted": 10.0, "clearance": 10.0, "cone": 1.0, "hinge": 100.0, "rom": 100.0, "near": 1.0, "near_sites": 1.0,
                   "forces": FORCES_WEIGHT}
#: Penalty-continuation bounds of the anatomical terms [rad] (their `TermSpec.limit`): rotation off the
#: hinge beyond the allowance (acceptance: the capture's + 3 deg; the allowance is 2 deg) and angle
#: beyond the range of motion (docs/anatomy.md).
ANATOMY_LIMITS = {"hinge": float(np.radians(0.5)), "rom": float(np.radians(1.0))}
#: Penalty-continuation bound of the forces term: excess over its bounds in body weights (the
#: acceleration's in g): 1 % of body weight (7 N for 70 kg), 0.1 m/s^2, within the summary's mark
#: (over the bound by 1 % and the printed digit).
FORCES_LIMIT = 0.01


class TermBuild:
    """What a term factory is given to build its term for one objective.

    Attributes:
        model: MjModel of the scene (figure + static surfaces; not to be modified).
        layout: its StateLayout. figure: its `solver.figure.Figure` (contact sites, flexion axes, ...). t_span: (t0, t1) [s] the keyframe interval.
        margin: [m] the penetration margin (also a planted site's rest height, `solver.problem.MARGIN`).
        contacts: the contact schedule (a `ContactSchedule`, or a tuple of objects with site, start, end,
            surface; may be empty).
        forces: True if a chosen term reads the inverse dynamics (then `engine` computes forces).
        conflicts: what keyframes contradict in the schedule (`solver.problem.keyframe_conflicts`, a
            `ScheduleConflicts`), for the contact terms to leave out of their bounds; None: nothing.
        plain: the plain spline through the keyframes (a `FrameSet`), or None: the anatomical terms
            allow what it shows (`plain_samples`; docs/anatomy.md).
        peaks: the problem's `PeakBounds` for the forces term (`solver.peak_bounds`), or None.
        airborne: ((start, end), ...) [s] where the capture the keyframes came from flies (every site
            above the flight height), for the clearance term's flights; None: no capture.
    """

    def __init__(self, model, t_span, margin: float, contacts, forces: bool, conflicts=None, plain=None,
                 peaks=None, airborne=None):
        from solver.figure import Figure

        self.model, self.layout, self.figure = model, StateLayout.from_model(model), Figure.from_model(model)
        self.t_span, self.margin, self.contacts, self.forces = t_span, float(margin), contacts, forces
        self.conflicts, self.plain, self._peaks, self.airborne = conflicts, plain, peaks, airborne
        self._engine = None
        self._plain_samples = None

    @property
    def plain_samples(self) -> np.ndarray | None:
        """(n, nq) the plain spline (`plain`) sampled at `solver.terms.anatomy.PLAIN_RATE` with its
        keyframes' times, computed on first use; None without a plain spline."""
        if self.plain is None:
            return None
        if self._plain_samples is None:
            from solver.terms.anatomy import plain_samples

            self._plain_samples = plain_samples(self.plain)
        return self._plain_samples

    @property
    def force_bounds(self):
        """The forces term's `PeakBounds` (`solver.problem.figure_objective` computes them from the plain
        spline when it is given and no bounds are), or None: the term then reads them on the path the
        solve starts from (`PeakForces.prepare`)."""
        return self._peaks

    @property
    def engine(self):
        """The engine every kinematic and dynamic term of the objective shares (created on first use):
        the inverse dynamics tracking the contact sites if a chosen term reads forces, else the
        sites' kinematics alone (`solver.path_context.site_engine`, about half the cost)."""
        if self._engine is None:
            if self.forces:
                from solver.terms.dynamics import make_engine

                self._engine = make_engine(self.model)
            else:
                from solver.path_context import site_engine

                self._engine = site_engine(self.model, self.figure.contact_sites, velocities=False)
        return self._engine


@dataclass(frozen=True)
class TermSpec:
    """A registered term.

    Attributes:
        name: the command-line name. factory: TermBuild -> Term. default_weight: lambda_j when the term
        is switched on without a weight (>= 0). contacts: needs a contact schedule. forces: reads the
        inverse dynamics. default: on when no terms are chosen (contact terms: when a schedule is
        known). limit: the penalty-continuation bound in the term's `violation` unit, or None (the
        built-ins' are `solver.problem.DEFAULT_LIMITS`).
    """

    name: str
    factory: Callable[[TermBuild], Term]
    default_weight: float = 1.0
    contacts: bool = False
    forces: bool = False
    default: bool = False
    limit: float | None = None


_REGISTRY: dict[str, TermSpec] = {}


def register_term(name: str, factory: Callable[[TermBuild], Term], default_weight: float = 1.0, *,
                  contacts: bool = False, forces: bool = False, default: bool = False,
                  limit: float | None = None, replace: bool = False) -> TermSpec:
    """Register an objective term under `name` (see `TermSpec` for the fields).

    Returns:
        the TermSpec.
    Raises:
        InputError: a name that is empty, has a comma or space, or is taken (unless replace=True), a
            factory that is not callable, a default weight or limit that is negative or not finite.
    """
    if not isinstance(name, str) or not name or any(c in name for c in ", \t") or name == "all":
        raise InputError(f"term name {name!r} must be a non-empty word without commas or spaces (and not 'all')")
    if name in _REGISTRY and not replace:
        raise InputError(f"objective term {name!r} is already registered; pass replace=True to replace it")
    if not callable(factory):
        raise InputError(f"the factory of term {name!r} must be callable (TermBuild -> Term)")
    w = float(default_weight)
    if not np.isfinite(w) or w < 0:
        raise InputError(f"default weight of term {name!r} is {default_weight}; it must be finite and >= 0")
    if limit is not None and not (np.isfinite(float(limit)) and float(limit) >= 0):
        raise InputError(f"limit of term {name!r} is {limit}; it must be finite and >= 0 (or None)")
    spec = TermSpec(name, factory, w, bool(contacts), bool(forces), bool(default),
                    None if limit is None else float(limit))
    _REGISTRY[name] = spec
    return spec


def unregister_term(name: str) -> None:
    """Remove a registered term (tests; a no-op for an unknown name)."""
    _REGISTRY.pop(name, None)


def registered_terms() -> tuple[TermSpec, ...]:
    """Every registered term, in registration order (the built-ins first)."""
    return tuple(_REGISTRY.values())


def term_spec(name: str) -> TermSpec:
    """The registered term `name`.

    Raises:
        InputError: an unknown name (lists the registered ones).
    """
    spec = _REGISTRY.get(name)
    if spec is None:
        raise InputError(f"unknown objective term {name!r}; valid terms: {', '.join(_REGISTRY)}")
    return spec


def build_term(spec: TermSpec, build: TermBuild) -> Term:
    """The factory's term for one objective, checked: a `Term` named as registered.

    Raises:
        InputError: the factory returned something else.
    """
    term = spec.factory(build)
    if not isinstance(term, Term) or term.name != spec.name:
        raise InputError(f"the factory of objective term {spec.name!r} returned "
                         f"{type(term).__name__} named {getattr(term, 'name', None)!r}; it must return a Term "
                         f"whose name is {spec.name!r}")
    return term


def _near(b: TermBuild):
    """The near term (`solver.terms.near.NearPlain`) toward the plain spline `b.plain`, with the
    root's length scale from the figure (`reference_length`). A build without the plain spline (an
    objective made without keyframes) gets a term without a reference, which is zero. Priced like planted
    with a contact schedule, but not beside the inverse-dynamics terms: those ask the path to leave the
    plain spline wherever it needs a hand of god (in flight), so there near keeps its absolute weight."""
    from solver.terms.near import NearPlain, reference_length

    return NearPlain(b.layout, None if b.plain is None else b.plain.path, b.t_span, length=reference_length(b.figure),
                     renormalize_like="planted" if len(b.contacts) and not b.forces else None)


def _near_sites(b: TermBuild):
    """The near_sites term (`solver.terms.near_sites.NearSites`): the contact sites toward the plain
    spline `b.plain`'s, on the engine shared with the contact terms, scaled like planted (eq. 7); beside
    the inverse-dynamics terms an absolute weight per m^2 instead, as `_near` says why."""
    from solver.terms.near_sites import NearSites

    return NearSites(b.model, None if b.plain is None else b.plain.path, engine=b.engine,
                     renormalize_like=None if b.forces else "planted")


def _register_builtins() -> None:
    """The figure's terms: sec. 5 (penetration, unit, bending, smooth, and the anatomical limits hinge and
    rom: docs/anatomy.md), sec. 6 (torque, root, and forces: the peaks
    they may ask of the body, docs/dynamics.md) and the contact terms (planted, clearance, cone;
    docs/contacts.md "The contact terms")."""
    from solver.terms.anatomy import Hinge, RangeOfMotion
    from solver.terms.bending import Hyperextension
    from solver.terms.clearance import Clearance
    from solver.terms.contact import Planted
    from solver.terms.contact_wrench import FrictionCone
    from solver.terms.covariant import CovariantAcceleration
    from solver.terms.dynamics import JointTorque, RootResidual
    from solver.terms.force_bounds import PeakForces
    from solver.terms.penetration import Penetration
    from solver.terms.unit import UnitQuaternion

    def smooth(b):
        term = CovariantAcceleration(b.layout.quat_slots, b.layout.linear_index)
        term.name = "smooth"  # the figure's name for the covariant acceleration with the root's linear part
        return term

    w = DEFAULT_WEIGHTS
    register_term("penetration", lambda b: Penetration(b.model, margin=b.margin, engine=b.engine),
                  w["penetration"], default=True)
    register_term("unit", lambda b: UnitQuaternion(b.layout.quat_slots), w["unit"], default=True)
    register_term("bending", lambda b: Hyperextension(b.layout, b.figure.flexion_axes), w["bending"], default=True)
    register_term("smooth", smooth, w["smooth"], default=True)
    register_term("hinge", lambda b: Hinge(b.layout, b.figure.flexion_axes, reference=b.plain_samples), w["hinge"],
                  default=True, limit=ANATOMY_LIMITS["hinge"])
    register_term("rom", lambda b: RangeOfMotion(b.layout, b.figure, reference=b.plain_samples), w["rom"],
                  default=True, limit=ANATOMY_LIMITS["rom"])
    register_term("near", _near, w["near"], default=True)
    register_term("torque", lambda b: JointTorque(b.model, engine=b.engine), w["torque"], forces=True)
    register_term("root", lambda b: RootResidual(b.model, engine=b.engine), w["root"], forces=True)
    register_term("forces", lambda b: PeakForces(b.model, b.force_bounds, engine=b.engine, t_span=b.t_span),
                  w["forces"], forces=True, limit=FORCES_LIMIT)
    register_term("planted", lambda b: Planted(b.model, b.contacts, rest_height=b.margin, t_span=b.t_span,
                                               engine=b.engine, conflicts=b.conflicts),
                  w["planted"], contacts=True, default=True)
    register_term("clearance", lambda b: Clearance(b.model, b.contacts, t_span=b.t_span, engine=b.engine,
                                                   conflicts=b.conflicts, airborne=b.airborne),
                  w["clearance"], contacts=True, default=True)
    register_term("near_sites", _near_sites, w["near_sites"], contacts=True, default=True)
    register_term("cone", lambda b: FrictionCone(b.model, b.contacts, engine=b.engine, t_span=b.t_span),
                  w["cone"], contacts=True, forces=True)


_register_builtins()
