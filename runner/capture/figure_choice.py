"""`--figure subject|default|FILE.xml`: which figure a clip is retargeted onto, and a given scene with it.

* ``subject`` (the default of `mocap`, `batch` and `keyframes-from-bvh`): the subject's own figure,
  made from the clip's HIERARCHY (runner/capture/subject_figure.py) and written next to the outputs as
  ``<stem>.figure.xml``;
* ``default``: the shipped figure (models/humanoid39.xml), whose proportions are fixed (the root path is
  then scaled by `--root-scale`, runner/capture/reference_motion.py);
* a file: any figure MJCF with the shipped figure's bodies, joints, sites and annotations.

A fitted scene (`--scene auto`) includes the chosen figure. A given scene includes its own figure; with
another figure chosen, a copy of the scene whose figure `<include>` names the chosen one is written
next to the outputs (`scene_with_figure`).
"""
from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

from solver.errors import InputError
from solver.figure import FIGURE_FILE

__all__ = ["SUBJECT", "DEFAULT", "FIGURE_CHOICES", "is_default", "choose_figure", "figure_include",
           "scene_with_figure"]

SUBJECT, DEFAULT = "subject", "default"
FIGURE_CHOICES = (SUBJECT, DEFAULT)
#: MJCF elements whose `file` attribute names another file, resolved against the scene's folder
_FILE_ELEMENTS = ("include", "mesh", "texture", "hfield", "skin", "model")


def is_default(figure) -> bool:
    """True if `figure` ("default", or a path) is the shipped figure."""
    if str(figure) == DEFAULT:
        return True
    return str(figure) != SUBJECT and Path(figure).resolve() == FIGURE_FILE.resolve()


def choose_figure(figure, clip, out: Path, mass: float | None = None, skeleton_map=None) -> Path:
    """The figure MJCF file for `--figure` value `figure` (module docstring).

    Args:
        figure: "subject", "default" or a path. clip: the run's `runner.capture.clip.Capture`, or the BVH
            file (read here for "subject"). out: where a subject figure is written.
        mass: [kg] the subject's body mass (None: from the stature; only for "subject").
        skeleton_map: a `runner.capture.skeleton_map.SkeletonMap` naming roles the recogniser cannot find
            (None: none; only for "subject").
    Returns:
        the figure file.
    Raises:
        InputError: a figure file that does not exist; with "subject", a clip that cannot be read, whose
            skeleton cannot be recognised or has a degenerate OFFSET (file and joint named).
    """
    if str(figure) == SUBJECT:
        from runner.capture.clip import as_capture
        from runner.capture.subject_figure import write_subject_figure

        return write_subject_figure(as_capture(clip).clip, out, mass, skeleton_map)
    if mass is not None:
        raise InputError(f"--mass {mass:g}: only the subject's figure (--figure subject) takes a body mass; "
                         f"the figure {figure} has its own masses")
    if is_default(figure):
        return FIGURE_FILE
    path = Path(figure)
    if not path.is_file():
        raise InputError(f"--figure {figure}: no such file (current folder: {Path.cwd()}); give 'subject', "
                         "'default' or a figure MJCF file")
    return path


def figure_include(scene) -> Path | None:
    """The figure file the scene MJCF `scene` includes (an `<include file=...>` of a file with the
    figure's annotations), resolved; None if it holds the figure inline or cannot be read."""
    from runner.saved_path import scene_figure

    found = scene_figure(scene)
    return Path(found) if found else None


def scene_with_figure(scene, figure, out) -> Path:
    """`scene` if it already includes `figure`, else a copy of it written to `out` whose figure include
    names `figure` (relative to `out`'s folder) and whose other file references are absolute.

    Raises:
        InputError: the scene cannot be parsed, or holds its figure inline (no include to replace).
    """
    scene, figure, out = Path(scene), Path(figure).resolve(), Path(out)
    current = figure_include(scene)
    if current == figure:
        return scene
    try:
        tree = ET.parse(scene)
    except (OSError, ET.ParseError) as e:
        raise InputError(f"{scene}: cannot read the scene ({e}); give an MJCF file") from None
    if current is None:
        raise InputError(f"{scene}: the scene holds its figure inline (no <include file=...> of a figure), so "
                         f"the figure {figure} cannot replace it; give --figure default or include the figure")
    for el in tree.getroot().iter():
        if el.tag in _FILE_ELEMENTS and el.get("file"):
            target = (scene.parent / el.get("file")).resolve()
            if el.tag == "include" and target == current:
                el.set("file", Path(os.path.relpath(figure, out.parent.resolve())).as_posix())
            else:
                el.set("file", str(target))
    if not out.parent.is_dir():
        raise InputError(f"{out}: the folder {out.parent} does not exist; create it first")
    from runner.files import atomic_output

    with atomic_output(out, suffix=".xml") as tmp:
        tree.write(tmp, encoding="unicode")
    return out
