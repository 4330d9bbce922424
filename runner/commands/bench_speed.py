"""`dynsplines bench speed`: the command line's solves against a baseline commit, side by side.

Each workload runs as the user would run it (a fresh `python -m runner` process, `--no-render`), in a
temporary worktree of the baseline revision (each workload's own, the one its bound is set against:
`Workload.against`; or the one --baseline names, whose ratios then carry no verdict) and in this checkout, alternately (baseline, current,
baseline, ...: load drift on a shared machine hits both), `--repeat` times each. Per run: the solve's
time as the run records it (`solve_time_s` of `--metrics`, or of the saved path), and the whole
process's CPU time and peak memory (`resource.getrusage` of the child). The table gives medians, the
ratio current / baseline of each, and the bound the issue set for it; where the runs record their
evaluations (`mocap`'s metrics), their medians and the ratio of the solve time per evaluation, which
separates what an evaluation costs from how many of them round-off sends a solve through. The
`mocap-corpus` workload solves the 60 (clip, keying) pairs of the shipped corpus in one `bench corpus`
process and sums their solve times and evaluations: one solve's count moves by about 20 % with round-off
(docs/benchmarks.md), a sum over many pairs far less.
"""
from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from runner.paths import REPO
from solver.errors import InputError

#: the commit before the least change (issue 40's "today")
BASELINE = "7624574"
#: the commit issue 60 was measured on (its "no slower than today's")
CERTIFICATE_BASELINE = "b590890"


@dataclass(frozen=True)
class Workload:
    """One command line to time: its arguments after `python -m runner`, the bound on its ratio and the
    revision the bound is set against (`against`: the baseline a run without --baseline compares with; a run
    against another revision prints the ratio without a verdict)."""

    name: str
    args: tuple
    bound: float
    against: str = BASELINE
    #: run without --only (the corpus, minutes a run, only when named)
    default: bool = True


WORKLOADS = (
    Workload("mocap-default", ("mocap", "models/cmu/127_33.bvh", "--every", "0.25"), 0.25),
    Workload("run-and-step-all", ("run-and-step", "--terms", "all"), 0.5),
    Workload("mocap-corpus", ("bench", "corpus", "--workers", "1"), 1.0, CERTIFICATE_BASELINE, default=False),
)


def register(bsub) -> None:
    """Add `bench speed` to the `dynsplines bench` subparsers."""
    c = bsub.add_parser("speed", help="the command line's solves against a baseline commit, side by side",
                        description=__doc__.split("\n\n")[1].replace("\n", " "))
    c.add_argument("--baseline", default=None, help="the revision to compare with [each workload's own: "
                   + ", ".join(f"{w.name} {w.against}" for w in WORKLOADS) + "]")
    c.add_argument("--repeat", type=int, default=3, help="runs of each workload in each checkout [3]")
    c.add_argument("--only", default=None, help=f"comma-separated workloads of {','.join(w.name for w in WORKLOADS)} "
                   f"[{','.join(w.name for w in WORKLOADS if w.default)}]")
    c.set_defaults(func=bench_speed)


def baseline_worktree(revision: str, where: Path) -> Path:
    """A detached git worktree of `revision` at `where`; raises InputError naming the revision."""
    if not (REPO / ".git").exists():
        raise InputError(f"{REPO} is not a git checkout; bench speed needs one to check out --baseline {revision}")
    r = subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", str(where), revision],
                       capture_output=True, text=True)
    if r.returncode != 0:
        raise InputError(f"--baseline {revision}: git cannot check it out ({r.stderr.strip().splitlines()[-1]}); "
                         "give a commit of this repository")
    return where


def time_run(root: Path, workload: Workload, out: Path) -> dict:
    """Run the workload with `root`'s packages (PYTHONPATH) in a fresh process; its solve time [s], the
    process's CPU time [s] and peak memory [MB]."""
    out.mkdir(parents=True, exist_ok=True)
    corpus = workload.args[:2] == ("bench", "corpus")
    if corpus:  # a corpus run renders nothing and writes a folder of pairs
        args = [*workload.args, "--quiet", "--out", str(out / "corpus")]
    elif workload.args[0] == "mocap":
        args = [*workload.args, "--no-render", "--quiet", "--out-dir", str(out), "--metrics", str(out / "m.json")]
    else:
        args = [*workload.args, "--no-render", "--quiet", "--save-path", str(out / "p.npz")]
    env = {**os.environ, "PYTHONPATH": str(root)}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "runner", *args], cwd=root, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode != 0:
        raise RuntimeError(f"{workload.name} in {root} failed: {r.stderr.strip()[-400:]}")
    evals = None
    if corpus:
        solve, evals = corpus_sums(out / "corpus")
    elif args[0] == "mocap":
        doc = json.loads((out / "m.json").read_text())
        solve, evals = doc["solve_time_s"], doc.get("n_evals")
    else:
        with np.load(out / "p.npz") as z:
            solve = float(z["wall_time_s"])
    return {"solve_s": float(solve), "cpu_s": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
            "wall_s": wall, "peak_mb": after.ru_maxrss / 1024.0, "evals": evals}


def corpus_sums(out: Path) -> tuple[float, int]:
    """(solve time [s], evaluations) summed over the pairs of a `bench corpus` run written to `out` (each pair's
    `<pair>/<clip>.metrics.json`); raises RuntimeError when it holds no pair's metrics."""
    docs = [json.loads(f.read_text()) for f in sorted(out.glob("*/*.metrics.json"))]
    if not docs:
        raise RuntimeError(f"the corpus run in {out} wrote no pair's metrics")
    return float(sum(d["solve_time_s"] for d in docs)), int(sum(d.get("n_evals") or 0 for d in docs))


