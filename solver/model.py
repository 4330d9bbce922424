"""`load_model(path)`: an MJCF scene as a MuJoCo model, with an InputError that names the file;
`check_scene(model, path)`: what the figure tools need of a scene (free root, contact sites, a surface)."""
from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

from solver.errors import InputError

#: what a scene file needs, said in every message about a scene that lacks it
SCENE_HELP = ("start from models/floor.xml (models/README.md, 'Writing a scene')")


def _missing_includes(path: Path) -> list[str]:
    """The `<include file=...>` of an MJCF file (recursively) that do not exist, as written in the file.

    MuJoCo resolves every include against the folder of the main file."""
    missing: list[str] = []
    seen: set[Path] = set()

    def walk(f: Path) -> None:
        if f in seen:
            return
        seen.add(f)
        try:
            root = ET.parse(f).getroot()
        except (ET.ParseError, OSError):
            return  # MuJoCo reports it
        for inc in root.iter("include"):
            name = inc.get("file")
            if not name:
                continue
            target = Path(name) if Path(name).is_absolute() else path.parent / name
            if target.is_file():
                walk(target)
            else:
                missing.append(name)

    walk(path)
    return missing


def load_model(path: str | os.PathLike):
    """MjModel from an MJCF file.

    Args:
        path: the MJCF file (a scene: the figure and the surfaces it meets).
    Returns:
        mujoco.MjModel.
    Raises:
        InputError: the file does not exist (for a relative path naming a shipped scene, the message
            says where that is: `solver.shipped`), it includes a file that is not there (MuJoCo resolves
            includes against the scene's folder: a copy of a scene saved elsewhere loses the figure),
            or MuJoCo cannot load it; the message names the file and says how to fix it.
    """
    import mujoco

    path = Path(path)
    if not path.is_file():
        from solver.shipped import shipped_hint

        raise InputError(f"scene file {path} does not exist{shipped_hint(path)}; give an MJCF file with --scene")
    missing = _missing_includes(path)
    if missing:
        name = missing[0]
        raise InputError(
            f"scene {path} includes {name}, which is not in {path.parent.resolve()} (MuJoCo looks for "
            f"included files in the scene's folder); write the figure's absolute path in <include file=...> "
            f"or copy {Path(name).name} next to the scene"
        )
    try:
        return mujoco.MjModel.from_xml_path(str(path))
    except ValueError as e:
        why = " ".join(line.strip() for line in str(e).splitlines() if line.strip())
        raise InputError(f"scene file {path} could not be loaded by MuJoCo: {why}") from None


def check_scene(model, path: str | os.PathLike) -> None:
    """Check that a scene has what the figure tools need, when it is loaded (not later, in a term).

    Needs: the figure (one free root joint, and its feet: the contact sites the figure's MJCF names,
    `solver.figure.Figure`) and at least one static plane or box on the world body (the floor the
    penetration term keeps feet out of).

    Raises:
        InputError: naming the scene file, what is missing and the fix.
    """
    from solver.figure import FIGURE_FILE, Figure
    from solver.layout import StateLayout
    from solver.surfaces import StaticSurfaces

    layout = StateLayout.from_model(model)
    if not any(j.kind == "free" for j in layout.joints):
        raise InputError(f"scene {path} has no free joint: does it include the figure ({FIGURE_FILE.name})? "
                         f"{SCENE_HELP[0].upper()}{SCENE_HELP[1:]}")
    try:
        Figure.from_model(model)
    except InputError as e:
        raise InputError(f"scene {path}: {e}. Does it include the figure ({FIGURE_FILE.name})? "
                         f"{SCENE_HELP[0].upper()}{SCENE_HELP[1:]}") from None
    if StaticSurfaces.from_model(model).count == 0:
        raise InputError(
            f"scene {path} has no static floor plane or box (a plane or box geom of the world body) for the "
            f"feet to stand on; use models/floor.xml (the figure on a flat floor), or add "
            f'<geom type="plane" size="0 0 0.05"/> to the scene\'s <worldbody>'
        )
