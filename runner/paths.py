"""Where the shipped files are (a leaf): the models (figure, scenes, keyframes, the CMU clip) beside the
code, in a checkout (solver/models links to the top-level models/) and in an installed copy alike.
Outputs never go here: they go where the user is (the commands' defaults are relative to the current
folder)."""
from __future__ import annotations

from pathlib import Path

from solver.figure import MODELS_DIR

PACKAGE = Path(__file__).resolve().parent
#: the shipped models: figure, scenes, keyframe files and the CMU clip (`solver.figure.MODELS_DIR`)
MODELS = MODELS_DIR
#: the checkout, when running from one (README, benchmarks' documents); in an installed copy a folder
#: without them
REPO = PACKAGE.parent


def display_path(path) -> str:
    """`path` as the user would type it: relative to the current folder when inside it, else absolute."""
    path = Path(path)
    absolute = path.resolve() if path.is_absolute() or path.exists() else (Path.cwd() / path)
    try:
        return str(absolute.relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path if path.is_absolute() else absolute)
