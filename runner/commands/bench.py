"""`dynsplines bench ...`: speed measured, not asserted in tests.

    dynsplines bench run-and-step [--terms all] [--repeat N]
        optimization wall time (median of N runs), evaluations, time per evaluation, and the acceptance
        figures of the plain and the optimized path (the summary's rows, "worse" marked); with dynamics
        terms, the geometric-only objective is run side by side in the same process for the ratio.
    dynsplines bench refine [--terms all] [--counts 14,21,28] [--scores gradient,decrease]
        adaptive (weak-form Euler-Lagrange, each score) against global subdivision at equal
        variable-frame counts on the run-and-step clip: final objective, evaluations, wall time
        (runner.bench.figure.compare_refinement).
    dynsplines bench orient [--speed-random N]
        the single-body problem against the Barr-92 and constrained B-spline baselines (runner.bench.orient);
        with --speed-random N also the time to gap 1e-4 against Barr-92 on N generated sets.
    dynsplines bench orient --random N [--bvp] [--first-seed SEED]
        accuracy on request: true and estimated gap, frames, time and |q| drift of the default and
        tol=1e-4 over N generated keyframe sets (runner.bench.random_sets).
    dynsplines bench docs [--check [--exact]] [--only NAME,...] [--file docs/benchmarks.md]
        regenerate the measured tables of docs/benchmarks.md (between `<!-- bench:NAME -->` and
        `<!-- /bench:NAME -->`) from runs of the current code (runner/readme_tables.py); --check
        compares instead of writing and exits 1 when a table no longer matches (wall times and a solve's
        evaluation count are not compared; frame counts within 10 %, other figures within 20 %; --exact:
        every figure as printed).
        `bench readme` is the same command under its former name.
    dynsplines bench speed [--baseline REV] [--repeat N] [--only mocap-default,run-and-step-all]
        the command line's default solves against a baseline commit, alternating runs in fresh
        processes: solve time, CPU and peak memory, the ratio and its bound (runner/commands/bench_speed.py).

The workloads are in runner/bench/; here: parse, load the showcase clip, call, format, print.
"""
from __future__ import annotations

import argparse

from runner.animate_options import default_args, solve_options
from runner.bench import orient as orient_workload
from runner.bench.figure import GEOMETRIC, compare_refinement, path_figures, per_eval_ms, time_solves
from runner.commands import bench_contacts, bench_corpus, bench_speed
from runner.console import LEGEND, comparison_rows, format_rows
from runner.paths import REPO
from runner.problem_file import RUN_AND_STEP_KEYFRAMES, file_problem, load_problem
from runner.readme_tables import Block, compare_blocks, replace_blocks, table, timing
from solver.animate import DEFAULT_RATE
from solver.errors import InputError
from solver.metrics import path_metrics
from solver.problem import parse_terms


