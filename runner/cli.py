"""The `dynsplines` command line: parses arguments and calls library functions; no algorithm here.

Each subcommand lives in its own module with `register(subparsers)`, which adds its parser and sets
`func` to a function(args) -> exit code.

Exit codes:
    0   success (also when --max-time ended the optimization: the best path so far is written)
    1   internal error (a bug: please report it with the --debug traceback)
    2   bad input (a file, field or option); the message says what and how to fix it
    3   the optimization failed partway (a non-finite objective or gradient, named by term, or an
        optimizer failure); the best path before it (it meets every keyframe) and the outputs were written
    130 interrupted (Ctrl-C); the best path so far and the requested outputs were written (a second
        Ctrl-C aborts at once and writes nothing; Ctrl-C while rendering leaves any earlier video as it was)

A user mistake prints one line, "dynsplines: error: ...", never a traceback; --debug shows it.
"""
from __future__ import annotations

import argparse
import sys

from solver.errors import DynsplinesError, InputError

EXIT_OK = 0
EXIT_INTERNAL = 1
EXIT_INPUT = 2
EXIT_FAILED = 3
EXIT_INTERRUPTED = 130


class OneLineParser(argparse.ArgumentParser):
    """An ArgumentParser whose usage errors are one line (and the --help hint), exit code 2."""

    def error(self, message):
        self.exit(EXIT_INPUT, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


_Parser = OneLineParser


def build_parser() -> argparse.ArgumentParser:
    from runner import animate, bench

    parser = _Parser(
        prog="dynsplines",
        description="Dynamic splines with constraints for animation: keyframes in, optimized in-betweens out.",
    )
    parser.add_argument("--debug", action="store_true", help="show the full traceback on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    animate.register(sub)
    _register_keyframes_from_bvh(sub)
    bench.register(sub)
    for optional in ("orient",):  # subcommands added by their own modules when present
        try:
            module = __import__(f"runner.{optional}_cmd", fromlist=["register"])
        except ModuleNotFoundError:
            continue
        module.register(sub)
    return parser


def _register_keyframes_from_bvh(sub) -> None:
    p = sub.add_parser("keyframes-from-bvh", add_help=False,
                       help="make a keyframe file from a BVH motion-capture clip (see --help)")
    p.add_argument("args", nargs=argparse.REMAINDER)

    def run(args):
        from runner.bvh_import import keyframes_from_bvh_main

        return keyframes_from_bvh_main(args.args, prog="dynsplines keyframes-from-bvh", debug=args.debug)

    p.set_defaults(func=run)


def main(argv: list[str] | None = None) -> int:
    """Run the command line. Returns the exit code (see the module docstring)."""
    argv = sys.argv[1:] if argv is None else argv
    parser = build_parser()
    head, tail = argv, None
    if "keyframes-from-bvh" in argv:  # its own parser reads everything after it (also --help, --out first)
        i = argv.index("keyframes-from-bvh")
        if all(a == "--debug" for a in argv[:i]):
            head, tail = argv[: i + 1], argv[i + 1:]
    try:
        args = parser.parse_args(head)
    except SystemExit as e:  # --help (0) or a usage error (2, its message already printed)
        return e.code if isinstance(e.code, int) else EXIT_INPUT
    if tail is not None:
        args.args = tail
    try:
        return int(args.func(args) or 0)
    except InputError as e:
        if args.debug:
            raise
        print(f"dynsplines: error: {e}", file=sys.stderr)
        return EXIT_INPUT
    except KeyboardInterrupt:
        if args.debug:
            raise
        print("dynsplines: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except DynsplinesError as e:
        if args.debug:
            raise
        print(f"dynsplines: error: {e}", file=sys.stderr)
        return EXIT_INTERNAL
    except Exception as e:  # noqa: BLE001 - a bug; say so, show the traceback with --debug
        if args.debug:
            raise
        print(f"dynsplines: internal error: {type(e).__name__}: {e}\n(run again with --debug for the "
              "traceback, and please report it)", file=sys.stderr)
        return EXIT_INTERNAL
