"""The `dynsplines` command line: builds the parser from every subcommand and maps exceptions to exit codes.

Each subcommand lives in its own module of runner/commands/ with `register(subparsers)`, which adds its
parser and sets `func` to a function(args) -> exit code. No algorithm here.

Exit codes: runner/exit_codes.py (0 success, 1 internal error, 2 bad input, 3 failed partway, 130 Ctrl-C).
A user mistake prints one line, "dynsplines: error: ...", never a traceback; --debug shows it.
"""
from __future__ import annotations

import argparse
import faulthandler
import sys

from runner.commands.animate import register as register_animate
from runner.commands.batch import register as register_batch
from runner.commands.bench import register as register_bench
from runner.commands.blender_addon import register as register_blender_addon
from runner.commands.clean import register as register_clean
from runner.commands.export import register as register_export
from runner.commands.fig10 import register as register_fig10
from runner.commands.keyframes_from_bvh import register as register_keyframes_from_bvh
from runner.commands.mocap import register as register_mocap
from runner.commands.orient import register as register_orient
from runner.commands.view import register as register_view
from runner.exit_codes import EXIT_FAILED, EXIT_INPUT, EXIT_INTERNAL, EXIT_INTERRUPTED
from runner.parser import OneLineParser
from solver.errors import DynsplinesError, InputError
from solver.objective import NonFiniteError

#: every subcommand's `register`, in the order of `dynsplines --help`
SUBCOMMANDS = (register_animate, register_mocap, register_clean, register_batch, register_keyframes_from_bvh, register_export,
               register_view, register_bench, register_orient, register_blender_addon, register_fig10)


def build_parser() -> argparse.ArgumentParser:
    """The `dynsplines` parser with every subcommand."""
    parser = OneLineParser(
        prog="dynsplines",
        description="Dynamic splines with constraints for animation: keyframes in, optimized in-betweens out.",
    )
    parser.set_defaults(debug=False)  # `--debug` itself: OneLineParser, before or after the subcommand
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=OneLineParser)
    sub.required = True
    for register in SUBCOMMANDS:
        register(sub)
    return parser


def _crash_tracebacks() -> None:
    """A crash in native code (a segmentation fault in a GL driver, say) prints every thread's Python
    stack to stderr (`faulthandler`) before the process dies, so that a report says where it was; left
    alone where it is already on (pytest) or stderr has no file descriptor."""
    if not faulthandler.is_enabled():
        try:
            faulthandler.enable()
        except (OSError, ValueError):  # a captured stderr without fileno()
            pass


def main(argv: list[str] | None = None) -> int:
    """Run the command line. Returns the exit code (see the module docstring)."""
    _crash_tracebacks()
    argv = sys.argv[1:] if argv is None else argv
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # --help (0) or a usage error (2, its message already printed)
        return e.code if isinstance(e.code, int) else EXIT_INPUT
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
    except NonFiniteError as e:  # on the plain spline itself: nothing to optimize from, nothing written
        if args.debug:
            raise
        print(f"dynsplines: error: {e} on the plain spline through the keyframes, before any optimization; "
              "nothing was written (check the keyframes' values and the scene; --debug shows where)", file=sys.stderr)
        return EXIT_FAILED
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