def register(sub) -> None:
    """Add `bench` (run-and-step, refine, docs, orient, scaling, contacts, corpus, speed) to the `dynsplines` parser."""
    p = sub.add_parser("bench", help="benchmarks: run-and-step, refine, docs, orient, scaling, contacts, corpus, speed")
    bsub = p.add_subparsers(dest="bench", metavar="BENCH")
    bsub.required = True
    r = bsub.add_parser("run-and-step", help="optimization time of the showcase clip")
    r.add_argument("--terms", default=None, help="objective terms as for `animate` ('all' adds the dynamics terms)")
    r.add_argument("--repeat", type=int, default=3, help="runs per configuration; the median is reported [3]")
    r.add_argument("--rate", type=float, default=400.0, help="quadrature points per second [400]")
    r.set_defaults(func=bench_run_and_step)
    f = bsub.add_parser("refine", help="adaptive vs global subdivision at equal variable-frame counts")
    f.add_argument("--terms", default=None, help="objective terms as for `animate` [the default terms]")
    f.add_argument("--counts", default="14,21,28",
                   help="variable-frame counts, multiples of the keyframe intervals (7 on run-and-step) [14,21,28]")
    f.add_argument("--scores", default="gradient,decrease",
                   help="adaptive subdivision scores to run (SolveOptions.score) [gradient,decrease]")
    f.add_argument("--rate", type=float, default=400.0, help="quadrature points per second [400]")
    f.set_defaults(func=bench_refine)
    m = bsub.add_parser("docs", aliases=["readme"], help="regenerate (or --check) docs/benchmarks.md's measured tables",
                        description="Regenerate the measured tables of docs/benchmarks.md (between <!-- bench:NAME "
                        "--> markers) from runs of the current code; --check compares instead (wall times and "
                        "evaluation counts excepted, frame counts within 10 %, other figures within 20 %).")
    m.add_argument("--check", action="store_true",
                   help="compare the file's tables with fresh runs instead of writing; exit 1 if one differs")
    m.add_argument("--exact", action="store_true",
                   help="with --check: every figure as printed (only on the machine that wrote the tables)")
    m.add_argument("--only", default=",".join(README_TABLES), help=f"tables to make [{','.join(README_TABLES)}]")
    m.add_argument("--file", default=str(REPO / "docs" / "benchmarks.md"),
                   help="the Markdown file [docs/benchmarks.md]")
    m.set_defaults(func=bench_readme)
    o = bsub.add_parser("orient", help="single-body orientation vs earlier methods")
    add_arguments(o)
    o.set_defaults(func=bench_orient)
    c = bsub.add_parser("scaling", help="cost against clip length: run-and-step's gait tiled 1x..8x",
                        description="The shipped clip's keyframes tiled end to end (root carried forward) on a "
                        "floor-only scene: optimization time, evaluations, time per evaluation and peak memory "
                        "of each length, one subprocess per length (runner.bench.scaling, docs/scaling.md).")
    c.add_argument("--factors", default="1,2,4,8", help="lengths, as multiples of the clip [1,2,4,8]")
    c.add_argument("--per-segment", type=int, default=2, help="variable frames per keyframe interval [2]")
    c.add_argument("--rate", type=float, default=400.0, help="quadrature points per second [400]")
    c.add_argument("--dense", action="store_true", help="also run with dense spline matrices at every length")
    c.add_argument("--per-eval", action="store_true", help="only the spline's per-evaluation table, dense vs banded")
    c.add_argument("--repeat", type=int, default=3,
                   help="solves per length, the lengths alternating; the table gives medians [3]")
    c.set_defaults(func=bench_scaling)
    bench_contacts.register(bsub)
    bench_corpus.register(bsub)
    bench_speed.register(bsub)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the options of `dynsplines bench orient` to a parser."""
    p.add_argument("--sets", default=orient_workload.DEFAULT_SETS,
                   help="comma-separated keyframe sets (runner/bench/sphere_reference/) [the three large sets]")
    p.add_argument("--methods", default="dynsplines,barr92,bspline", help="comma-separated methods")
    p.add_argument("--budget", type=float, default=60.0, help="seconds per baseline and set [60]")
    p.add_argument("--repeat", type=int, default=7,
                   help="timed runs per setting of ours, after one untimed warm-up; median reported [7]")
    p.add_argument("--verbose", action="store_true", help="print every run of every ladder")
    p.add_argument("--random", type=int, default=0, metavar="N",
                   help="instead: the accuracy distribution (true and estimated gap, frames, time, max |1 - |q||) "
                   "of the default and tol=1e-4 over the first N generated acceptance sets (seeds 1000+)")
    p.add_argument("--bvp", action="store_true",
                   help="with --random: E* by solve_bvp (minutes or out of memory on some sets; falls back to "
                   "the discrete reference when it fails) instead of the discrete reference (1-5 s a set)")
    p.add_argument("--speed-random", type=int, default=0, metavar="N",
                   help="after the named sets: time to gap 1e-4 of Barr-92 against ours (orient(tol=1e-4) and "
                   "the fastest ladder setting) on the first N generated acceptance sets")
    p.add_argument("--first-seed", type=int, default=None, metavar="SEED",
                   help="with --random or --speed-random: N generated sets from this seed on instead of the acceptance "
                   "seeds 1000-1049 (0-49 are the tuning seeds the defaults were chosen on)")
    p.add_argument("--tradeoff", action="store_true",
                   help="instead: the table of gap and max |1 - |q|| against variable frames, for both "
                   "objective forms (docs/orient.md), on --sets (default here: large_nonuniform,moderate)")


def bench_orient(args) -> int:
    """`dynsplines bench orient` for parsed arguments (see `add_arguments`). Returns 0."""
    sets = args.sets
    if args.tradeoff and sets == orient_workload.DEFAULT_SETS:
        sets = "large_nonuniform,moderate"
    chosen = orient_workload.keyframe_sets([s.strip() for s in sets.split(",") if s.strip()])
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    orient_workload.check_methods(methods)
    if args.budget <= 0 or args.repeat < 1:
        raise InputError("--budget must be > 0 seconds and --repeat >= 1")
    if args.random < 0 or args.speed_random < 0:
        raise InputError("--random and --speed-random take a number of sets >= 0")
    if args.first_seed is not None and args.first_seed < 0:
        raise InputError(f"--first-seed must be >= 0, got {args.first_seed}")
    if args.first_seed is None and (args.random > len(orient_workload.random_sets.ACCEPTANCE_SEEDS) or args.speed_random > len(
            orient_workload.random_sets.ACCEPTANCE_SEEDS)):
        raise InputError(f"at most {len(orient_workload.random_sets.ACCEPTANCE_SEEDS)} generated acceptance sets")
    if args.tradeoff:
        orient_workload.tradeoff(orient_workload.sphere_reference, chosen, out=print)
        return 0
    if args.random:
        orient_workload.random_accuracy(args.random, method="bvp" if args.bvp else "discrete", out=print,
                                        first_seed=args.first_seed)
        return 0
    print("bench orient: wall time to reach a relative gap (E - E*)/E* of the normalized path "
          f"(baselines: budget {args.budget:g} s per set; ours: median of {args.repeat} runs)")
    for ks in chosen:
        res = orient_workload.bench_set(ks, methods, args.budget, args.repeat, out=print)
        if args.verbose:
            for m, log in res["logs"].items():
                for row in log:
                    print(f"     {m}: " + ", ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}"
                                                   for k, v in row.items()))
    if args.speed_random:
        orient_workload.speed_random(args.speed_random, args.budget, args.repeat, out=print, first_seed=args.first_seed)
    return 0


def run_and_step_problems(terms: str | None, rate: float) -> dict:
    """{name: Problem} that `bench run-and-step` times: the geometric terms, and `terms` when they differ -
    each exactly what `dynsplines run-and-step --terms TERMS` solves (the keyframe file's contacts
    included: `runner.problem_file.file_problem`)."""
    problems = {"geometric": file_problem(RUN_AND_STEP_KEYFRAMES, terms=GEOMETRIC, rate=rate)[0]}
    if terms is not None:
        chosen = file_problem(RUN_AND_STEP_KEYFRAMES, terms=terms, rate=rate)[0]
        if set(chosen.terms) != set(problems["geometric"].terms):
            problems[terms] = chosen
    return problems


def bench_run_and_step(args) -> int:
    """`dynsplines bench run-and-step`: print the optimization time of the showcase clip. Returns 0."""
    problems = run_and_step_problems(args.terms, args.rate)
    keyframes = problems["geometric"].keyframes
    print(f"bench run-and-step: {keyframes.count} keyframes, {args.repeat} runs per configuration, "
          f"quadrature {args.rate:g} Hz, the command's problem and solve options")
    results = {}
    for name, problem in problems.items():
        weights = dict(problem.weights)
        options = solve_options(default_args("penalty"), weights)  # exactly what `dynsplines animate` runs
        r = results[name] = time_solves(problem, options, args.repeat)
        print(f"  {name:<12} terms {', '.join(f'{n}={w:g}' for n, w in weights.items())}")
        print(f"  {'':<12} optimization {r['wall_median_s']:.2f} s median (runs: "
              f"{', '.join(f'{w:.2f}' for w in r['wall_all_s'])}), {r['evals']} evaluations, "
              f"{r['per_eval_ms']:.2f} ms per evaluation in the run (wall time / evaluations, "
              f"{r['frames']} frames at the end)")
        print_figures(problem.model, keyframes, r["solution"], weights)
    print(f"  {LEGEND}")
    # per-evaluation cost of every configuration on one frame set (the last run's result), so the
    # ratio compares the objectives and not the frame counts they ended with
    common = results[list(results)[-1]]["solution"].frames
    direct = {name: per_eval_ms(r["objective"], common) for name, r in results.items()}
    pts = len(results["geometric"]["objective"].t)
    print(f"  value + gradient, median of 30, on one frame set ({common.count} frames, {pts} quadrature "
          f"points): " + ", ".join(f"{name} {ms:.2f} ms" for name, ms in direct.items()))
    if len(results) > 1:
        name = list(results)[1]
        g, other = results["geometric"], results[name]
        ratio = direct[name] / direct["geometric"]
        print(f"  {name} / geometric per evaluation: {ratio:.2f}x (the dynamics terms add "
              f"{direct[name] - direct['geometric']:.2f} ms, {ratio - 1:.2f}x the geometric terms' cost); "
              f"optimization wall time {other['wall_median_s'] / g['wall_median_s']:.2f}x, evaluations "
              f"{other['evals'] / max(1, g['evals']):.2f}x")
    return 0


def print_figures(model, keyframes, solution, weights, indent: str = "  ") -> None:
    """The acceptance figures of the plain spline and of an optimized path (the summary's rows, marked
    where the optimized path is worse), so a benchmark run tracks what the time bought."""
    plain = path_metrics(model, solution.initial.times, solution.initial.values, keyframes)
    opt = path_metrics(model, solution.frames.times, solution.frames.values, keyframes)
    rows = comparison_rows(plain, opt, dynamics_terms=bool({"torque", "root"} & set(weights)))
    for line in format_rows(rows):
        print(indent + line)


def bench_refine(args) -> int:
    """`dynsplines bench refine`: print adaptive vs global subdivision at equal frame counts. Returns 0;
    raises InputError for a malformed --counts or --scores."""
    keyframes, info, model, layout, _ = load_problem(RUN_AND_STEP_KEYFRAMES, None)
    weights = parse_terms(args.terms)
    try:
        counts = [int(c) for c in args.counts.split(",") if c.strip()]
    except ValueError:
        raise InputError(f"--counts {args.counts!r}: expected a comma-separated list of integers, e.g. 14,21,28") from None
    scores = [s.strip() for s in args.scores.split(",") if s.strip()]
    print(f"bench refine: run-and-step, terms {', '.join(f'{n}={w:g}' for n, w in weights.items())}\n"
          f"  renormalized on the plain spline, fixed weights (no penalty continuation); final objective E, "
          f"evaluations, seconds")
    rows = compare_refinement(model, keyframes, layout, weights, counts, scores, args.rate)
    print(f"  objective on the plain spline: {rows[0]['global']['E_initial']:.6g}")
    methods = [m for m in rows[0] if m != "count"]
    print(f"  {'variable frames':>15}" + "".join(f"  {m:>26}" for m in methods))
    for r in rows:
        cells = []
        for m in methods:
            c = r[m]
            ratio = "" if m == "global" else f" ({c['E'] / r['global']['E']:.3f}x)"
            frames = "" if c["variable"] == r["count"] else f" [{c['variable']} frames]"
            cells.append(f"{c['E']:.5g}{ratio}{frames} {c['evals']}/{c['wall_s']:.1f}s".rjust(26))
        print(f"  {r['count']:>15}" + "".join(f"  {c}" for c in cells))
    return 0


# ----------------------------------------------------------------- docs/benchmarks.md tables
#: the measured tables of docs/benchmarks.md, in the order they are made: name -> what it shows
README_TABLES = {
    "terms-all": "run-and-step, plain spline vs `--terms all` (the least change with the force bounds)",
    "run-and-step": "bench run-and-step --terms all: both objectives' evaluations and times",
    "refine": "bench refine --terms all: adaptive vs global subdivision, final objective",
}
REFINE_COUNTS = (14, 21, 28, 35, 42)


class _Runs:
    """The showcase clip's runs, made once and shared by the tables (the command's problem and options)."""

    def __init__(self, rate: float):
        self.keyframes, info, self.model, self.layout, _ = load_problem(RUN_AND_STEP_KEYFRAMES, None)
        self.rate = rate
        self._solved = {}

    def solved(self, terms: str, method: str = "penalty") -> dict:
        """The solve of `terms` by `method` ("penalty": the weighted terms; "least-change": as
        `run-and-step --terms all` solves it)."""
        if (terms, method) not in self._solved:
            problem = file_problem(RUN_AND_STEP_KEYFRAMES, terms=terms, rate=self.rate)[0]
            weights = dict(problem.weights)
            r = time_solves(problem, solve_options(default_args(method), weights), 1)
            r["figures"] = path_figures(self.model, self.keyframes, r["solution"])
            r["weights"] = weights
            self._solved[terms, method] = r
        return self._solved[terms, method]


def _kf_error(v: float) -> str:
    return "< 1e-12" if v < 1e-12 else f"{v:.1e}"  # round-off differs between machines


def _terms_all_block(runs: _Runs) -> Block:
    r = runs.solved("all", "least-change")
    f = r["figures"]
    p, o = f["plain"], f["optimized"]
    worse = {label: flag for label, _, _, _, flag in comparison_rows(p, o, dynamics_terms=True)}

    def mark(*labels):
        return " (worse)" if any(worse.get(label) for label in labels) else ""

    def pair(key_rms, key_peak, fmt, d):
        return f"{fmt.format(d[key_rms])} / {fmt.format(d[key_peak])}"

    def geometry(d):
        return (f"{d['max_penetration_mm']:.2f} / {_kf_error(d['keyframe_error'])} / {d['max_norm_deviation']:.4f} / "
                f"{d['max_hyperextension_deg']:.2f}")

    rows = [
        ["max penetration [mm] / keyframe error / max \\|1-\\|q\\|\\| / hyperextension [deg]", geometry(p),
         geometry(o) + mark("max penetration [mm] (1000 Hz)", "max |1 - |q||", "max hyperextension [deg]")],
        ["RMS / peak joint torque [N m]", pair("rms_joint_torque_Nm", "peak_joint_torque_Nm", "{:.1f}", p),
         pair("rms_joint_torque_Nm", "peak_joint_torque_Nm", "{:.1f}", o)
         + mark("RMS joint torque [N m]", "peak joint torque [N m]")],
        ["flight (all four contact sites clear) [s]", f"{p['flight_s']:.3f}",
         f"{o['flight_s']:.3f}" + mark("flight (all feet clear) [s]")],
        [f"RMS / peak root force in flight [N] (body weight: {f['body_weight_N']:.0f} N)",
         pair("rms_root_force_flight_N", "peak_root_force_flight_N", "{:.1f}", p),
         pair("rms_root_force_flight_N", "peak_root_force_flight_N", "{:.1f}", o)
         + mark("RMS root force in flight [N]", "peak root force in flight [N]")],
        ["RMS / peak root torque in flight [N m]", pair("rms_root_torque_flight_Nm", "peak_root_torque_flight_Nm",
                                                        "{:.1f}", p),
         pair("rms_root_torque_flight_Nm", "peak_root_torque_flight_Nm", "{:.1f}", o)
         + mark("RMS root torque in flight [N m]", "peak root torque in flight [N m]")],
        ["peak pelvis acceleration [m/s^2]", f"{p['peak_pelvis_acceleration_ms2']:.1f}",
         f"{o['peak_pelvis_acceleration_ms2']:.1f}" + mark("peak pelvis acceleration [m/s^2]")],
        ["RMS / peak root force on the ground [body weights]",
         pair("rms_root_force_ground_bw", "peak_root_force_ground_bw", "{:.2f}", p),
         pair("rms_root_force_ground_bw", "peak_root_force_ground_bw", "{:.2f}", o)
         + mark("RMS root force on ground [body wt]", "peak root force on ground [body wt]")],
        ["optimization", "", f"{f['variable']} variable frames, "
                             + timing(f"{f['evals']} evaluations, {f['wall_s']:.0f} s")],
    ]
    return Block("terms-all", table(["", "plain spline", "optimized (`--terms all`)"], rows))


def _run_and_step_block(runs: _Runs) -> Block:
    rows = []
    common = runs.solved("all")["solution"].frames
    for name, terms in (("geometric (no contact terms)", GEOMETRIC), ("all terms (with the file's contacts)", "all")):
        r = runs.solved(terms)
        f = r["figures"]
        rows.append([name, timing(str(f["evals"])), str(f["frames"]), f"{f['E_final']:.5g}",
                     timing(f"{f['wall_s']:.1f}"), timing(f"{per_eval_ms(r['objective'], common):.1f}")])
    header = ["objective", "evaluations", "frames at the end", "final objective E",
              "optimization [s]", f"value + gradient on one frame set ({common.count} frames) [ms]"]
    return Block("run-and-step", table(header, rows))


def _refine_block(runs: _Runs) -> Block:
    weights = parse_terms("all")
    out = compare_refinement(runs.model, runs.keyframes, runs.layout, weights, REFINE_COUNTS,
                             ("gradient", "decrease"), 400.0)
    methods = ["global", "adaptive-gradient", "adaptive-decrease"]
    rows = []
    for r in out:
        cells = [str(r["count"])]
        for m in methods:
            c = r[m]
            frames = "" if c["variable"] == r["count"] else f" ({c['variable']} frames)"
            cells.append(f"{c['E']:.3f}{frames}")
        rows.append(cells)
    header = [f"variable frames (plain spline: {out[0]['global']['E_initial']:.3g})", "global",
              'adaptive, score "gradient"', 'adaptive, score "decrease" (default)']
    return Block("refine", table(header, rows))


_MAKERS = {"terms-all": _terms_all_block, "run-and-step": _run_and_step_block, "refine": _refine_block}


def bench_readme(args) -> int:
    """`dynsplines bench docs [--check [--exact]]` (alias `bench readme`): regenerate or check the
    measured tables of docs/benchmarks.md (runner/readme_tables.py has the tolerances of the check).

    Returns 0 (written, or every table matches), 1 with --check when a table differs (each difference
    printed). Raises InputError for an unknown table name, --exact without --check, or a file without
    the markers."""
    from pathlib import Path

    names = [n.strip() for n in args.only.split(",") if n.strip()]
    unknown = [n for n in names if n not in _MAKERS]
    if unknown or not names:
        raise InputError(f"--only {args.only!r}: unknown table(s) {', '.join(unknown) or '(none given)'}; "
                         f"the tables are {', '.join(_MAKERS)}")
    if args.exact and not args.check:
        raise InputError("--exact compares; it goes with --check (without --check the tables are written)")
    path = Path(args.file)
    if not path.is_file():
        raise InputError(f"--file {path}: no such file")
    runs = _Runs(DEFAULT_RATE)
    blocks = []
    for n in names:
        print(f"bench docs: {n}: {README_TABLES[n]} ...", flush=True)
        blocks.append(_MAKERS[n](runs))
    if args.check:
        problems = compare_blocks(path, blocks, exact=args.exact)
        for p in problems:
            print(p)
        rule = "every figure as printed" if args.exact else "frame counts within 10 %, other figures within 20 %"
        print(f"bench docs --check: {len(blocks) - len(problems)} of {len(blocks)} tables match {path} "
              f"(wall times and evaluation counts not compared; {rule})")
        return 1 if problems else 0
    replace_blocks(path, blocks)
    print(f"bench docs: wrote {', '.join(b.name for b in blocks)} in {path}")
    return 0


def bench_scaling(args) -> int:
    """`dynsplines bench scaling`: runner.bench.scaling's table for the given lengths."""
    from runner.bench import scaling

    if args.repeat < 1:
        raise InputError(f"--repeat must be at least 1, got {args.repeat}")
    argv = ["--factors", args.factors, "--per-segment", str(args.per_segment), "--rate", str(args.rate),
            "--repeat", str(args.repeat)]
    argv += ["--dense"] * args.dense + ["--per-eval"] * args.per_eval
    return scaling.main(argv)
