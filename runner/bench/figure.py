"""Benchmark workloads of the figure (`dynsplines bench run-and-step`, `dynsplines bench refine`): solve a
keyframe problem several times and time it, and compare adaptive with global subdivision.

Every function takes the model, keyframes, layout and options as arguments (no files read here) and
returns data; runner/commands/bench.py loads the showcase clip and prints.
"""
from __future__ import annotations

import statistics
import time

from solver.errors import InputError
from solver.frames import FrameSet
from solver.problem import figure_objective
from solver.solve import SCORES, SolveOptions, solve

#: the geometric terms (the default objective), the baseline of the dynamics terms' cost
GEOMETRIC = "penetration,unit,bending,smooth"


def time_solves(problem, options: SolveOptions, repeat: int) -> dict:
    """Solve a problem `repeat` times (at least once) with `options`; the timings and the last solution.

    Args:
        problem: a `solver.Problem` (`make_problem`; the command line's benchmarks build it with the same
            function as the command, e.g. `runner.problem_file.file_problem`).
        options: SolveOptions (the command passes exactly what `dynsplines animate` runs).
        repeat: runs.
    Returns:
        dict: wall_median_s, wall_all_s (list) [s], cpu_median_s (CPU time of this process in the
        solves [s]: what a loaded machine's wall time is not), evals (median), per_eval_ms (median of wall / evals),
        objective_s and optimizer_s (medians [s, wall] of the rounds' time inside the objective and in the
        optimizer's own work, `OptimizeResult.fun_time_s`), E_final, frames (count at the end), objective
        (the problem's Objective), solution (the last Solution).
    """
    from solver.animate import solve_problem

    runs, cpus = [], []
    for _ in range(max(1, repeat)):
        c0 = time.process_time()
        sol = solve_problem(problem, options)
        cpus.append(time.process_time() - c0)
        runs.append(sol)
    walls = [s.wall_time_s for s in runs]
    evals = [s.n_evals for s in runs]
    return {
        "wall_median_s": statistics.median(walls),
        "wall_all_s": walls,
        "cpu_median_s": statistics.median(cpus),
        "evals": int(statistics.median(evals)),
        "per_eval_ms": 1e3 * statistics.median([s.wall_time_s / max(1, s.n_evals) for s in runs]),
        "objective_s": statistics.median(sum(r.result.fun_time_s for r in s.rounds) for s in runs),
        "optimizer_s": statistics.median(sum(r.result.wall_time_s - r.result.fun_time_s for r in s.rounds) for s in runs),
        "E_final": runs[-1].E_final,
        "frames": runs[-1].frames.count,
        "objective": problem.objective,
        "solution": runs[-1],
    }


def per_eval_ms(objective, frames, n: int = 30) -> float:
    """Median wall time [ms] of one value + gradient evaluation of `objective` on `frames`.

    Evaluations alternate between the frames and the frames with their free components moved by 1e-9,
    so that no term's cache of its last evaluation (the shared engine's forward pass) is hit, as in an
    optimization, where every evaluation is at a new point."""
    objective.evaluate(frames.times, frames.values, grad=True)  # warm the spline-matrix cache
    moved = frames.values + 1e-9 * frames.free
    times = []
    for i in range(n):
        P = moved if i % 2 else frames.values
        t0 = time.perf_counter()
        objective.evaluate(frames.times, P, grad=True)
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


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


def path_figures(model, keyframes, solution) -> dict:
    """The acceptance figures (`solver.metrics.path_metrics`, 1000 Hz) of a solution's plain spline and
    optimized path, for docs/benchmarks.md's tables and `dynsplines bench run-and-step`.

    Returns:
        dict: plain, optimized (path_metrics dicts), evals, frames (count at the end), variable,
        E_initial, E_final, wall_s [s] (machine-dependent), body_weight_N (m g of the model).
    """
    import numpy as np

    from solver.metrics import path_metrics

    return {
        "plain": path_metrics(model, solution.initial.times, solution.initial.values, keyframes),
        "optimized": path_metrics(model, solution.frames.times, solution.frames.values, keyframes),
        "evals": solution.n_evals,
        "frames": solution.frames.count,
        "variable": solution.frames.n_variable,
        "E_initial": solution.E_initial,
        "E_final": solution.E_final,
        "wall_s": solution.wall_time_s,
        "body_weight_N": float(np.sum(model.body_mass) * np.linalg.norm(model.opt.gravity)),
    }
