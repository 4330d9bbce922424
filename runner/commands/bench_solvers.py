"""`dynsplines bench solvers`: the optimizer back ends side by side, clip by clip, in one process.

Each input (run-and-step's keyframe file; BVH clips keyed every 0.25 s with their contacts and fitted
scene, as `dynsplines mocap CLIP --every 0.25 --scene auto` makes them) is solved with the geometric
terms, the default terms (with the contact terms) and `--terms all`, each by nlopt's L-BFGS and by
Levenberg-Marquardt (`--backend lm`), alternating, with the command's solve options. Printed per solve:
evaluations, CPU time (time.process_time, one BLAS thread for both), final E and the motion metrics (max penetration, and against
the motion capture: float and skate in contact, the flight time's error, joint-orientation error); per
pair the ratios LM / L-BFGS and whether every metric is within 2 % (or 0.2 mm, 0.002 s, 0.02 deg) of
L-BFGS's or better; at the end the acceptance verdicts (docs/solvers.md "Choosing the default").
"""
from __future__ import annotations

import os
import statistics
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from runner.animate_options import default_args, solve_options
from runner.commands.bench_contacts import input_problem
from runner.paths import MODELS
from runner.problem_file import RUN_AND_STEP_KEYFRAMES
from solver.bench.figure import GEOMETRIC
from solver.problem import make_problem

#: the clips the default back end is chosen on, and those it is checked on (not tuned on)
CHOOSE = ("127_33", "16_23", "35_17")
CHECK = ("75_03", "83_02", "07_04")
#: where clips not shipped in models/cmu are looked for (`--clips-dir`, or this environment variable)
CLIPS_ENV = "DYNSPLINES_CLIPS"
OBJECTIVES = ("geometric", "contacts", "all")
#: (label, key, format, absolute tolerance) of the motion metrics, lower is better: max penetration,
#: float and skate in contact, |flight time - the capture's|, mean joint-orientation error
METRICS = (("pen mm", "max_penetration_mm", "{:.2f}", 0.2), ("float mm", "float_contact_mm", "{:.2f}", 0.2),
           ("skate mm", "skate_contact_mm", "{:.2f}", 0.2), ("flight err s", "flight_error_s", "{:.3f}", 0.002),
           ("joint deg", "joint_deg", "{:.2f}", 0.02))


def register(bsub) -> None:
    """Add `bench solvers` to the `dynsplines bench` subparsers."""
    c = bsub.add_parser("solvers", help="nlopt L-BFGS against Levenberg-Marquardt, clip by clip",
                        description=__doc__.split("\n\n")[1].replace("\n", " "))
    c.add_argument("--clips", nargs="*", default=None, metavar="CLIP",
                   help="inputs: run-and-step, clip names (127_33, ...) or .bvh/.json paths "
                        f"[run-and-step {' '.join(CHOOSE + CHECK)}, those found]")
    c.add_argument("--clips-dir", type=Path, default=None,
                   help=f"folder of the CMU clips not shipped in models/cmu [${CLIPS_ENV}, else /work/shared/data/cmu]")
    c.add_argument("--objectives", default=",".join(OBJECTIVES),
                   help=f"comma-separated from {','.join(OBJECTIVES)} [%(default)s]")
    c.add_argument("--every", type=float, default=0.25, help="key spacing [s] for BVH clips [0.25]")
    c.add_argument("--rate", type=float, default=400.0, help="quadrature points per second [400]")
    c.set_defaults(func=bench_solvers)


def find_inputs(names, clips_dir: Path | None) -> tuple[list, list]:
    """(inputs [(label, path)], missing names): run-and-step's keyframe file, clips from models/cmu, then
    from `clips_dir` ($DYNSPLINES_CLIPS, else /work/shared/data/cmu); paths as given."""
    folder = Path(clips_dir or os.environ.get(CLIPS_ENV) or "/work/shared/data/cmu")
    found, missing = [], []
    for name in names:
        if name == "run-and-step":
            found.append((name, RUN_AND_STEP_KEYFRAMES))
            continue
        p = Path(name)
        candidates = [p] if p.suffix else [MODELS / "cmu" / f"{name}.bvh", folder / f"{name}.bvh"]
        hit = next((c for c in candidates if c.is_file()), None)
        (found.append((p.stem if p.suffix else name, hit)) if hit else missing.append(name))
    return found, missing


def _metrics(problem, solution, reference) -> dict:
    from runner.run import reference_motion_metrics
    from solver.metrics import path_metrics

    fs = solution.frames
    out = {"max_penetration_mm": path_metrics(problem.model, fs.times, fs.values, problem.keyframes,
                                              dynamics=False)["max_penetration_mm"]}
    if reference is not None and problem.contacts:
        mm = reference_motion_metrics(problem.model, solution, reference, problem.contacts)["optimized"]
        out.update({k: mm["path"][k] for k in ("float_contact_mm", "skate_contact_mm")})
        out["flight_error_s"] = abs(mm["path"]["flight_time_s"] - mm["reference"]["flight_time_s"])
        joints = mm["error"]["joint_orientation_deg"]
        out["joint_deg"] = float(statistics.fmean(v["mean"] for v in joints.values()))
    return out