class SpeedRow(NamedTuple):
    """One workload's line of the table: solve times [s] (medians), their ratio current / baseline and the
    ratio run by run, the bound (None: the runs were against another revision than the bound's), CPU times
    [s] (medians), peak memory [MB] (largest), and the evaluations (medians; None where the run records
    none) with the ratio of the solve time per evaluation: the solve's cost apart from how many evaluations
    round-off sends it through (docs/benchmarks.md)."""

    name: str
    base_s: float
    current_s: float
    ratio: float
    per_run: list
    bound: float | None
    base_cpu_s: float
    current_cpu_s: float
    base_mb: float
    current_mb: float
    base_evals: float | None = None
    current_evals: float | None = None
    per_eval_ratio: float | None = None


def ratio_rows(runs: dict, bounded=None) -> list[SpeedRow]:
    """The table's `SpeedRow`s from runs {(workload name, "baseline" | "current"): [run dicts]} (`time_run`)
    and the workloads' bounds, each only where its name is in `bounded` (None: every one; else the workloads
    whose runs were against the revision their bound is set against); a workload without runs of both has
    no row."""
    rows = []
    for w in WORKLOADS:
        base, cur = runs.get((w.name, "baseline")), runs.get((w.name, "current"))
        if not base or not cur:
            continue
        b = np.array([x["solve_s"] for x in base])
        c = np.array([x["solve_s"] for x in cur])
        per_run = (c[: len(b)] / b[: len(c)]).tolist()
        evals = [None if any(x.get("evals") is None for x in r) else [float(x["evals"]) for x in r] for r in (base, cur)]
        counted = {}
        if evals[0] and evals[1] and min(evals[0] + evals[1]) > 0:
            counted = {"base_evals": float(np.median(evals[0])), "current_evals": float(np.median(evals[1])),
                       "per_eval_ratio": float(np.median(c / evals[1]) / np.median(b / evals[0]))}
        rows.append(SpeedRow(w.name, float(np.median(b)), float(np.median(c)), float(np.median(c) / np.median(b)),
                             per_run, w.bound if bounded is None or w.name in bounded else None, float(np.median([x["cpu_s"] for x in base])),
                             float(np.median([x["cpu_s"] for x in cur])), max(x["peak_mb"] for x in base),
                             max(x["peak_mb"] for x in cur), **counted))
    return rows


def same_commit(a: str, b: str) -> bool:
    """Whether two revisions name the same commit of this repository (False where git knows either not)."""
    shas = [subprocess.run(["git", "-C", str(REPO), "rev-parse", "--verify", "--quiet", f"{r}^{{commit}}"],
                           capture_output=True, text=True).stdout.strip() for r in (a, b)]
    return bool(shas[0]) and shas[0] == shas[1]


def bench_speed(args) -> int:
    """`dynsplines bench speed`: print the table (module docstring). Returns 0."""
    chosen = [w for w in WORKLOADS if (w.default if args.only is None else w.name in args.only.split(","))]
    if not chosen:
        raise InputError(f"--only {args.only}: no such workload; choose from {', '.join(w.name for w in WORKLOADS)}")
    revision = {w.name: args.baseline or w.against for w in chosen}
    bounded = {w.name for w in chosen if same_commit(revision[w.name], w.against)}
    runs: dict = {}
    with tempfile.TemporaryDirectory(prefix="dynsplines-speed-") as tmp:
        trees = {}
        try:
            for rev in dict.fromkeys(revision.values()):
                trees[rev] = baseline_worktree(rev, Path(tmp) / f"baseline-{len(trees)}")
            for i in range(args.repeat):
                for w in chosen:
                    for label, root in (("baseline", trees[revision[w.name]]), ("current", REPO)):
                        r = time_run(root, w, Path(tmp) / f"{label}-{w.name}-{i}")
                        runs.setdefault((w.name, label), []).append(r)
                        print(f"  {w.name} {label} run {i + 1}: solve {r['solve_s']:.2f} s, CPU {r['cpu_s']:.2f} s",
                              flush=True)
        finally:
            for tree in trees.values():
                subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force", str(tree)], capture_output=True)
    against = ", ".join(f"{w.name} {revision[w.name]}" for w in chosen)
    print(f"bench speed: this checkout against the baseline ({against}), {args.repeat} alternating runs each")
    print(f"  {'workload':<18} {'solve base':>10} {'current':>8} {'ratio':>6} {'bound':>6}  per run        "
          f"{'CPU base':>8} {'current':>8} {'peak MB':>15} {'evals':>13} {'per eval':>8}")
    for r in ratio_rows(runs, bounded):
        held = ("held" if r.ratio <= r.bound else "NOT held") if r.bound is not None \
            else f"(its bound is against {next(w.against for w in chosen if w.name == r.name)})"
        bound = "-" if r.bound is None else f"{r.bound:.2f}"
        evals = "-" if r.per_eval_ratio is None else f"{r.base_evals:.0f} / {r.current_evals:.0f}"
        per_eval = "-" if r.per_eval_ratio is None else f"{r.per_eval_ratio:.3f}"
        print(f"  {r.name:<18} {r.base_s:>9.2f}s {r.current_s:>7.2f}s {r.ratio:>6.3f} {bound:>6}  "
              f"{', '.join(f'{x:.3f}' for x in r.per_run):<14} {r.base_cpu_s:>7.2f}s {r.current_cpu_s:>7.2f}s "
              f"{r.base_mb:>6.0f} / {r.current_mb:<6.0f} {evals:>13} {per_eval:>8} {held}")
    return 0
