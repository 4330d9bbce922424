"""`dynsplines bench ...`: speed measured, not asserted in tests.

    dynsplines bench run-and-step [--terms all] [--repeat N]
        optimization wall time (median of N runs), evaluations, time per evaluation; with dynamics
        terms, the geometric-only objective is run side by side in the same process for the ratio.
    dynsplines bench refine [--terms all] [--counts 14,21,28] [--scores gradient,decrease]
        adaptive (weak-form Euler-Lagrange, each score) against global subdivision at equal
        variable-frame counts on the run-and-step clip: final objective, evaluations, wall time
        (`compare_refinement`).
    dynsplines bench orient
        the single-body problem against the Barr-92 and constrained B-spline baselines (runner.bench_orient).
"""
from __future__ import annotations

import statistics
import time

from solver.frames import FrameSet
from solver.problem import figure_objective, parse_terms
from solver.solve import solve

GEOMETRIC = "penetration,unit,bending,smooth"


def register(sub) -> None:
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
    from runner.bench_orient import add_arguments as _orient_arguments

    _orient_arguments(o)
    o.set_defaults(func=_bench_orient)


def _bench_orient(args) -> int:
    from runner.bench_orient import run

    return run(args)


def _one_config(model, keyframes, layout, weights, rate, repeat):
    """Solve `repeat` times with the command's options; returns the timings and the last objective."""
    from runner.animate import default_args, solve_options

    options = solve_options(default_args(), weights)  # exactly what `dynsplines animate` runs
    runs = []
    for _ in range(max(1, repeat)):
        objective = figure_objective(model, weights, keyframes.times[0], keyframes.times[-1], rate=rate)
        initial = FrameSet.from_keyframes(keyframes, layout.quat_slots)
        sol = solve(objective, initial, options)
        runs.append(sol)
    walls = [s.wall_time_s for s in runs]
    evals = [s.n_evals for s in runs]
    return {
        "wall_median_s": statistics.median(walls),
        "wall_all_s": walls,
        "evals": int(statistics.median(evals)),
        "per_eval_ms": 1e3 * statistics.median([s.wall_time_s / max(1, s.n_evals) for s in runs]),
        "E_final": runs[-1].E_final,
        "frames": runs[-1].frames.count,
        "objective": objective,
        "solution": runs[-1],
    }


def _per_eval_ms(objective, frames, n: int = 30) -> float:
    """Median wall time [ms] of one value + gradient evaluation of `objective` on `frames`."""
    objective.evaluate(frames.times, frames.values, grad=True)  # warm the spline-matrix cache
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        objective.evaluate(frames.times, frames.values, grad=True)
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


def bench_run_and_step(args) -> int:
    from runner.animate import RUN_AND_STEP_KEYFRAMES, load_problem

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
        r = results[name] = _one_config(model, keyframes, layout, weights, args.rate, args.repeat)
        print(f"  {name:<12} terms {', '.join(f'{n}={w:g}' for n, w in weights.items())}")
        print(f"  {'':<12} optimization {r['wall_median_s']:.2f} s median (runs: "
              f"{', '.join(f'{w:.2f}' for w in r['wall_all_s'])}), {r['evals']} evaluations, "
              f"{r['per_eval_ms']:.2f} ms per evaluation in the run (wall time / evaluations, "
              f"{r['frames']} frames at the end)")
    # per-evaluation cost of every configuration on one frame set (the last run's result), so the
    # ratio compares the objectives and not the frame counts they ended with
    common = results[list(results)[-1]]["solution"].frames
    direct = {name: _per_eval_ms(r["objective"], common) for name, r in results.items()}
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


def compare_refinement(model, keyframes, layout, weights: dict, counts, scores=("gradient", "decrease"),
                       rate: float = 400.0, ftol: float = 1e-6) -> list[dict]:
    """Adaptive against global subdivision at equal numbers of variable frames (paper fig. 10's
    experiment, on any keyframes).

    Every run starts from the plain spline with the same renormalization scales (eq. 7, from the
    plain spline) and *fixed* weights (no penalty continuation: it would change the objective by a
    different amount in each run). Global: n frames in each of the k keyframe intervals, one
    optimization. Adaptive: one frame per interval, then rounds that add frames where the weak-form
    Euler-Lagrange score ranks segments highest until `count` variable frames, optimizing after each
    round. The final objectives compare: the same terms, weights and scales (the root term's lagged
    flight indicator equals the path's own at the end of a solve, see `RootResidual`).

    Args:
        model, keyframes, layout: the problem. weights: {term: weight}. counts: variable-frame
            counts, each a multiple of the number of keyframe intervals k.
        scores: adaptive rankings to run (`SolveOptions.score`: "gradient", "decrease").
        rate: quadrature points per second. ftol: relative objective tolerance of each optimization.
    Returns:
        one dict per count: "count", and per method ("global", "adaptive-<score>"): E (final
        objective), E_initial, variable (frames), evals, wall_s.
    Raises:
        InputError: a count that is not a positive multiple of k, or an unknown score.
    """
    from solver.errors import InputError
    from solver.solve import SCORES, SolveOptions

    k = keyframes.count - 1
    for sc in scores:
        if sc not in SCORES:
            raise InputError(f"unknown subdivision score {sc!r}; choose from: {', '.join(SCORES)}")
    rows = []
    for count in counts:
        if count <= 0 or count % k:
            raise InputError(f"variable-frame count {count} is not a positive multiple of the {k} keyframe intervals")
        row = {"count": count}
        methods = [("global", SolveOptions(subdivision="global", per_segment=count // k, limits=(), ftol_rel=ftol,
                                           precondition=True))]
        methods += [(f"adaptive-{sc}", SolveOptions(subdivision="adaptive", per_segment=1, rounds=64,
                                                     max_frames=count, limits=(), ftol_rel=ftol, score=sc,
                                                     precondition=True)) for sc in scores]
        for kind, options in methods:
            objective = figure_objective(model, weights, keyframes.times[0], keyframes.times[-1], rate=rate)
            sol = solve(objective, FrameSet.from_keyframes(keyframes, layout.quat_slots), options)
            row[kind] = {"E": sol.E_final, "variable": sol.frames.n_variable, "evals": sol.n_evals,
                         "wall_s": sol.wall_time_s, "E_initial": sol.E_initial}
        rows.append(row)
    return rows


def bench_refine(args) -> int:
    from runner.animate import RUN_AND_STEP_KEYFRAMES, load_problem
    from solver.errors import InputError

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
