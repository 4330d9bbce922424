"""dynsplines solver: dynamic splines with constraints (Ramamoorthi, Ball & Barr, Caltech).

The algorithm and the public Python API: the C2 natural cubic spline through keyframes and variable
frames, the objective terms with their gradients, the nlopt driver and Euler-Lagrange subdivision. No
rendering, no command line, no printing, and no process-wide side effects: importing it leaves
`os.environ` alone (the command line chooses the GL backend and the BLAS threads itself).

One call for a figure in a scene, one for a single orientation::

    import solver
    model = solver.load_model(solver.shipped("run_and_step.xml"))  # a shipped scene, from any folder
    keyframes, info = solver.read_keyframes(solver.shipped("run_and_step.keyframes.json"), model)
    solution = solver.animate(model, keyframes, contacts=info.contacts)  # the command line's settings
    result = solver.orient(times, quats)                   # paper sec. 3
"""
from solver.animate import animate, solve_problem
from solver.constraints.base import Constraint
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
from solver.paper.orient import OrientResult, orient
from solver.paper.solve import Round, Solution, SolveOptions, solve
from solver.path_context import PathContext
from solver.problem import Problem, ProblemSpec, build_problem
from solver.shipped import shipped
from solver.spline_basis import SplineBasis
from solver.terms import (
    CovariantAcceleration,
    Hyperextension,
    JointTorque,
    NormalizedCovariantAcceleration,
    Penetration,
    RootResidual,
    Term,
    TermEval,
    UnitQuaternion,
)

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
    # the contact schedule (docs/contacts.md "Contact schedules")
    "Contact", "ContactSchedule",
    # objective terms (paper eq. 9, 12, sec. 5, sec. 6 / appendix A) and the objective (eq. 1, eq. 7) of
    # the orientation problem (sec. 3) and of `solve`
    "Term", "TermEval", "Penetration", "UnitQuaternion", "Hyperextension", "CovariantAcceleration",
    "NormalizedCovariantAcceleration", "JointTorque", "RootResidual", "PathContext",
    "Objective", "Evaluation",
    # solving a weighted objective (paper fig. 5)
    "SolveOptions", "Solution", "Round", "Status", "OptimizeResult", "solve",
    # a figure problem built once from its spec (`build_problem`) and solved (`solve_problem`): the least
    # change to the plain spline that meets the constraints, as the command line does
    "Problem", "ProblemSpec", "build_problem", "solve_problem", "LeastChangeOptions",
    # a constraint: the figure's own, or one of yours (`ProblemSpec.bounds`, docs/design.md)
    "Constraint",
    # one-call APIs
    "animate", "orient", "OrientResult",
    # acceptance figures
    "path_metrics",
]
