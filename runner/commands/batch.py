"""`dynsplines batch CLIP_OR_FOLDER... --out DIR [--mode mocap|clean]`: `mocap` (or `clean`) over many clips, in
worker processes, resumable, with a summary (the work is `runner.batch.run_batch`; this module is argument glue)."""
from __future__ import annotations

from pathlib import Path

from runner.animate_options import add_solve_arguments
from runner.batch import ENGINES, find_clips, run_batch
from runner.commands.clean import add_newton_argument, add_pin_arguments, pins_of
from runner.commands.mocap import add_clip_arguments, clip_options
from runner.exit_codes import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK
from runner.parser import positive
from solver.errors import InputError

PROG = "dynsplines batch"
MODES = ("mocap", "clean")
#: the options of `mocap`'s keyframes that `--mode clean` has no use for (it keeps every frame of the capture),
#: with their defaults: one given with --mode clean is an error, not silently dropped
KEYING = {"keys": "every", "every": None, "partial": False, "key_frames": None, "key_joints": None, "boxes": None,
          "terms": None}


def register(sub) -> None:
    """Add `batch` to the `dynsplines` parser."""
    p = sub.add_parser(
        "batch", help="mocap (or clean) over many clips: worker processes, resumable, a summary table",
        description="Run `dynsplines mocap` (or with --mode clean `dynsplines clean`) on every clip given (or every "
                    ".bvh in the folders given), in worker processes. Outputs: DIR/<clip stem>/ per clip (mocap: "
                    "keyframes, scene, .npz, metrics JSON; clean: <stem>.clean.npz, .bvh, .glb, .metrics.json; and "
                    "done.json) and DIR/summary.csv, DIR/summary.json (a row per clip and a totals row). A rerun "
                    "skips the clips already done with the same clip file and options. A bad clip is reported "
                    "with its error and the others go on. Exit code 0 if every clip is ok, 3 if any failed, "
                    "130 on Ctrl-C (no new clips started; the summary of what finished is written).")
    p.add_argument("clips", nargs="+", type=Path, metavar="CLIP_OR_FOLDER", help=".bvh clips or folders of them")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    p.add_argument("--mode", choices=MODES, default="mocap",
                   help="mocap: keyframes and new in-betweens (`dynsplines mocap`); clean: every frame of the capture "
                        "kept, the least displacement that fixes the feet (`dynsplines clean`; its summary gives the "
                        "penetration, float, skate, deviation from the capture and the change's peak accelerations) "
                        "[%(default)s]")
    p.add_argument("--workers", type=positive(int), default=1, metavar="N",
                   help="clips processed at once (worker processes, one BLAS thread each; with --engine ray: Ray tasks "
                        "in flight, and a local Ray's CPUs) [%(default)s]")
    p.add_argument("--engine", choices=ENGINES, default="local",
                   help="local: processes on this machine; ray: Ray tasks, one CPU per clip (needs "
                        "pip install -e \".[cluster]\") [%(default)s]")
    p.add_argument("--ray-address", default=None, metavar="ADDR",
                   help="Ray cluster address for --engine ray [a local Ray, or RAY_ADDRESS]")
    add_clip_arguments(p)
    pins = p.add_argument_group("pins (--mode clean)")
    add_pin_arguments(pins, each="; the same for every clip, and a pin outside a clip is that clip's error")
    add_newton_argument(pins)
    p.add_argument("--render", action="store_true",
                   help="also render each clip's video (off by default in a batch: rendering is slow)")
    add_solve_arguments(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar or per-clip lines")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run `batch`. Returns the exit code; raises InputError on bad input."""
    if args.ray_address is not None and args.engine != "ray":
        raise InputError(f"--ray-address {args.ray_address} goes with --engine ray")
    if args.mode != "clean" and (args.pin or args.pin_ends or args.gauss_newton):
        names = ", ".join(n for n, given in (("--pin", args.pin), ("--pin-ends", args.pin_ends),
                                             ("--gauss-newton", args.gauss_newton)) if given)
        raise InputError(f"{names}: clean's options; --mode mocap keys the clip instead (add --mode clean, or drop them)")
    clips = find_clips(args.clips)
    options = clean_options(args) if args.mode == "clean" else clip_options(args, PROG, render=args.render)
    say = (lambda *a: None) if args.quiet else print
    r = run_batch(clips, args.out, options, workers=args.workers, engine=args.engine,
                  ray_address=args.ray_address, say=say, quiet=args.quiet)
    t = r["totals"]
    print(f"dynsplines batch: {t['status']} in {r['wall_time_s']:.1f} s; wrote {r['summary'][0]}, {r['summary'][1]}")
    if r["interrupted"]:
        return EXIT_INTERRUPTED
    return EXIT_FAILED if t["counts"]["failed"] else EXIT_OK


def clean_options(args):
    """`CleanOptions` of the parsed arguments (`--mode clean`): the pins, scene, figure, root scale, skeleton map,
    the solve options, --render.

    Raises:
        InputError: a keying option (`KEYING`) given with --mode clean.
    """
    import shlex
    import sys
    from dataclasses import replace

    from runner.animate_options import solve_options
    from runner.clean import CleanOptions

    given = [k for k, default in KEYING.items() if getattr(args, k) != default]
    if given:
        names = ", ".join("--" + k.replace("_", "-") for k in given)
        raise InputError(f"{names}: mocap's keying options; --mode clean keeps every frame of the capture (drop them, "
                         "or use --mode mocap)")
    return CleanOptions(pins=pins_of(args), pin_ends=args.pin_ends, scene=args.scene, figure=args.figure,
                        mass=args.mass, root_scale=args.root_scale, skeleton_map=args.skeleton_map,
                        solve=replace(solve_options(args), newton=args.gauss_newton), render=args.render, quiet=True,
                        summary=False, command=f"{PROG} {shlex.join(sys.argv[2:])}" if sys.argv[1:2] == ["batch"] else PROG)
