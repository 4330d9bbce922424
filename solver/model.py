"""`load_model(path)`: an MJCF scene as a MuJoCo model, with an InputError that names the file."""
from __future__ import annotations

import os
from pathlib import Path

from solver.errors import InputError


def load_model(path: str | os.PathLike):
    """MjModel from an MJCF file.

    Args:
        path: the MJCF file (a scene: the figure and the surfaces it meets).
    Returns:
        mujoco.MjModel.
    Raises:
        InputError: the file does not exist or MuJoCo cannot load it; the message names the file and
            says how to fix it (the `--scene` option of the commands).
    """
    import mujoco

    path = Path(path)
    if not path.is_file():
        raise InputError(f"scene file {path} does not exist; give an MJCF file with --scene")
    try:
        return mujoco.MjModel.from_xml_path(str(path))
    except ValueError as e:
        why = " ".join(line.strip() for line in str(e).splitlines() if line.strip())
        raise InputError(f"scene file {path} could not be loaded by MuJoCo: {why}") from None
