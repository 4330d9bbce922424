"""`python -m runner.fig10` and `dynsplines fig10`: figure 10 of the paper for a keyframe file
(runner/figure10.py), written as a PNG, and its numbers printed."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from runner.exit_codes import EXIT_INPUT, EXIT_OK
from runner.figure10 import figure10, format_table
from runner.orient_file import read_keyframes
from runner.paths import MODELS
from solver.errors import InputError

DEFAULT_KEYFRAMES = MODELS / "orient_example.json"
DEFAULT_OUT = Path("renders") / "fig10_euler_lagrange.png"  # in the current folder
DESCRIPTION = "Figure 10 of the paper: Euler-Lagrange deviation integrated over tenths of the path."


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The arguments of the command."""
    p.add_argument("keyframes", nargs="?", default=str(DEFAULT_KEYFRAMES), metavar="KEYFRAMES.json")
    p.add_argument("--out", default=str(DEFAULT_OUT), metavar="FILE.png")


def register(sub) -> None:
    """Add `fig10` to the `dynsplines` parser."""
    p = sub.add_parser("fig10", help="figure 10 of the paper for orientation keyframes (PNG and numbers)",
                       description=DESCRIPTION)
    add_arguments(p)
    p.set_defaults(func=run)


def run(args) -> int:
    """Write the figure and print its numbers. Returns 0; raises InputError on bad input."""
    times, quats = read_keyframes(args.keyframes)
    rows = figure10(times, quats, args.out, source=args.keyframes)
    print(f"wrote {args.out}")
    print(format_table(rows))
    return EXIT_OK


def main(argv: list[str] | None = None) -> int:
    """`python -m runner.fig10`: write the figure and print its numbers. Returns the exit code."""
    p = argparse.ArgumentParser(prog="python -m runner.fig10", description=DESCRIPTION)
    add_arguments(p)
    args = p.parse_args(argv)
    try:
        return run(args)
    except InputError as e:
        print(f"fig10: error: {e}", file=sys.stderr)
        return EXIT_INPUT
