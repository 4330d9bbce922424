"""Cost against clip length (docs/scaling.md "The scaling workload"): the run-and-step gait tiled 1x, 2x, 4x, 8x.

    python -m runner.bench.scaling [--factors 1,2,4,8] [--dense] [--per-eval]

The workload (`scaling`) takes a Keyframes object (the driver, `main`, reads the shipped clip) and
repeats it end to end (`tile_keyframes`): copy r starts where copy r-1 ends, with the root's x and y
carried forward by the clip's displacement, so the tiled clip is a run exactly r times as long (r
times the keyframe intervals and quadrature points). The scene is floor-only (`FLOOR_SCENE`: the
figure plus the floor plane): the shipped scene's step box would sit under the first copy only.

Each length is solved in its own subprocess (one BLAS thread), so that its peak resident memory
(getrusage ru_maxrss) is its own and not the largest of the lengths before it; the table reports the
peak minus the resident size just before the solve (the solve's own memory: arrays, the spline bases,
the optimizer; the interpreter, numpy, scipy and MuJoCo are the same at every length).

The problem is built and solved as `dynsplines animate` builds and solves it (`solver.build_problem`,
`solver.solve_problem`: the least change to the plain spline that meets the constraints, with the
command's `LeastChangeOptions`). The keyframes have no contact schedule here (the shipped schedule
names the step box), so the constraints are penetration, the anatomical limits, the unit norm and the
no-jolt bounds; refinement is the command's (a frame in each segment over its share of the tolerance, until
the total is below it), so the frame count at 8x need not be 8 times the count at 1x.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from solver.figure import FIGURE_FILE
from solver.keyframes import Keyframes

FIGURE = FIGURE_FILE  # the shipped figure

#: The scene of the scaling workload: the figure and a floor, nothing else.
FLOOR_SCENE = """<mujoco model="floor_only">
  <include file="humanoid39.xml"/>
  <option timestep="0.002" gravity="0 0 -9.81"/>
  <worldbody>
    <geom name="floor" type="plane" size="0 0 0.05" contype="1" conaffinity="1"/>
  </worldbody>
