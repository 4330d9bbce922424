"""`dynsplines bench ...`: speed measured, not asserted in tests.

    dynsplines bench run-and-step [--terms all] [--repeat N]
        optimization wall time (median of N runs), evaluations, time per evaluation, and the acceptance
        figures of the plain and the optimized path (the summary's rows, "worse" marked); with dynamics
        terms, the geometric-only objective is run side by side in the same process for the ratio.
    dynsplines bench refine [--terms all] [--counts 14,21,28] [--scores gradient,decrease]
        adaptive (weak-form Euler-Lagrange, each score) against global subdivision at equal
        variable-frame counts on the run-and-step clip: final objective, evaluations, wall time
        (solver.bench.figure.compare_refinement).
    dynsplines bench orient
        the single-body problem against the Barr-92 and constrained B-spline baselines (solver.bench.orient).

The workloads are in solver/bench/; here: parse, load the showcase clip, call, format, print.
"""
from __future__ import annotations

import argparse

from runner.animate_options import default_args, solve_options
from runner.console import LEGEND, comparison_rows, format_rows
from runner.problem_file import RUN_AND_STEP_KEYFRAMES, load_problem
from solver.bench import orient as orient_workload
from solver.bench.figure import GEOMETRIC, compare_refinement, per_eval_ms, time_solves
from solver.errors import InputError
from solver.metrics import path_metrics
from solver.problem import parse_terms


def register(sub) -> None:
    """Add `bench` (run-and-step, refine, orient) to the `dynsplines` parser."""
    p = sub.add_parser("bench", help="benchmarks: run-and-step, orient")
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
    o = bsub.add_parser("orient", help="single-body orientation vs earlier methods")
    add_arguments(o)
    o.set_defaults(func=bench_orient)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the options of `dynsplines bench orient` to a parser."""
    p.add_argument("--sets", default=orient_workload.DEFAULT_SETS,
                   help="comma-separated keyframe sets (solver/bench/sphere_reference/) [the three large sets]")
    p.add_argument("--methods", default="dynsplines,barr92,bspline", help="comma-separated methods")
    p.add_argument("--budget", type=float, default=60.0, help="seconds per baseline and set [60]")
    p.add_argument("--repeat", type=int, default=7,
                   help="timed runs per setting of ours, after one untimed warm-up; median reported [7]")
    p.add_argument("--verbose", action="store_true", help="print every run of every ladder")
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
    if args.tradeoff:
        orient_workload.tradeoff(orient_workload.sphere_reference, chosen, out=print)
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
    return 0


def bench_run_and_step(args) -> int:
    """`dynsplines bench run-and-step`: print the optimization time of the showcase clip. Returns 0."""
    keyframes, info, model, layout, _ = load_problem(RUN_AND_STEP_KEYFRAMES, None)
    configs = {"geometric": parse_terms(GEOMETRIC)}
    if args.terms is not None:
        chosen = parse_terms(args.terms)
        if set(chosen) != set(configs["geometric"]):
            configs[args.terms] = chosen
    print(f"bench run-and-step: {keyframes.count} keyframes, {args.repeat} runs per configuration, "
          f"quadrature {args.rate:g} Hz, the command's solve options")
    results = {}
    for name, weights in configs.items():
        options = solve_options(default_args(), weights)  # exactly what `dynsplines animate` runs
        r = results[name] = time_solves(model, keyframes, layout, weights, options, args.rate, args.repeat)
        print(f"  {name:<12} terms {', '.join(f'{n}={w:g}' for n, w in weights.items())}")
        print(f"  {'':<12} optimization {r['wall_median_s']:.2f} s median (runs: "
              f"{', '.join(f'{w:.2f}' for w in r['wall_all_s'])}), {r['evals']} evaluations, "
              f"{r['per_eval_ms']:.2f} ms per evaluation in the run (wall time / evaluations, "
              f"{r['frames']} frames at the end)")
        print_figures(model, keyframes, r["solution"], weights)
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