def _solve(problem, options) -> dict:
    from threadpoolctl import threadpool_limits

    from solver.animate import solve_problem

    c0 = time.process_time()
    with threadpool_limits(1):  # as the lm back end runs: BLAS threads spinning would count as CPU time
        sol = solve_problem(problem, options)
    return {"cpu": time.process_time() - c0, "evals": sol.n_evals, "E": sol.E_final, "solution": sol}


def within(lm: float, ref: float, tol: float, higher_is_better: bool = False) -> bool:
    """True if the LM metric is within 2 % or `tol` of L-BFGS's, or better."""
    if lm != lm or ref != ref:  # NaN: no verdict to give
        return True
    better = lm >= ref if higher_is_better else lm <= ref
    return better or abs(lm - ref) <= max(0.02 * abs(ref), tol)


def bench_solvers(args) -> int:
    """Run `bench solvers`. Returns 0."""
    names = args.clips if args.clips else ["run-and-step", *CHOOSE, *CHECK]
    inputs, missing = find_inputs(names, args.clips_dir)
    objectives = [o.strip() for o in args.objectives.split(",") if o.strip()]
    print(f"bench solvers: {len(inputs)} input(s) ({', '.join(n for n, _ in inputs)}), objectives {', '.join(objectives)}; "
          f"nlopt L-BFGS and Levenberg-Marquardt (lm) alternating, the command's solve options; CPU = process time")
    if missing:
        print(f"  not found (skipped): {', '.join(missing)}")
    head = f"  {'input':<12} {'objective':<10} {'backend':<7} {'evals':>6} {'CPU s':>7} {'E':>11}  " + " ".join(
        f"{m[0]:>12}" for m in METRICS)
    print(head)
    rows = []
    with tempfile.TemporaryDirectory(prefix="dynsplines-bench-") as tmp:
        for label, path in inputs:
            base, source = input_problem(Path(path), args.every, Path(tmp), args.rate)
            for objective in objectives:
                terms = {"geometric": GEOMETRIC, "contacts": None, "all": "all"}[objective]
                if objective != "geometric" and not base.contacts:
                    continue
                problem = base if terms is None else make_problem(base.model, base.keyframes, terms,
                                                                  contacts=base.contacts, rate=args.rate)
                options = solve_options(default_args("penalty"), dict(problem.weights))
                runs = {}
                for backend in ("nlopt", "lm"):
                    run = _solve(problem, replace(options, backend=backend))
                    run["metrics"] = _metrics(problem, run["solution"], source.reference)
                    runs[backend] = run
                    print(f"  {label:<12} {objective:<10} {backend:<7} {run['evals']:>6} {run['cpu']:>7.2f} "
                          f"{run['E']:>11.5g}  " + " ".join(
                              f"{fmt.format(run['metrics'][k]):>12}" if k in run["metrics"] else f"{'-':>12}"
                              for _, k, fmt, _ in METRICS), flush=True)
                rows.append(_pair(label, objective, runs))
    _verdicts(rows)
    return 0


def _pair(label, objective, runs) -> dict:
    """The LM / L-BFGS ratios of one input and objective, printed."""
    a, b = runs["nlopt"], runs["lm"]
    ok = {k: within(b["metrics"][k], a["metrics"][k], tol) for _, k, _, tol in METRICS if k in a["metrics"]}
    ratio = b["cpu"] / max(a["cpu"], 1e-9)
    worse = [lab for lab, k, _, _ in METRICS if k in ok and not ok[k]]
    print(f"  {'':<12} {'':<10} {'lm/lbfgs':<7} {b['evals'] / max(a['evals'], 1):>6.2f} {ratio:>7.2f} "
          f"{b['E'] / a['E'] if a['E'] else float('nan'):>11.4f}  metrics "
          + ("all within 2 % or better" if not worse else "worse: " + ", ".join(worse)))
    return {"input": label, "objective": objective, "cpu_ratio": ratio, "metrics_ok": not worse}


def _verdicts(rows) -> None:
    """The acceptance verdicts of the issue (docs/solvers.md "Choosing the default")."""
    contact = [r for r in rows if r["objective"] == "contacts" and r["input"] != "run-and-step"]
    print("\n  verdicts (LM / L-BFGS CPU):")
    for name, group in (("chosen on", [r for r in contact if r["input"] in CHOOSE]),
                        ("checked on", [r for r in contact if r["input"] not in CHOOSE])):
        if group:
            ratios = [r["cpu_ratio"] for r in group]
            print(f"    contact solves, {name} {', '.join(r['input'] for r in group)}: median "
                  f"{statistics.median(ratios):.2f} (bound 0.25), max {max(ratios):.2f} (bound 0.5)")
    if contact:
        ratios = [r["cpu_ratio"] for r in contact]
        passed = statistics.median(ratios) <= 0.25 and max(ratios) <= 0.5
        print(f"    contact solves, all shared clips: {'met' if passed else 'not met'}")
    for r in rows:
        if r["input"] == "run-and-step" and r["objective"] == "all":
            print(f"    run-and-step --terms all: {r['cpu_ratio']:.2f} (bound 0.25): "
                  f"{'met' if r['cpu_ratio'] <= 0.25 else 'not met'}")
    bad = [f"{r['input']}/{r['objective']}" for r in rows if not r["metrics_ok"]]
    print(f"    motion metrics within 2 % of L-BFGS or better: {'all' if not bad else 'not for ' + ', '.join(bad)}")
