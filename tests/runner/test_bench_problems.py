"""A benchmark that names a workload solves exactly the problem the command solves: the same terms
(the keyframe file's contacts included), weights, limits and quadrature."""
import pytest

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


@pytest.mark.parametrize("terms", ["all", "penetration,unit,planted"])
def test_bench_run_and_step_solves_the_commands_problem(monkeypatch, terms):
    """Each configuration `bench run-and-step --terms TERMS` times ("geometric" and TERMS) is what
    `run-and-step --terms <its terms>` solves."""
    from runner.bench.figure import GEOMETRIC

    benched = run_and_step_problems(terms, 400.0)
    assert set(benched) == {"geometric", terms}
    for name, spec in (("geometric", GEOMETRIC), (terms, terms)):
        problem, _ = command_problem(monkeypatch, "run-and-step", "--terms", spec)
        mine = benched[name]
        assert mine.terms == problem.terms
        assert dict(mine.weights) == dict(problem.weights) and mine.limits == problem.limits
        assert mine.rate == problem.rate and mine.contacts == problem.contacts and len(problem.contacts) > 0
    # with the file's contacts: the contact terms and the friction cone are on with "all"
    assert {"planted", "clearance", "cone", "torque", "root"} <= set(benched[terms].terms) or terms != "all"
