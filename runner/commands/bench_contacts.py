"""`dynsplines bench contacts`: what the contact constraints cost and buy, clip by clip, in one run.

For each input (a keyframe file with a contact schedule, or a BVH clip whose keyframes, contacts and
fitted scene are made as `dynsplines mocap CLIP --every 0.25 --scene auto` makes them), the same
keyframes are solved as the least change without a contact schedule (no planted feet, no swing or
flight clearance: "geometric") and with the input's schedule ("contacts"), alternating, `--repeat`
times each, with the command's solve options. Printed per input: evaluations and optimization time of
both (CPU time of the process, and wall, split into the time inside the objective and the optimizer's
own work: nlopt's L-BFGS costs O(n k) per iteration for k stored pairs) and their ratio on CPU time
(CPU time, because wall time on a shared machine counts waiting for a core) and on
objective time (what the ratio would be if the optimizer's own work were free), and
the motion metrics against the motion capture (float, skate, skating ratio, flight, flight extra /
missed, joint and site error) of the plain spline and both paths.
"""
from __future__ import annotations

import statistics
import tempfile
from pathlib import Path

from runner.animate_options import default_args, solve_options
from runner.bench.figure import time_solves
from runner.problem_file import RUN_AND_STEP_KEYFRAMES, file_problem
from solver.errors import InputError
from solver.metrics import path_metrics
from solver.problem import ProblemSpec, build_problem

#: (label, key in the motion metrics' "path" block, format)
ROWS = (("float in contact [mm]", "float_contact_mm", "{:.2f}"), ("skate in contact [mm/frame]", "skate_contact_mm", "{:.2f}"),
        ("skating ratio (contacts)", "skating_ratio_contacts", "{:.3f}"), ("flight [s]", "flight_time_s", "{:.3f}"))


def register(bsub) -> None:
    """Add `bench contacts` to the `dynsplines bench` subparsers."""
    c = bsub.add_parser("contacts", help="the contact constraints' cost and effect, clip by clip",
                        description=__doc__.split("\n\n")[1].replace("\n", " "))
    c.add_argument("inputs", nargs="*", type=Path,
                   help="keyframe files (.json, with 'contacts') or BVH clips [run-and-step's keyframe file]")
    c.add_argument("--repeat", type=int, default=1, help="solves per configuration; medians reported [1]")
    c.add_argument("--every", type=float, default=0.25, help="key spacing [s] for BVH clips [0.25]")
    c.set_defaults(func=bench_contacts)


def input_problem(path: Path, every: float, tmp: Path):
    """(problem, source) of a keyframe file (as `dynsplines animate FILE` solves it) or a BVH clip (as
    `dynsplines mocap CLIP --every EVERY --scene auto` solves it, its files written under `tmp`)."""
    if path.suffix.lower() == ".bvh":
        from runner.pipeline import ClipOptions, clip_problem

        out = tmp / path.stem
        out.mkdir(parents=True, exist_ok=True)
        paths = {"keyframes": out / f"{path.stem}.keyframes.json", "scene": out / f"{path.stem}.scene.xml"}
        problem, source, _ = clip_problem(path, out, ClipOptions(every=every, quiet=True), paths,
                                          say=lambda *a: None)
        return problem, source
    return file_problem(path)


