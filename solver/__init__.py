"""dynsplines solver: dynamic splines with constraints (Ramamoorthi, Ball & Barr, Caltech).

The algorithm and the public Python API: the C2 natural cubic spline through keyframes and variable
frames, the objective terms with their gradients, the nlopt driver and Euler-Lagrange subdivision. No
rendering, no command line, no printing, and no process-wide side effects: importing it leaves
`os.environ` alone (the command line chooses the GL backend and the BLAS threads itself).

One call for a figure in a scene, one for a single orientation::

    import solver
    model = solver.load_model(solver.shipped("run_and_step.xml"))  # a shipped scene, from any folder
    keyframes, info = solver.read_keyframes(solver.shipped("run_and_step.keyframes.json"), model)
    solution = solver.animate(model, keyframes)            # the command line's settings
    result = solver.orient(times, quats)                   # paper sec. 3
"""
from solver.animate import animate, default_options, solve_problem
from solver.contact_schedule import ContactSchedule
from solver.contacts import Contact
from solver.errors import DynsplinesError, InputError
from solver.figure import Figure
from solver.frames import FrameSet
from solver.keyframe_file import KeyframeFileInfo, read_keyframes, write_keyframes
from solver.keyframes import Keyframes
from solver.layout import StateLayout
from solver.least_change import LeastChangeOptions
from solver.metrics import path_metrics
from solver.model import load_model
from solver.objective import Evaluation, NonFiniteError, Objective
from solver.optimize import OptimizeResult, Status
from solver.orient import OrientResult, orient
from solver.path_context import PathContext
from solver.problem import (
    DEFAULT_TERMS,
    DEFAULT_WEIGHTS,
    Problem,
    default_limits,
    figure_objective,
    make_problem,
    parse_terms,
    term_names,
)
from solver.schedule_conflicts import ScheduleConflicts
from solver.shipped import shipped
from solver.solve import Round, Solution, SolveOptions, solve
from solver.spline_basis import SplineBasis
from solver.terms import (
    CovariantAcceleration,
    Hyperextension,
    JointTorque,
    NormalizedCovariantAcceleration,
    Penetration,
    Residual,
    RootResidual,
    Term,
    TermEval,
    UnitQuaternion,
)
from solver.terms.registry import TermBuild, TermSpec, register_term, registered_terms, unregister_term

__all__ = [
    # errors
    "DynsplinesError", "InputError", "NonFiniteError",
    # inputs: keyframes, the figure's state layout, frames and the spline
    "Keyframes", "StateLayout", "FrameSet", "SplineBasis",
    # the figure read from its MJCF: bodies, joints, flexion axes, feet, segments, masses, height
    "Figure",
    # files: an MJCF scene, the JSON keyframe file
    "load_model", "read_keyframes", "write_keyframes", "KeyframeFileInfo",
    # the shipped figure, scenes, keyframe files and clips, from any folder
    "shipped",
    # the contact schedule (docs/contacts.md "Contact schedules") and what keyframes contradict in it
    "Contact", "ContactSchedule", "ScheduleConflicts",
    # objective terms (paper eq. 9, 12, sec. 5, sec. 6 / appendix A) and the objective (eq. 1, eq. 7)
    "Term", "TermEval", "Penetration", "UnitQuaternion", "Hyperextension", "CovariantAcceleration",
    "NormalizedCovariantAcceleration", "JointTorque", "RootResidual", "Residual", "PathContext",
    # the term registry: a new term is usable by name (`animate(..., terms=...)`, `--terms`) once registered
    "register_term", "unregister_term", "registered_terms", "TermBuild", "TermSpec",
    "Objective", "Evaluation", "figure_objective", "parse_terms", "term_names", "default_limits",
    "DEFAULT_TERMS", "DEFAULT_WEIGHTS",
    # solving (paper fig. 5)
    "SolveOptions", "Solution", "Round", "Status", "OptimizeResult", "solve",
    # a figure problem built once (`make_problem`) and solved (`solve_problem`), as the command line does
    "Problem", "make_problem", "solve_problem", "LeastChangeOptions",
    # one-call APIs
    "animate", "default_options", "orient", "OrientResult",
    # acceptance figures
    "path_metrics",
]
