"""`shipped(name)`: the path of a file shipped with dynsplines (the figure, the scenes, the example keyframe
files, the CMU clips), whatever the current folder; and `shipped_hint(path)`, the hint the file readers add
when a relative path such as ``models/run_and_step.xml`` is not found from the current folder.

The files live beside the code (`solver.figure.MODELS_DIR`: in a checkout solver/models links to the
top-level models/, and an installation copies them), so ``solver.shipped("run_and_step.xml")`` works from
any folder, where ``"models/run_and_step.xml"`` works from the checkout's root only.
"""
from __future__ import annotations

import os
from pathlib import Path

from solver.errors import InputError
from solver.figure import MODELS_DIR

__all__ = ["shipped", "shipped_hint"]


def _inside(name: str | os.PathLike) -> Path:
    """`name` relative to the models folder: a leading ``models/`` (the checkout's spelling) dropped."""
    parts = Path(name).parts
    return Path(*parts[1:]) if len(parts) > 1 and parts[0] == "models" else Path(name)


def shipped(name: str | os.PathLike = "") -> Path:
    """The absolute path of a shipped file.

    Args:
        name: the file's name inside models/, e.g. "run_and_step.xml", "run_and_step.keyframes.json",
            "cmu/127_33.bvh"; a leading "models/" is accepted ("models/run_and_step.xml"); "" gives the
            folder itself.
    Returns:
        Path of the file (or folder), which exists.
    Raises:
        InputError: `name` is absolute or no such file is shipped; the message lists the files that are.
    """
    if Path(name).is_absolute():
        raise InputError(f"shipped({str(name)!r}): give a name inside the shipped models folder, e.g. "
                         "shipped('run_and_step.xml'), not an absolute path")
    path = MODELS_DIR / _inside(name)
    if not path.exists():
        folder = path.parent if path.parent.is_dir() else MODELS_DIR
        names = sorted(p.name for p in folder.iterdir() if not p.name.startswith((".", "_")))
        raise InputError(f"shipped({str(name)!r}): no such shipped file in {folder}; the files there: "
                         f"{', '.join(names)}")
    return path


def shipped_hint(path: str | os.PathLike) -> str:
    """For a relative `path` that does not exist from the current folder but names a shipped file: the
    sentence saying where it is (``"; the shipped models/run_and_step.xml is solver.shipped(...)..."``);
    else ""."""
    path = Path(path)
    if path.is_absolute() or path.exists() or str(path) in ("", "."):
        return ""
    inside = _inside(path)
    if not (MODELS_DIR / inside).is_file():
        return ""
    return (f" (relative to the current folder {Path.cwd()}); the shipped {path} is "
            f"{MODELS_DIR / inside}: in Python solver.shipped({str(inside)!r}) gives it from any folder")
