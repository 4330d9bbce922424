"""Argument parsing pieces shared by the subcommands (a leaf): `OneLineParser` and bounded number types."""
from __future__ import annotations

import argparse
import math

from runner.exit_codes import EXIT_INPUT


class OneLineParser(argparse.ArgumentParser):
    """An ArgumentParser whose usage errors are one line (and the --help hint), exit code 2, and which
    accepts `--debug` (show the full traceback on errors) wherever it stands: before the subcommand or
    after it (`dynsplines animate FILE --debug`). The top-level parser sets its default (False);
    a subcommand's `--debug` only ever sets it."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        if self.add_help:  # every parser the command line builds (not argparse's internal ones)
            self.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                              help="show the full traceback on errors")

    def error(self, message):
        self.exit(EXIT_INPUT, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def _bounded(kind, ok, requirement: str):
    noun = "a whole number" if kind is int else "a number"

    def parse(text: str):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {noun}") from None
        if not (math.isfinite(v) and ok(v)):
            raise argparse.ArgumentTypeError(f"{text!r} must be {requirement}")
        return v

    return parse


def positive(kind=float):
    """argparse type: a finite number > 0 of type `kind` (float or int)."""
    return _bounded(kind, lambda v: v > 0, "> 0")


def nonnegative(kind=float):
    """argparse type: a finite number >= 0 of type `kind` (float or int)."""
    return _bounded(kind, lambda v: v >= 0, ">= 0")


def positive_or(word: str):
    """argparse type: the text `word` itself, or a number > 0 (e.g. `--root-scale legs|1`)."""
    number = positive(float)

    def parse(text: str):
        return text if text == word else number(text)

    return parse
