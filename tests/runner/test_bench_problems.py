"""A benchmark that names a workload solves exactly the problem the command solves: the same keyframes,
contacts (the keyframe file's), flights, capture, constraint set and options."""
import numpy as np

import runner.commands.animate as animate_cmd
from runner.cli import main
from runner.commands.bench import run_and_step_problems


def command_problem(monkeypatch, *argv):
    """The Problem and SolveOptions `dynsplines ARGV` hands to the run."""
    seen = {}

    class Done:
        exit_code = 0

    def capture(problem, options, source, outputs, say=print):
        seen.update(problem=problem, options=options)
        return Done()

    monkeypatch.setattr(animate_cmd, "execute", capture)
    assert main([*argv, "--no-render", "--quiet"]) == 0
    return seen["problem"], seen["options"]


def test_bench_run_and_step_solves_the_commands_problem(monkeypatch):
    """Each configuration `bench run-and-step` times ("default", "all") is what `run-and-step --terms
    <it>` solves, with the same options."""
    from runner.animate_options import default_args, solve_options

    benched = run_and_step_problems()
    assert set(benched) == {"default", "all"}
    for name in ("default", "all"):
        problem, options = command_problem(monkeypatch, "run-and-step", "--terms", name)
        mine = benched[name]
        assert mine.forces == problem.forces == (name == "all") and mine.terms == problem.terms == name
        assert mine.contacts == problem.contacts and len(problem.contacts) > 0
        assert mine.airborne == problem.airborne
        np.testing.assert_array_equal(mine.keyframes.values, problem.keyframes.values)
        np.testing.assert_array_equal(mine.capture[1], problem.capture[1])
        assert options == solve_options(default_args())
