"""Where the repository's files are (a leaf): the checkout, its models and its renders."""
from __future__ import annotations

from pathlib import Path

from solver.figure import MODELS_DIR

REPO = Path(__file__).resolve().parents[1]
#: the shipped models (`solver.figure.MODELS_DIR`: the figure, the scenes, the example keyframes)
MODELS = MODELS_DIR
RENDERS = REPO / "renders"


def display_path(path) -> str:
    """`path` relative to the current directory if inside it, else to the repository, else absolute."""
    path = Path(path).resolve()
    for base in (Path.cwd(), REPO):
        try:
            return str(path.relative_to(base))
        except ValueError:
            continue
    return str(path)


def repo_relative(path) -> str:
    """`path` relative to the repository if inside it, else absolute (as stored in a saved path)."""
    path = Path(path).resolve()
    try:
        return str(path.relative_to(REPO))
    except ValueError:
        return str(path)
