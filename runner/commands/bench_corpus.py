"""`dynsplines bench corpus [CLIPS or FOLDERS] [--mode mocap|clean] [--every 0.2,0.25,0.33] [--keys every,contacts]
[--workers N] [--engine local|ray] [--out DIR]`: every (clip, keying) pair solved as `dynsplines mocap` solves it
and held to the acceptance bounds, tuning and validation clips apart (`runner.corpus.run_corpus`); with --mode
clean every clip cleaned as `dynsplines clean` cleans it and held to the clean's bounds beside the IK peer
(`runner.corpus_clean.run_clean_corpus`). This module is argument glue; docs/corpus.md."""
from __future__ import annotations

import argparse
from pathlib import Path

from runner.animate_options import add_solve_arguments, clip_terms
from runner.batch import ENGINES, find_clips
from runner.commands.mocap import add_figure_arguments, add_root_scale_argument
from runner.exit_codes import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK
from runner.parser import positive
from runner.paths import REPO

PROG = "dynsplines bench corpus"
MODES = ("mocap", "clean")
#: the output folder of each mode, without --out
DEFAULT_OUT = {"mocap": Path("renders") / "corpus", "clean": Path("renders") / "corpus-clean"}
#: the shipped corpus
CORPUS = REPO / "models" / "cmu"


def _type(parse):
    """An argparse type from a parser that raises ValueError with the whole message."""
    def convert(text):
        try:
            return parse(text)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None
    return convert


def register(bsub) -> None:
    """Add `bench corpus` to the `dynsplines bench` subparsers."""
    from runner.capture.scene import AUTO
    from runner.corpus import DEFAULT_EVERY, parse_every, parse_keys

    c = bsub.add_parser(
        "corpus", help="every (clip, keying) pair held to the acceptance bounds, tuning and validation apart",
        description="Solve every (clip, keying) pair as `dynsplines mocap` does (keys every S for each S of --every, "
                    "and --keys contacts), check each against the acceptance bounds (docs/corpus.md) and report a "
                    "held / not-held table per pair, the pass rate per bound and the failing pairs with a cause, for "
                    "the tuning clips (the defaults were chosen on them) and the validation clips apart. A batch "
                    "underneath: worker processes or Ray, resumable (a rerun skips the pairs already done). Writes "
                    "DIR/corpus.md, DIR/corpus.json and DIR/<clip>.<keying>/ per pair. Exit 0 when every pair ran "
                    "(whatever the bounds), 3 if one failed to run, 130 on Ctrl-C.")
    c.add_argument("clips", nargs="*", type=Path, metavar="CLIP_OR_FOLDER",
                   help=".bvh clips or folders of them [models/cmu/, the shipped corpus]")
    c.add_argument("--mode", choices=MODES, default="mocap",
                   help="mocap: the (clip, keying) pairs as `mocap` solves them; clean: each clip once as `clean` "
                        "cleans it, held to the clean's bounds (penetration, float, skate in contact, deviation and "
                        "CPU against the IK peer's, no new jolt) [%(default)s]")
    c.add_argument("--every", type=_type(parse_every), default=DEFAULT_EVERY, metavar="S,S,...",
                   help=f"key spacings [s] of the 'every' keying [{','.join(f'{v:g}' for v in DEFAULT_EVERY)}]")
    c.add_argument("--keys", type=_type(parse_keys), default=("every", "contacts"), metavar="every,contacts",
                   help="keyings: every (one pair per --every spacing), contacts (keys at the contact events) "
                        "[every,contacts]")
    c.add_argument("--workers", type=positive(int), default=1, metavar="N", help="pairs solved at once [%(default)s]")
    c.add_argument("--engine", choices=ENGINES, default="local",
                   help="local: processes on this machine; ray: Ray tasks (pip install -e \".[cluster]\") [%(default)s]")
    c.add_argument("--ray-address", default=None, metavar="ADDR", help="Ray cluster address for --engine ray")
    c.add_argument("--out", type=Path, default=None, metavar="DIR",
                   help="output folder [renders/corpus; with --mode clean renders/corpus-clean]")
    c.add_argument("--scene", default=AUTO, help="scene MJCF, or 'auto' (a scene fitted per clip) [auto]")
    add_figure_arguments(c)
    add_root_scale_argument(c)
    add_solve_arguments(c, terms_help="default")
    from runner.commands.clean import add_newton_argument

    add_newton_argument(c.add_argument_group("--mode clean"))
    c.add_argument("--quiet", action="store_true", help="no progress bar or per-pair lines")
    c.set_defaults(func=run)


def run(args) -> int:
    """Run `bench corpus`. Returns the exit code; raises InputError on bad input."""
    from runner.corpus import keyings, run_corpus
    from runner.pipeline import ClipOptions
    from solver.errors import InputError

    if args.ray_address is not None and args.engine != "ray":
        raise InputError(f"--ray-address {args.ray_address} goes with --engine ray")
    clips = find_clips(args.clips or [CORPUS])
    out = args.out if args.out is not None else DEFAULT_OUT[args.mode]
    say = (lambda *a: None) if args.quiet else print
    if args.mode == "clean":
        return _run_clean(args, clips, out, say)
    if args.gauss_newton:
        raise InputError("--gauss-newton: clean's option; --mode mocap keys the clips instead (add --mode clean, or drop it)")
    base = ClipOptions(scene=args.scene, figure=args.figure, mass=args.mass, root_scale=args.root_scale,
                       skeleton_map=args.skeleton_map, command=PROG,
                       **clip_terms(args))
    r = run_corpus(clips, out, keyings(args.keys, args.every), base, workers=args.workers, engine=args.engine,
                   ray_address=args.ray_address, say=say, quiet=args.quiet)
    print(r["markdown"])
    print(f"{PROG}: wrote {r['paths'][0]}, {r['paths'][1]}")
    if r["batch"]["interrupted"]:
        return EXIT_INTERRUPTED
    return EXIT_FAILED if r["batch"]["totals"]["counts"]["failed"] else EXIT_OK


def _run_clean(args, clips, out, say) -> int:
    """`bench corpus --mode clean`: `run_clean_corpus` with the clean's options; mocap's keying options refused."""
    from dataclasses import replace

    from runner.animate_options import solve_options
    from runner.clean import CleanOptions
    from runner.corpus import DEFAULT_EVERY
    from runner.corpus_clean import run_clean_corpus
    from solver.errors import InputError

    given = [name for name, v, default in (("--every", args.every, DEFAULT_EVERY), ("--keys", args.keys, ("every", "contacts")),
                                           ("--terms", args.terms, None)) if v != default]
    if given:
        raise InputError(f"{', '.join(given)}: mocap's keying options; --mode clean keeps every frame of the capture "
                         "(drop them, or use --mode mocap)")
    base = CleanOptions(scene=args.scene, figure=args.figure, mass=args.mass, root_scale=args.root_scale,
                        skeleton_map=args.skeleton_map, solve=replace(solve_options(args), newton=args.gauss_newton),
                        command=f"{PROG} --mode clean")
    r = run_clean_corpus(clips, out, base, workers=args.workers, engine=args.engine, ray_address=args.ray_address,
                         say=say, quiet=args.quiet)
    print(r["markdown"])
    print(f"{PROG}: wrote {r['paths'][0]}, {r['paths'][1]}")
    if r["batch"]["interrupted"]:
        return EXIT_INTERRUPTED
    return EXIT_FAILED if r["batch"]["totals"]["counts"]["failed"] else EXIT_OK