def bench_contacts(args) -> int:
    """Run `bench contacts`. Returns 0; raises InputError for an input without contacts."""
    from runner.run import reference_motion_metrics

    inputs = args.inputs or [RUN_AND_STEP_KEYFRAMES]
    print(f"bench contacts: {len(inputs)} input(s), {args.repeat} solve(s) per configuration, the command's "
          "solve options; geometric = the least change without a contact schedule, contacts = with the input's")
    ratios = []
    with tempfile.TemporaryDirectory(prefix="dynsplines-bench-") as tmp:
        for path in inputs:
            base, source = input_problem(Path(path), args.every, Path(tmp))
            model, keyframes, contacts, ref = base.model, base.keyframes, base.contacts, source.reference
            if not contacts:
                raise InputError(f"{path}: no contact schedule ('contacts'); make the keyframes with "
                                 "`dynsplines mocap` or give a BVH clip")
            bare = ProblemSpec(keyframes, (), base.forces, base.capture, base.airborne)
            configs = {"geometric": build_problem(model, bare), "contacts": base}
            runs = {name: [] for name in configs}
            for _ in range(max(1, args.repeat)):  # alternate, so load on the machine hits both alike
                for name, problem in configs.items():
                    options = solve_options(default_args())
                    runs[name].append(time_solves(problem, options, 1))
            fields = ("cpu_median_s", "evals", "wall_median_s", "objective_s", "optimizer_s")
            med = {n: {k: statistics.median(r[k] for r in rs) for k in fields} for n, rs in runs.items()}
            ratio = med["contacts"]["cpu_median_s"] / med["geometric"]["cpu_median_s"]
            ratios.append(ratio)
            print(f"\n  {Path(path).name}: {keyframes.count} keyframes, {len(contacts)} contacts")
            for n, m in med.items():
                print(f"    {n:<10} {m['evals']:>6.0f} evaluations  {m['cpu_median_s']:7.2f} s CPU ({m['wall_median_s']:.2f} s "
                      f"wall: objective {m['objective_s']:.2f} s, optimizer {m['optimizer_s']:.2f} s)  "
                      f"({runs[n][-1]['frames']} frames)")
            ev_ratio = med["contacts"]["evals"] / med["geometric"]["evals"]
            obj_ratio = med["contacts"]["objective_s"] / max(med["geometric"]["objective_s"], 1e-12)
            print(f"    contacts / geometric: CPU time {ratio:.2f}x, evaluations {ev_ratio:.2f}x, objective time "
                  f"{obj_ratio:.2f}x (the CPU ratio if the optimizer's own work were free)")
            plain_fs = runs["geometric"][-1]["solution"].initial
            geo = [path_metrics(model, fs.times, fs.values, keyframes, dynamics=False) for fs in
                   (plain_fs, runs["geometric"][-1]["solution"].frames, runs["contacts"][-1]["solution"].frames)]
            print("    max penetration [mm] / keyframe error / max |1-|q|| / hyperextension [deg]: "
                  + "; ".join(f"{lab} {g['max_penetration_mm']:.2f} / {g['keyframe_error']:.0e} / "
                              f"{g['max_norm_deviation']:.4f} / {g['max_hyperextension_deg']:.2f}"
                              for lab, g in zip(("plain", "geometric", "contacts"), geo, strict=True)))
            if ref is None:
                continue
            motion = {n: reference_motion_metrics(model, rs[-1]["solution"], ref, contacts) for n, rs in runs.items()}
            print(f"    {'':<28} {'capture':>8} {'plain':>8} {'geometric':>10} {'contacts':>9}")
            for label, key, fmt in ROWS:
                vals = [motion["geometric"]["plain"]["reference"][key], motion["geometric"]["plain"]["path"][key],
                        motion["geometric"]["optimized"]["path"][key], motion["contacts"]["optimized"]["path"][key]]
                print(f"    {label:<28} " + " ".join(f"{fmt.format(v):>{w}}" for v, w in zip(vals, (8, 8, 10, 9), strict=True)))
            errs = [motion["geometric"]["plain"]["error"], motion["geometric"]["optimized"]["error"],
                    motion["contacts"]["optimized"]["error"]]
            print(f"    {'flight extra / missed [s]':<28} {'':>8} " + " ".join(
                f"{e['flight_extra_s']:.3f}/{e['flight_missed_s']:.3f}".rjust(w) for e, w in zip(errs, (8, 10, 9), strict=True)))
            for label, key in (("joint-orientation error [deg]", "joint_orientation_deg"), ("site position error [cm]", "site_position_cm")):
                vals = [_mean_of_means(motion["geometric"]["plain"]["error"][key]),
                        _mean_of_means(motion["geometric"]["optimized"]["error"][key]),
                        _mean_of_means(motion["contacts"]["optimized"]["error"][key])]
                print(f"    {label:<28} {'':>8} " + " ".join(f"{v:>{w}.2f}" for v, w in zip(vals, (8, 10, 9), strict=True)))
    if len(ratios) > 1:
        print(f"\n  CPU time ratio contacts / geometric: median {statistics.median(ratios):.2f}x, max {max(ratios):.2f}x "
              f"over {len(ratios)} inputs (bound 2x)")
    return 0


def _mean_of_means(d: dict) -> float:
    """The mean over joints (or sites) of each one's mean error."""
    return float(statistics.fmean(v["mean"] for v in d.values()))