</mujoco>
"""

SINGLE_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def floor_model(figure: Path = FIGURE):
    """MjModel of `FLOOR_SCENE` with the figure file `figure` (humanoid39.xml)."""
    import mujoco

    return mujoco.MjModel.from_xml_string(FLOOR_SCENE, {"humanoid39.xml": Path(figure).read_bytes()})


def tile_keyframes(keyframes: Keyframes, copies: int, root_xy=(0, 1)) -> Keyframes:
    """The keyframes repeated `copies` times end to end, the root's x, y carried forward; exactly
    `copies` times the span and the keyframe intervals.

    Copy r is the clip shifted in time by r T and in root x, y by r D (T the clip's span, D the root's
    x, y displacement from its first keyframe to its last); every copy but the last drops its last
    keyframe, whose time the next copy's first keyframe takes (the gait restarts there: its last
    interval runs into the next copy's first pose).

    Args:
        keyframes: (k keyframes, full or partial). copies: >= 1. root_xy: qpos indices of the root's x, y.
    Returns:
        Keyframes with (k - 1) copies + 1 keyframes over copies T.
    """
    t, v, mask = keyframes.times, keyframes.values, keyframes.mask
    span = t[-1] - t[0]
    ix = list(root_xy)
    disp = v[-1, ix] - v[0, ix]
    times, values, masks = [], [], []
    for r in range(copies):
        last = r == copies - 1
        keep = slice(None) if last else slice(0, -1)
        times.append(t[keep] + r * span)
        vr = v[keep].copy()
        vr[:, ix] += r * disp
        values.append(vr)
        masks.append(mask[keep])
    return Keyframes(np.concatenate(times), np.concatenate(values), np.concatenate(masks),
                     source=f"{keyframes.source} x{copies}")


def solve_one(keyframes: Keyframes, figure: Path = FIGURE, rate: float | None = None) -> dict:
    """Solve the tiled clip once in this process; returns timings, memory and result figures.

    Args:
        keyframes: the tiled clip. figure: the figure MJCF. rate: quadrature points per second [1/s]
            (None: `LeastChangeOptions`' default).
    Returns:
        dict: keyframes, frames, points (quadrature), wall_s, cpu_s (user + system of the solve),
        evals, checks (refinement checks: `Solution.segment_decreases`), ms_per_eval (wall / evals),
        rss_before_mb, maxrss_mb (peak resident size of the process after the solve), peak_mb (the
        difference), E_initial, E_final, status, max_penetration_mm, keyframe_error (path_metrics at 1000 Hz), banded (the spline bases of the
        final frames are evaluated through the tridiagonal system), obj_cpu_s and obj_calls (CPU time
        in, and calls of, `AugmentedLagrangian.evaluate` during the solve: `_objective_cpu`).
    """
    from solver.animate import solve_problem
    from solver.least_change import LeastChangeOptions
    from solver.metrics import path_metrics
    from solver.problem import ProblemSpec, build_problem
    from solver.quadrature import quadrature_times
    from solver.spline_basis import SplineBasis

    model = floor_model(figure)
    options = LeastChangeOptions() if rate is None else LeastChangeOptions(rate=rate)
    problem = build_problem(model, ProblemSpec(keyframes))
    rss_before = _rss_mb()
    r0 = resource.getrusage(resource.RUSAGE_SELF)
    t0 = time.perf_counter()
    with _objective_cpu() as obj:
        sol = solve_problem(problem, options)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_SELF)
    maxrss = r1.ru_maxrss / 1024.0  # Linux: kilobytes
    t, _ = quadrature_times(float(keyframes.times[0]), float(keyframes.times[-1]), options.rate)
    metrics = path_metrics(model, sol.frames.times, sol.frames.values, keyframes, rate=1000.0, dynamics=False)
    return {
        "keyframes": keyframes.count, "frames": sol.frames.count, "points": len(t),
        "wall_s": wall, "cpu_s": (r1.ru_utime + r1.ru_stime) - (r0.ru_utime + r0.ru_stime),
        "solve_wall_s": sol.wall_time_s, "evals": sol.n_evals, "checks": len(sol.segment_decreases),
        "ms_per_eval": 1e3 * wall / max(1, sol.n_evals),
        "rss_before_mb": rss_before, "maxrss_mb": maxrss, "peak_mb": maxrss - rss_before,
        "E_initial": sol.E_initial, "E_final": sol.E_final, "status": sol.status.name,
        "max_penetration_mm": metrics["max_penetration_mm"], "keyframe_error": metrics["keyframe_error"],
        "banded": bool(SplineBasis(sol.frames.times, t).banded), "obj_cpu_s": obj["cpu_s"], "obj_calls": obj["calls"],
    }


@contextmanager
def _objective_cpu():
    """Within the block, CPU time [s] and calls of `AugmentedLagrangian.evaluate` (every evaluation of
    the augmented Lagrangian: the subproblems' and the refinement's), collected in the dict it yields:
    "cpu_s", "calls". The rest of a solve's CPU time is the optimizer's own work (nlopt's L-BFGS, the
    preconditioner's maps) and the setup (reference motion, constraints, spline bases)."""
    from solver.lagrangian import AugmentedLagrangian

    acc = {"cpu_s": 0.0, "calls": 0}
    evaluate = AugmentedLagrangian.evaluate

    def timed(self, *args, **kwargs):
        t = time.process_time()
        try:
            return evaluate(self, *args, **kwargs)
        finally:
            acc["cpu_s"] += time.process_time() - t
            acc["calls"] += 1

    AugmentedLagrangian.evaluate = timed
    try:
        yield acc
    finally:
        AugmentedLagrangian.evaluate = evaluate


def _rss_mb() -> float:
    """Current resident set size [MB] (Linux /proc; 0 elsewhere)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except OSError:
        return 0.0


def scaling(keyframes: Keyframes, factors=(1, 2, 4, 8), dense: bool = False, figure: Path = FIGURE,
            rate: float | None = None, repeat: int = 1) -> list[dict]:
    """The workload: per length factor, `solve_one` on the tiled clip in a fresh subprocess.

    Args:
        keyframes: the clip to tile. factors: length multiples. dense: force the dense spline matrices
            at every size (the cost before the banded evaluation, for comparison). rate: as `solve_one`.
        repeat: solves per length, the lengths alternating (1x, 2x, .., 1x, 2x, ..), so that a slow
            or fast spell of a shared machine falls on every length (`median_rows` combines them).
    Returns:
        one `solve_one` dict per factor and repeat, plus "factor" and "repeat", in the order run.
    """
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        paths = {}
        for f in factors:
            kf = tile_keyframes(keyframes, f)
            paths[f] = Path(tmp) / f"x{f}.npz"
            np.savez(paths[f], times=kf.times, values=kf.values, mask=kf.mask)
        env = {**os.environ, **SINGLE_THREAD}
        for rep in range(max(1, int(repeat))):
            for f in factors:
                cmd = [sys.executable, "-m", "runner.bench.scaling", "--worker", str(paths[f]), "--figure", str(figure)]
                cmd += [] if rate is None else ["--rate", str(rate)]
                cmd += ["--dense"] if dense else []
                res = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
                if res.returncode != 0:
                    raise RuntimeError(f"scaling worker x{f} failed:\n{res.stderr}")
                row = json.loads(res.stdout.strip().splitlines()[-1])
                row["factor"], row["repeat"] = f, rep
                out.append(row)
    return out


#: the timing and memory fields of a `solve_one` row that `median_rows` takes the median of; the rest
#: (evaluations, frames, penetration, ...) is the same in every repeat of a length (the solve is
#: deterministic) and is taken from the first
TIMED_FIELDS = ("wall_s", "cpu_s", "obj_cpu_s", "peak_mb")


def median_rows(rows: list[dict]) -> list[dict]:
    """One row per factor (in the order first run): the median over its repeats of `TIMED_FIELDS`,
    the other fields of its first repeat, and "repeats" (how many).

    Raises:
        RuntimeError: the repeats of a length differ in evaluations (the solve should be deterministic).
    """
    by: dict = {}
    for r in rows:
        by.setdefault(r["factor"], []).append(r)
    out = []
    for f, rs in by.items():
        if len({r["evals"] for r in rs}) > 1:
            raise RuntimeError(f"the {f}x solves took different evaluation counts: {[r['evals'] for r in rs]}")
        m = dict(rs[0])
        for k in TIMED_FIELDS:
            m[k] = float(np.median([r[k] for r in rs]))
        m["repeats"] = len(rs)
        out.append(m)
    return out


def repeat_ratios(rows: list[dict], factor: int, base: int, key: str = "cpu_s") -> list[float]:
    """`key` of `factor` over `key` of `base`, repeat by repeat (the two run next to each other)."""
    by = {(r["factor"], r["repeat"]): r[key] for r in rows}
    reps = sorted({r["repeat"] for r in rows})
    return [by[(factor, k)] / by[(base, k)] for k in reps if (factor, k) in by and (base, k) in by]


def per_eval_spline(sizes, nq: int = 51, needs=(0, 2), reps_budget: float = 2e5) -> list[dict]:
    """Value + pullback time of `SplineBasis` dense against banded, side by side in one process.

    Args:
        sizes: ((points, frames), ...). nq: components (51: the figure). needs: orders evaluated
            (the figure's default terms read Y and Y'').
    Returns:
        one dict per size: points, frames, entries, dense_us, banded_us (best of 5 repeats).
    """
    from solver.spline_basis import SplineBasis

    rng = np.random.default_rng(0)
    rows = []
    for n, m in sizes:
        x = np.linspace(0.0, n / 400.0, m)
        t = np.linspace(0.0, n / 400.0, n)
        P = rng.normal(size=(m, nq))
        g = rng.normal(size=(n, nq))
        reps = max(3, int(reps_budget / (n * m)))
        r = {"points": n, "frames": m, "entries": n * m}
        for mode in ("dense", "banded"):
            b = SplineBasis(x, t, mode=mode)
            best = np.inf
            for _ in range(5):
                t0 = time.perf_counter()
                for _ in range(reps):
                    b.evaluate(P, needs)
                    b.pullback(*(g if k in needs else None for k in range(3)))
                best = min(best, (time.perf_counter() - t0) / reps)
            r[f"{mode}_us"] = 1e6 * best
        rows.append(r)
    return rows


def _worker(args) -> int:
    import solver.spline_basis as spline_basis

    if args.dense:  # the comparison run: dense matrices at every size
        spline_basis.DENSE_MAX_ENTRIES = 1 << 62
    d = np.load(args.worker)
    kf = Keyframes(d["times"], d["values"], d["mask"])
    print(json.dumps(solve_one(kf, Path(args.figure), args.rate)))
    return 0


def print_table(rows: list[dict], title: str) -> None:
    """The table: wall and CPU time, evaluations, CPU per evaluation, CPU per call of the objective
    (obj ms) and the solve's CPU time outside it (rest s: nlopt, the preconditioner, the setup), peak
    memory, each also relative to the first row; the result's penetration and keyframe error. CPU time
    (user + system of the solve) is the figure to compare on a shared machine: wall time includes
    waiting for a core."""
    base = rows[0]
    b_cpu_eval = base["cpu_s"] / max(1, base["evals"])
    b_obj = base["obj_cpu_s"] / max(1, base["obj_calls"])
    print(title)
    print(f"{'length':>6} {'keyfr':>5} {'frames':>6} {'points':>6} {'wall s':>7} {'cpu s':>6} {'evals':>5} {'checks':>6} "
          f"{'cpu ms/ev':>9} {'obj ms':>6} {'rest s':>6} {'peak MB':>7} | {'wall/1x':>7} {'cpu/1x':>6} {'ev/1x':>5} "
          f"{'ms/ev/1x':>8} {'obj/1x':>6} {'rest/1x':>7} {'mem/1x':>6} | {'pen mm':>6} {'kf err':>7} {'E_final':>7}  status")
    for r in rows:
        cpu_eval = r["cpu_s"] / max(1, r["evals"])
        obj = r["obj_cpu_s"] / max(1, r["obj_calls"])
        rest = r["cpu_s"] - r["obj_cpu_s"]
        print(f"{r['factor']:>5}x {r['keyframes']:>5} {r['frames']:>6} {r['points']:>6} {r['wall_s']:>7.2f} "
              f"{r['cpu_s']:>6.2f} {r['evals']:>5} {r['checks']:>6} {1e3 * cpu_eval:>9.2f} {1e3 * obj:>6.2f} {rest:>6.2f} "
              f"{r['peak_mb']:>7.1f} | {r['wall_s'] / base['wall_s']:>7.2f} {r['cpu_s'] / base['cpu_s']:>6.2f} "
              f"{r['evals'] / max(1, base['evals']):>5.2f} {cpu_eval / b_cpu_eval:>8.2f} {obj / b_obj:>6.2f} "
              f"{rest / max(base['cpu_s'] - base['obj_cpu_s'], 1e-9):>7.2f} "
              f"{r['peak_mb'] / max(base['peak_mb'], 1e-9):>6.2f} | {r['max_penetration_mm']:>6.3f} "
              f"{r['keyframe_error']:>7.0e} {r['E_final']:>7.4f}  {r['status']}{' banded' if r['banded'] else ''}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m runner.bench.scaling", description=__doc__.splitlines()[0])
    p.add_argument("--keyframes", type=Path, default=FIGURE.parent / "run_and_step.keyframes.json")
    p.add_argument("--figure", type=Path, default=FIGURE)
    p.add_argument("--factors", default="1,2,4,8")
    p.add_argument("--rate", type=float, default=None, help="quadrature points per second [the command's]")
    p.add_argument("--dense", action="store_true", help="also run with dense spline matrices at every size")
    p.add_argument("--repeat", type=int, default=3, help="solves per length, alternating; medians reported [3]")
    p.add_argument("--per-eval", action="store_true", help="only the spline's per-evaluation table")
    p.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        return _worker(args)
    if args.per_eval:
        sizes = ((64, 8), (200, 20), (400, 40), (700, 15), (700, 30), (1400, 60), (2800, 120), (5600, 240),
                 (11200, 480))
        for nq, needs in ((51, (0, 2)), (4, (0, 1, 2))):
            print(f"SplineBasis value + pullback, nq={nq}, orders {needs}, best of 5 [us]")
            print(f"{'points':>7} {'frames':>6} {'entries':>8} {'dense':>9} {'banded':>9} {'dense/banded':>12}")
            for r in per_eval_spline(sizes, nq, needs):
                print(f"{r['points']:>7} {r['frames']:>6} {r['entries']:>8} {r['dense_us']:>9.1f} "
                      f"{r['banded_us']:>9.1f} {r['dense_us'] / r['banded_us']:>12.2f}")
        return 0
    # the driver: the shipped clip, read as the command line reads it (runner is imported only here)
    import mujoco

    from solver.keyframe_file import read_keyframes

    # the keyframes, read against the figure alone: its feet name the contacts, whose surfaces are not this scene's
    keyframes, _ = read_keyframes(args.keyframes, mujoco.MjModel.from_xml_path(str(args.figure)))
    factors = [int(f) for f in args.factors.split(",")]
    print(f"scaling: {args.keyframes.name} ({keyframes.count} keyframes, {keyframes.times[-1] - keyframes.times[0]:.2f} s) "
          f"tiled {args.factors}x, floor-only scene, the command's least change (LeastChangeOptions"
          f"{'' if args.rate is None else f', quadrature {args.rate:g} Hz'}); one subprocess per length, one BLAS "
          "thread; peak MB = maxrss - RSS before the solve")
    runs = [(False, "spline: auto (dense up to DENSE_MAX_ENTRIES, banded above)"),
            (True, "spline: dense at every size (before)")][:1 + args.dense]
    for dense, title in runs:
        rows = scaling(keyframes, factors, dense=dense, figure=args.figure, rate=args.rate, repeat=args.repeat)
        if args.repeat > 1:
            title += f"; times and memory: median of {args.repeat} runs per length, the lengths alternating"
        print_table(median_rows(rows), title)
        if args.repeat > 1 and len(factors) > 1:
            top, base = factors[-1], factors[0]
            for key, what in (("cpu_s", "CPU time"), ("wall_s", "wall time")):
                ratios = repeat_ratios(rows, top, base, key)
                print(f"{what} {top}x / {base}x, run by run: {', '.join(f'{r:.2f}' for r in ratios)} "
                      f"(median {np.median(ratios):.2f}, min {min(ratios):.2f}, max {max(ratios):.2f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
