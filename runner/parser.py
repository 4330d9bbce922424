"""Argument parsing pieces shared by the subcommands (a leaf): `OneLineParser` and bounded number types."""
from __future__ import annotations

import argparse
import difflib
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

    def parse_args(self, args=None, namespace=None):
        """As argparse's, but arguments no parser knows are reported by the subcommand that was given
        (its prog and its --help), with the nearest option of that subcommand for a mistyped one
        (`dynsplines mocap clip.bvh --evry 0.25`: "did you mean --every?")."""
        namespace, extras = self.parse_known_args(args, namespace)
        if extras:
            parser = self.chosen_subcommand(namespace)
            message = f"unrecognized arguments: {' '.join(extras)}"
            near = parser.nearest_option(extras)
            parser.error(f"{message}; did you mean {near}?" if near else message)
        return namespace

    def chosen_subcommand(self, namespace) -> OneLineParser:
        """The innermost parser of the subcommand (and sub-subcommand, e.g. `bench corpus`) chosen in
        `namespace`; this parser when none was."""
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                chosen = action.choices.get(getattr(namespace, action.dest, None) or "")
                if isinstance(chosen, OneLineParser):
                    return chosen.chosen_subcommand(namespace)
        return self

    def nearest_option(self, extras) -> str | None:
        """This parser's long option nearest to the first unknown option among `extras` (`--name` or
        `--name=value`) by difflib's similarity ratio (at least 0.6, its default cutoff), or None."""
        options = [s for a in self._actions for s in a.option_strings if s.startswith("--")]
        for word in extras:
            if word.startswith("--"):
                near = difflib.get_close_matches(word.split("=", 1)[0], options, n=1)
                return near[0] if near else None
        return None


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
