"""`dynsplines bench speed`'s pure parts: the ratio table from given runs, and a clear error for a revision
git does not know (timing itself is measured by the command, never asserted)."""
import pytest

from runner.commands.bench_speed import WORKLOADS, baseline_worktree, ratio_rows, same_commit
from solver.errors import InputError


def _run(solve, cpu=None, mb=100.0, evals=None):
    return {"solve_s": solve, "cpu_s": solve + 1.0 if cpu is None else cpu, "wall_s": solve + 2.0, "peak_mb": mb,
            "evals": evals}


def test_ratio_rows_are_medians_and_per_run_ratios():
    name = WORKLOADS[0].name
    runs = {(name, "baseline"): [_run(20.0), _run(18.0), _run(22.0)],
            (name, "current"): [_run(4.0), _run(3.0), _run(5.5, mb=250.0)]}
    (row,) = ratio_rows(runs)
    assert row[0] == name and row[1] == 20.0 and row[2] == 4.0  # medians of (20, 18, 22) and (4, 3, 5.5)
    assert row[3] == pytest.approx(0.2) and row[4] == pytest.approx([0.2, 3.0 / 18.0, 5.5 / 22.0])
    assert row[5] == WORKLOADS[0].bound and row[9] == 250.0  # the larger peak of the current runs
    assert ratio_rows({(name, "baseline"): [_run(1.0)]}) == []  # no current runs: no row
    assert ratio_rows(runs, bounded=set())[0].bound is None  # runs against another revision: no bound
    assert row.per_eval_ratio is None and row.base_evals is None  # runs that record no evaluations


def test_the_time_per_evaluation_separates_cost_from_the_count():
    """Twice the evaluations in twice the time: the solve is 2x, each evaluation costs the same (1.0)."""
    name = WORKLOADS[0].name
    runs = {(name, "baseline"): [_run(1.0, evals=100), _run(1.2, evals=100), _run(0.9, evals=100)],
            (name, "current"): [_run(2.0, evals=200), _run(2.4, evals=200), _run(1.8, evals=200)]}
    (row,) = ratio_rows(runs)
    assert row.ratio == pytest.approx(2.0)
    assert (row.base_evals, row.current_evals) == (100.0, 200.0)
    assert row.per_eval_ratio == pytest.approx(1.0)
    runs[(name, "current")][1]["evals"] = None  # one run without a count: no per-evaluation figure
    assert ratio_rows(runs)[0].per_eval_ratio is None


def test_each_bound_has_its_own_baseline_and_revisions_compare_as_commits():
    """mocap-corpus's bound is issue 60's, against b590890; the others are issue 40's, against 7624574. A
    revision compares as the commit it names (a full hash and its abbreviation agree; an unknown one names none)."""
    import subprocess

    from runner.paths import REPO

    against = {w.name: w.against for w in WORKLOADS}
    assert against["mocap-corpus"] == "b590890" and against["mocap-default"] == "7624574"
    head = subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True).stdout.strip()
    if not head:
        pytest.skip("not a git checkout")
    assert same_commit(head, head[:12]) and same_commit("HEAD", head)
    assert not same_commit("no-such-rev", "no-such-rev")


def test_an_unknown_revision_is_one_clear_error(tmp_path):
    with pytest.raises(InputError, match="--baseline no-such-rev"):
        baseline_worktree("no-such-rev", tmp_path / "b")


def test_the_tuning_corpus_sums_its_pairs(tmp_path):
    """The corpus workload's figures are the sums over the pairs' metrics files; a run without one is an error."""
    import json

    from runner.commands.bench_speed import corpus_sums

    for pair, t, n in (("a.every0.2", 1.5, 100), ("a.contacts", 2.25, 300), ("b.every0.2", 0.25, 7)):
        (tmp_path / pair).mkdir()
        (tmp_path / pair / f"{pair.split('.')[0]}.metrics.json").write_text(json.dumps({"solve_time_s": t, "n_evals": n}))
    assert corpus_sums(tmp_path) == (pytest.approx(4.0), 407)
    with pytest.raises(RuntimeError, match="no pair"):
        corpus_sums(tmp_path / "a.every0.2" / "nothing")
