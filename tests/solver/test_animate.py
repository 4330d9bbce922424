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
    for name in ("animate", "solve", "orient", "build_problem", "solve_problem"):
        assert callable(getattr(solver, name)), name


def test_default_options_are_the_command_lines():
    """The settings `dynsplines animate` uses without options (runner/animate_options.py: add_options and
    solve_options) are the library's LeastChangeOptions, field by field."""
    from runner.animate_options import default_args, solve_options

    assert solve_options(default_args()) == solver.LeastChangeOptions()


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


def test_animate_is_build_problem_then_solve_problem(toy):
    model, layout, kf = toy
    sol = solver.animate(model, kf, tol=0.5)
    ref = solver.solve_problem(solver.build_problem(model, solver.ProblemSpec(kf)), solver.LeastChangeOptions(tol=0.5))
    np.testing.assert_array_equal(sol.frames.times, ref.frames.times)
    np.testing.assert_array_equal(sol.frames.values, ref.frames.values)
    assert sol.frames.n_variable > 0 and sol.E_final >= 0.0
    np.testing.assert_array_equal(sol.frames.values[sol.frames.is_keyframe], kf.values)  # keyframes exactly


def test_animate_refuses_inputs_it_cannot_use(toy):
    model, _, kf = toy
    short = solver.Keyframes(kf.times, kf.values[:, :-1], kf.mask[:, :-1])
    with pytest.raises(InputError, match="22 qpos components but the model has nq = 23"):
        solver.animate(model, short)
    with pytest.raises(InputError, match="options must be a solver.LeastChangeOptions"):
        solver.animate(model, kf, options={"rounds": 1})
    with pytest.raises(InputError, match="rate must be > 0"):
        solver.animate(model, kf, options=solver.LeastChangeOptions(rate=0.0))
    with pytest.raises(InputError, match="keyframes must be a solver.Keyframes"):
        solver.animate(model, kf.values)
    with pytest.raises(InputError, match="spec must be a solver.ProblemSpec"):
        solver.build_problem(model, kf)


def test_animate_hands_the_capture_to_the_problem(toy, monkeypatch):
    """`capture=` reaches `build_problem` (where the no-jolt and force bounds read it), unchanged."""
    animate_module = sys.modules["solver.animate"]  # the module (solver.animate is the function)
    model, layout, kf = toy
    seen = {}
    real = animate_module.build_problem

    class Built(Exception):
        """The problem was built: the test needs no solve of it."""

    def spy(model_, spec):
        seen["spec"], seen["problem"] = spec, real(model_, spec)
        raise Built

    monkeypatch.setattr(animate_module, "build_problem", spy)
    capture = (np.linspace(0.0, 1.0, 21), np.tile(model.qpos0, (21, 1)))
    with pytest.raises(Built):
        solver.animate(model, kf, capture=capture, tol=0.5)
    assert seen["spec"].capture is capture and seen["problem"].capture is capture
