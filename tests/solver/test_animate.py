"""The public API (solver/__init__.py) and the one-call figure API (solver/animate.py)."""
import json
import os
import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest

import solver
from solver.animate import DEFAULT_TOL
from solver.errors import InputError

from conftest import TOY_SCENE

REPO = Path(__file__).resolve().parents[2]


def test_import_leaves_the_environment_unchanged():
    """Importing the library sets no GL backend and no BLAS threads (the command line does, itself)."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "DISPLAY", "WAYLAND_DISPLAY", "OPENBLAS_NUM_THREADS",
                        "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    code = ("import json, os; before = dict(os.environ); import solver, solver.animate; after = dict(os.environ); "
            "print(json.dumps({k: [before.get(k), after.get(k)] for k in set(before) | set(after) "
            "if before.get(k) != after.get(k)}))")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True, timeout=120,
                         check=False)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout.strip().splitlines()[-1]) == {}


def test_every_public_name_exists_once():
    assert len(solver.__all__) == len(set(solver.__all__))
    missing = [name for name in solver.__all__ if not hasattr(solver, name)]
    assert missing == []
    for name in ("animate", "solve", "orient", "default_options", "figure_objective", "parse_terms"):
        assert callable(getattr(solver, name)), name


def test_default_options_are_the_command_lines():
    """The settings `dynsplines animate` uses without options (runner/animate_options.py: add_options and
    solve_options), field by field: the least change by default, the penalty method's with --method penalty."""
    from runner.animate_options import default_args, solve_options

    assert solve_options(default_args(), solver.parse_terms(None)) == solver.LeastChangeOptions()
    for weights in (solver.parse_terms(None), {"unit": 1.0, "smooth": 0.05, "penetration": 0.0}):
        assert solver.default_options(weights) == solve_options(default_args("penalty"), weights)
    opts = solver.default_options({"penetration": 1.0, "unit": 1.0, "bending": 1.0, "smooth": 0.05})
    assert (opts.subdivision, opts.per_segment, opts.score) == ("adaptive", 1, "decrease")
    assert (opts.refine, opts.tol, opts.rounds) == ("tol", DEFAULT_TOL, None)
    assert (opts.algorithm, opts.ftol_rel, opts.precondition, opts.renormalize) == ("lbfgs", 1e-6, True, True)
    assert (opts.max_evals, opts.max_time_s, opts.boost, opts.max_boosts) == (0, 0.0, 10.0, 4)
    assert dict(opts.limits) == {"penetration": 0.0005, "unit": 0.03, "bending": pytest.approx(np.pi / 180)}
    assert solver.default_options({"smooth": 1.0, "penetration": 0.0}).limits == ()  # off: no limit
    with pytest.raises(InputError, match="weights must be a dict"):
        solver.default_options(["unit"])


@pytest.fixture(scope="module")
def toy():
    """The toy figure of conftest with three full keyframes: a step forward, a hip and a knee turning."""
    model = mujoco.MjModel.from_xml_string(TOY_SCENE)
    layout = solver.StateLayout.from_model(model)
    V = np.zeros((3, model.nq))
    V[:, 0], V[:, 2] = [0.0, 0.5, 1.0], [1.0, 1.1, 1.0]
    V[:, layout.quat_slots[:, 0]] = 1.0
    V[1, layout.quat_slots[1]] = [np.cos(0.3), np.sin(0.3), 0, 0]
    V[2, layout.quat_slots[3]] = [np.cos(0.4), 0, np.sin(0.4), 0]
    return model, layout, solver.Keyframes(np.array([0.0, 0.4, 1.0]), V, np.ones_like(V, bool))


def test_animate_is_solve_on_the_figure_objective_with_the_default_options(toy):
    model, layout, kf = toy
    sol = solver.animate(model, kf, ["unit", "smooth"], {"smooth": 0.1})
    weights = {"unit": 1.0, "smooth": 0.1}
    objective = solver.figure_objective(model, weights, 0.0, 1.0, rate=400.0)
    ref = solver.solve(objective, solver.FrameSet.from_keyframes(kf, layout.quat_slots),
                       solver.default_options(weights))
    np.testing.assert_array_equal(sol.frames.times, ref.frames.times)
    np.testing.assert_array_equal(sol.frames.values, ref.frames.values)
    assert sol.weights == weights and sol.status is solver.Status.CONVERGED
    assert sol.frames.n_variable > 0 and sol.E_final < sol.E_initial
    np.testing.assert_array_equal(sol.frames.values[sol.frames.is_keyframe], kf.values)  # keyframes exactly


def test_animate_refuses_inputs_it_cannot_use(toy):
    model, _, kf = toy
    short = solver.Keyframes(kf.times, kf.values[:, :-1], kf.mask[:, :-1])
    with pytest.raises(InputError, match="22 qpos components but the model has nq = 23"):
        solver.animate(model, short)
    with pytest.raises(InputError, match="unknown objective term 'jerk'; valid terms: penetration"):
        solver.animate(model, kf, "unit,jerk")
    with pytest.raises(InputError, match="options must be a SolveOptions"):
        solver.animate(model, kf, "unit", options={"rounds": 1})
    with pytest.raises(InputError, match="rate must be > 0"):
        solver.animate(model, kf, "unit", rate=0.0)
    with pytest.raises(InputError, match="keyframes must be a solver.Keyframes"):
        solver.animate(model, kf.values)


def test_animate_hands_the_capture_to_the_problem(toy, monkeypatch):
    """`capture=` reaches `make_problem` (where the forces term's bounds read it), unchanged."""
    animate_module = sys.modules["solver.animate"]  # the module (solver.animate is the function)
    model, layout, kf = toy
    seen = {}
    real = animate_module.make_problem

    def spy(*args, **kwargs):
        seen.update(kwargs)
        return real(*args, **kwargs)

    monkeypatch.setattr(animate_module, "make_problem", spy)
    capture = (np.linspace(0.0, 1.0, 5), np.tile(model.qpos0, (5, 1)))
    solver.animate(model, kf, "unit", options=solver.default_options({"unit": 1.0}), capture=capture, tol=0.5)
    assert seen["capture"] is capture
