"""`dynsplines bench ...`: speed measured, not asserted in tests.

    dynsplines bench run-and-step [--repeat N]
        the least change with the default constraints and with the force bounds (`--terms all`), side
        by side in one process: optimization wall and CPU time (median of N runs), evaluations, and the
        acceptance figures of the plain and the optimized path (the summary's rows, "worse" marked).
    dynsplines bench orient [--speed-random N]
        the single-body problem against the Barr-92 and constrained B-spline baselines (runner.bench.orient);
        with --speed-random N also the time to gap 1e-4 against Barr-92 on N generated sets.
    dynsplines bench orient --random N [--bvp] [--first-seed SEED]
        accuracy on request: true and estimated gap, frames, time and |q| drift of the default and
        tol=1e-4 over N generated keyframe sets (runner.bench.random_sets).
    dynsplines bench docs [--check [--exact]] [--only NAME,...] [--file docs/benchmarks.md]
        regenerate the measured tables of docs/benchmarks.md (between `<!-- bench:NAME -->` and
        `<!-- /bench:NAME -->`) from runs of the current code (runner/readme_tables.py); --check
        compares instead of writing and exits 1 when a table no longer matches (wall times, a solve's
        evaluation and frame counts and the figures inside a constraint's bound are not compared; other
        figures within 20 %; --exact: every figure as printed).
        `bench readme` is the same command under its former name.
    dynsplines bench speed [--baseline REV] [--repeat N] [--only mocap-default,run-and-step-all]
        the command line's default solves against a baseline commit, alternating runs in fresh
        processes: solve time, CPU and peak memory, the ratio and its bound (runner/commands/bench_speed.py).

The workloads are in runner/bench/; here: parse, load the showcase clip, call, format, print.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from runner.animate_options import default_args, solve_options
from runner.bench.figure import path_figures, time_solves
from runner.commands import bench_clean, bench_contacts, bench_corpus, bench_speed
from runner.console import LEGEND, comparison_rows, format_rows
from runner.paths import REPO
from runner.problem_file import RUN_AND_STEP_KEYFRAMES, file_problem, load_problem
from runner.readme_tables import WORSE, Block, compare_blocks, replace_blocks, table, timing
from solver.constraint_set import PENETRATION_TOLERANCE
from solver.constraints.forces import FORCE_TOLERANCE
from solver.constraints.unit import UNIT_LIMIT
from solver.errors import InputError
from solver.metrics import path_metrics

#: the keyframe sets of `bench orient` (runner/bench/sphere_reference/keyframe_sets.py)
DEFAULT_SETS = "large_uniform,large_nonuniform,large_nonuniform_b"


def register(sub) -> None:
    """Add `bench` (run-and-step, docs, orient, scaling, contacts, corpus, speed) to the `dynsplines` parser."""
    p = sub.add_parser("bench", help="benchmarks: run-and-step, docs, orient, scaling, contacts, corpus, speed, clean")
    bsub = p.add_subparsers(dest="bench", metavar="BENCH")
    bsub.required = True
    r = bsub.add_parser("run-and-step", help="optimization time of the showcase clip, default and --terms all")
    r.add_argument("--repeat", type=int, default=3, help="runs per configuration; the median is reported [3]")
    r.set_defaults(func=bench_run_and_step)
    m = bsub.add_parser("docs", aliases=["readme"], help="regenerate (or --check) docs/benchmarks.md's measured tables",
                        description="Regenerate the measured tables of docs/benchmarks.md (between <!-- bench:NAME "
                        "--> markers) from runs of the current code; --check compares instead (wall times, a "
                        "solve's evaluation and frame counts and the figures inside a constraint's bound "
                        "excepted, other figures within 20 %).")
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
    c = bsub.add_parser("scaling", help="cost against clip length: run-and-step's gait tiled 1x..8x (or a clean's)",
                        description="The shipped clip's keyframes tiled end to end (root carried forward) on a "
                        "floor-only scene: optimization time, evaluations, time per evaluation and peak memory "
                        "of each length, one subprocess per length (runner.bench.scaling, docs/scaling.md). With "
                        "--mode clean: `dynsplines clean` of the first 1/8, 2/8, 4/8 and all of one real "
                        "capture (or, with --loop, a shipped clip looped forward and backward 1x..8x), its CPU "
                        "time per length (runner.bench.clean_scaling).")
    c.add_argument("--mode", choices=("animate", "clean"), default="animate",
                   help="animate: the keyframes' solve; clean: a capture cleaned [%(default)s]")
    c.add_argument("--clip", type=Path, default=None,
                   help="with --mode clean: the BVH clip [models/long/zombie.bvh; with --loop models/cmu/16_23.bvh]")
    c.add_argument("--loop", action="store_true",
                   help="with --mode clean: the clip looped forward and backward instead of its prefixes")
    c.add_argument("--factors", default="1,2,4,8", help="lengths, as multiples of the clip [1,2,4,8]")
    c.add_argument("--rate", type=float, default=None, help="quadrature points per second [the command's]")
    c.add_argument("--dense", action="store_true", help="also run with dense spline matrices at every length")
    c.add_argument("--per-eval", action="store_true", help="only the per-evaluation table, dense vs banded: the spline's "
                   "(--mode animate) or D's preconditioner on a clean's grid (--mode clean)")
    c.add_argument("--repeat", type=int, default=None,
                   help="solves per length, the lengths alternating; the table gives medians [3; --mode clean 1]")
    c.set_defaults(func=bench_scaling)
    bench_contacts.register(bsub)
    bench_corpus.register(bsub)
    bench_speed.register(bsub)
    bench_clean.register(bsub)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the options of `dynsplines bench orient` to a parser."""
    p.add_argument("--sets", default=DEFAULT_SETS,
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
    from runner.bench import orient as orient_workload  # scipy.interpolate and .optimize: only for this bench

    sets = args.sets
    if args.tradeoff and sets == DEFAULT_SETS:
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


def run_and_step_problems() -> dict:
    """{name: Problem} that `bench run-and-step` times: "default" and "all" (with the force bounds), each
    exactly what `dynsplines run-and-step [--terms all]` solves (`runner.problem_file.file_problem`)."""
    return {terms: file_problem(RUN_AND_STEP_KEYFRAMES, terms=terms)[0] for terms in ("default", "all")}


def bench_run_and_step(args) -> int:
    """`dynsplines bench run-and-step`: print the optimization time of the showcase clip. Returns 0."""
    import statistics

    problems = run_and_step_problems()
    keyframes = problems["default"].keyframes
    options = solve_options(default_args())  # exactly what `dynsplines run-and-step` runs
    print(f"bench run-and-step: {keyframes.count} keyframes, {args.repeat} runs per configuration, alternating, "
          f"the command's problem and solve options (the least change, quadrature {options.rate:g} Hz)")
    runs = {name: [] for name in problems}
    for _ in range(max(1, args.repeat)):  # alternate, so load on the machine hits both alike
        for name, problem in problems.items():
            runs[name].append(time_solves(problem, options, 1))
    for name, rs in runs.items():
        walls, cpus = [r["wall_median_s"] for r in rs], [r["cpu_median_s"] for r in rs]
        print(f"  --terms {name:<8} optimization {statistics.median(walls):.2f} s wall median (runs: "
              f"{', '.join(f'{w:.2f}' for w in walls)}), {statistics.median(cpus):.2f} s CPU, "
              f"{rs[-1]['evals']} evaluations, {rs[-1]['frames']} frames at the end")
        print_figures(problems[name].model, keyframes, rs[-1]["solution"], forces=problems[name].forces)
    print(f"  {LEGEND}")
    return 0


def print_figures(model, keyframes, solution, forces: bool = False, indent: str = "  ") -> None:
    """The acceptance figures of the plain spline and of an optimized path (the summary's rows, marked
    where the optimized path is worse), so a benchmark run tracks what the time bought."""
    plain = path_metrics(model, solution.initial.times, solution.initial.values, keyframes)
    opt = path_metrics(model, solution.frames.times, solution.frames.values, keyframes)
    for line in format_rows(comparison_rows(plain, opt, dynamics_terms=forces)):
        print(indent + line)


# ----------------------------------------------------------------- docs/benchmarks.md tables
#: the measured tables of docs/benchmarks.md, in the order they are made: name -> what it shows
README_TABLES = {
    "terms-all": "run-and-step, plain spline vs `--terms all` (the least change with the force bounds)",
    "run-and-step": "bench run-and-step: the least change with and without the force bounds, evaluations and times",
}


class _Runs:
    """The showcase clip's runs, made once and shared by the tables (the command's problem and options)."""

    def __init__(self):
        self.keyframes, info, self.model, self.layout, _ = load_problem(RUN_AND_STEP_KEYFRAMES, None)
        self._solved = {}

    def solved(self, terms: str) -> dict:
        """The solve of `run-and-step --terms TERMS` ("default" or "all")."""
        if terms not in self._solved:
            problem = file_problem(RUN_AND_STEP_KEYFRAMES, terms=terms)[0]
            r = time_solves(problem, solve_options(default_args()), 1)
            r["figures"] = path_figures(self.model, self.keyframes, r["solution"])
            self._solved[terms] = r
        return self._solved[terms]


def _kf_error(v: float) -> str:
    return "< 1e-12" if v < 1e-12 else f"{v:.1e}"  # round-off differs between machines


def _terms_all_block(runs: _Runs) -> Block:
    r = runs.solved("all")
    f = r["figures"]
    p, o = f["plain"], f["optimized"]
    worse = {label: flag for label, _, _, _, flag in comparison_rows(p, o, dynamics_terms=True)}

    def mark(*labels):
        return WORSE if any(worse.get(label) for label in labels) else ""

    def pair(key_rms, key_peak, fmt, d):
        return f"{fmt.format(d[key_rms])} / {fmt.format(d[key_peak])}"

    def geometry(d):
        return f"{_kf_error(d['keyframe_error'])} / {d['max_hyperextension_deg']:.2f}"

    rows = [
        # the optimized penetration and |q| sit inside their constraints' bounds, and where in them the solve
        # stops follows the machine's round-off (penetration 0.73 and 1.26 mm on two machines, max |1 - |q||
        # 0.0075 and 0.0101 under two BLAS kernels): machine-dependent, as a wall time
        [f"max penetration [mm] (the constraint's tolerance: {PENETRATION_TOLERANCE * 1e3:g} mm)", f"{p['max_penetration_mm']:.2f}",
         timing(f"{o['max_penetration_mm']:.2f}" + mark("max penetration [mm] (1000 Hz)"))],
        [f"max \\|1-\\|q\\|\\| (the constraint's limit: {UNIT_LIMIT:g})", f"{p['max_norm_deviation']:.4f}",
         timing(f"{o['max_norm_deviation']:.4f}" + mark("max |1 - |q||"))],
        ["keyframe error / hyperextension [deg]", geometry(p), geometry(o) + mark("max hyperextension [deg]")],
        ["RMS / peak joint torque [N m]", pair("rms_joint_torque_Nm", "peak_joint_torque_Nm", "{:.1f}", p),
         pair("rms_joint_torque_Nm", "peak_joint_torque_Nm", "{:.1f}", o)
         + mark("RMS joint torque [N m]", "peak joint torque [N m]")],
        ["flight (all four contact sites clear) [s]", f"{p['flight_s']:.3f}",
         f"{o['flight_s']:.3f}" + mark("flight (all feet clear) [s]")],
        # the flight wrench constraint drives these to 0 within its tolerance; where in it the solve stops
        # follows the round-off (peak root torque 20.7 and 24.7 N m under two BLAS kernels): machine-dependent
        [f"RMS / peak root force in flight [N] (body weight: {f['body_weight_N']:.0f} N; the constraint: 0, "
         f"tolerance {FORCE_TOLERANCE:.0%} of it)",
         pair("rms_root_force_flight_N", "peak_root_force_flight_N", "{:.1f}", p),
         timing(pair("rms_root_force_flight_N", "peak_root_force_flight_N", "{:.1f}", o)
                + mark("RMS root force in flight [N]", "peak root force in flight [N]"))],
        ["RMS / peak root torque in flight [N m] (the constraint: 0)",
         pair("rms_root_torque_flight_Nm", "peak_root_torque_flight_Nm", "{:.1f}", p),
         timing(pair("rms_root_torque_flight_Nm", "peak_root_torque_flight_Nm", "{:.1f}", o)
                + mark("RMS root torque in flight [N m]", "peak root torque in flight [N m]"))],
        # inside the no-jolt bound of the pelvis (16.6 m/s^2, the capture's 6 Hz peak), where the solve stops in it
        # follows the round-off (12.4 and 16.5 m/s^2 under two BLAS kernels): machine-dependent
        ["peak pelvis acceleration [m/s^2]", f"{p['peak_pelvis_acceleration_ms2']:.1f}",
         timing(f"{o['peak_pelvis_acceleration_ms2']:.1f}" + mark("peak pelvis acceleration [m/s^2]"))],
        ["RMS / peak root force on the ground [body weights]",
         pair("rms_root_force_ground_bw", "peak_root_force_ground_bw", "{:.2f}", p),
         pair("rms_root_force_ground_bw", "peak_root_force_ground_bw", "{:.2f}", o)
         + mark("RMS root force on ground [body wt]", "peak root force on ground [body wt]")],
        ["optimization", "", timing(f"{f['variable']} variable frames, {f['evals']} evaluations, {f['wall_s']:.0f} s")],
    ]
    return Block("terms-all", table(["", "plain spline", "optimized (`--terms all`)"], rows))


def _run_and_step_block(runs: _Runs) -> Block:
    rows = []
    for name, terms in (("the constraints (default)", "default"), ("and the force bounds (`--terms all`)", "all")):
        f = runs.solved(terms)["figures"]
        # where the solve stops, so its change E, follows the CPU's round-off: with the force bounds a limit
        # is out of reach (raised by the least violation, `Solution.certificate`); without them two kernels
        # stop after different refinement rounds (docs/solvers.md "Known limitation"): 0.65 here, 0.70
        # under OpenBLAS's Sandybridge kernels
        E = f"{f['E_final']:.3g}"
        rows.append([name, timing(str(f["evals"])), timing(str(f["frames"])), timing(E), timing(f"{f['wall_s']:.1f}")])
    header = ["the least change with", "evaluations", "frames at the end", "change E at the end", "optimization [s]"]
    return Block("run-and-step", table(header, rows))


_MAKERS = {"terms-all": _terms_all_block, "run-and-step": _run_and_step_block}


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
    runs = _Runs()
    blocks = []
    for n in names:
        print(f"bench docs: {n}: {README_TABLES[n]} ...", flush=True)
        blocks.append(_MAKERS[n](runs))
    if args.check:
        problems = compare_blocks(path, blocks, exact=args.exact)
        for p in problems:
            print(p)
        rule = "every figure as printed" if args.exact else "other figures within 20 %"
        print(f"bench docs --check: {len(blocks) - len(problems)} of {len(blocks)} tables match {path} "
              f"(wall times, evaluation and frame counts, figures inside a constraint's bound not compared; {rule})")
        return 1 if problems else 0
    replace_blocks(path, blocks)
    print(f"bench docs: wrote {', '.join(b.name for b in blocks)} in {path}")
    return 0


def bench_scaling(args) -> int:
    """`dynsplines bench scaling`: runner.bench.scaling's table for the given lengths."""
    from runner.bench import scaling

    repeat = args.repeat if args.repeat is not None else 1 if args.mode == "clean" else 3
    if repeat < 1:
        raise InputError(f"--repeat must be at least 1, got {repeat}")
    if args.mode == "clean":
        return _clean_scaling(args, repeat)
    if args.clip is not None or args.loop:
        what = f"--clip {args.clip}" if args.clip is not None else "--loop"
        raise InputError(f"{what} goes with --mode clean (--mode animate tiles run_and_step's keyframes)")
    argv = ["--factors", args.factors, "--repeat", str(repeat)]
    argv += [] if args.rate is None else ["--rate", str(args.rate)]
    argv += ["--dense"] * args.dense + ["--per-eval"] * args.per_eval
    return scaling.main(argv)


def _clean_per_eval(clip: Path, factors: list[int]) -> int:
    """`bench scaling --mode clean --per-eval`: D's preconditioner on a clean's grid, dense against banded, on the
    first f/max(factors) of the clip's retargeted capture (`runner.bench.clean_scaling.preconditioner_rows`)."""
    import tempfile

    from runner.bench import clean_scaling
    from runner.clean import CleanOptions, _capture

    with tempfile.TemporaryDirectory(prefix="dynsplines-per-eval-") as tmp:
        cs, contacts, _ = _capture(clip, CleanOptions(render=False, quiet=True), Path(tmp) / "scene.xml", lambda *_: None)
    ref = cs.reference
    print(f"clean per evaluation: {clip.name}, its first {','.join(map(str, factors))} / {max(factors)} of "
          f"{ref.count} frames; D's preconditioner on the clean's grid, built and applied in this process (CPU)")
    try:
        clean_scaling.print_preconditioner_rows(clean_scaling.preconditioner_rows(cs.model, ref.times, ref.qpos, contacts, factors))
    except ValueError as e:
        raise InputError(f"--clip {clip}: {e}; give a longer clip or smaller --factors") from None
    return 0


def _clean_scaling(args, repeat: int) -> int:
    """`bench scaling --mode clean`: runner.bench.clean_scaling's table."""
    from runner.bench import clean_scaling

    if args.rate is not None or args.dense:
        raise InputError("--rate and --dense go with --mode animate (the keyframes' solve)")
    clip = args.clip or (clean_scaling.LOOP_CLIP if args.loop else clean_scaling.PREFIX_CLIP)
    if not Path(clip).is_file():
        raise InputError(f"--clip {clip}: no such BVH clip (current folder: {Path.cwd()})")
    try:
        factors = [int(f) for f in args.factors.split(",")]
    except ValueError:
        raise InputError(f"--factors {args.factors}: give whole numbers separated by commas, e.g. 1,2,4,8") from None
    if min(factors) < 1:
        raise InputError(f"--factors {args.factors}: every factor must be at least 1")
    if args.per_eval:
        return _clean_per_eval(Path(clip), factors)
    if not args.loop:
        try:
            clean_scaling.prefix_frames(Path(clip), factors)
        except ValueError as e:
            raise InputError(f"--clip {e}; give a longer clip or smaller --factors") from None
    argv = ["--clip", str(clip), "--factors", args.factors, "--repeat", str(repeat)]
    return clean_scaling.main(argv + ["--loop"] * args.loop)
