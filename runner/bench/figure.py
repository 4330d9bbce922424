"""Benchmark workloads of the figure (`dynsplines bench run-and-step`, `bench contacts`, `bench docs`): solve
a keyframe problem several times and time it, and its acceptance figures.

Every function takes the model, keyframes, layout and options as arguments (no files read here) and
returns data; runner/commands/bench.py loads the showcase clip and prints.
"""
from __future__ import annotations

import statistics
import time

from solver.least_change import LeastChangeOptions


def time_solves(problem, options: LeastChangeOptions, repeat: int) -> dict:
    """Solve a problem `repeat` times (at least once) with `options`; the timings and the last solution.

    Args:
        problem: a `solver.Problem` (`build_problem`; the command line's benchmarks build it with the same
            function as the command, e.g. `runner.problem_file.file_problem`).
        options: LeastChangeOptions (the command passes exactly what `dynsplines animate` runs).
        repeat: runs.
    Returns:
        dict: wall_median_s, wall_all_s (list) [s], cpu_median_s (CPU time of this process in the
        solves [s]: what a loaded machine's wall time is not), evals (median), per_eval_ms (median of wall / evals),
        objective_s and optimizer_s (medians [s, wall] of the rounds' time inside the objective and in the
        optimizer's own work, `OptimizeResult.fun_time_s`), E_final, frames (count at the end), solution
        (the last Solution).
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
        "solution": runs[-1],
    }


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
