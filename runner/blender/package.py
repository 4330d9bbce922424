"""`write_addon_zip`: the add-on's files (runner/blender/addon/) packed as a Blender extension zip, the
form Blender 4.2+ installs (Edit > Preferences > Get Extensions > Install from Disk, or
`bpy.ops.extensions.package_install_files`): `blender_manifest.toml` and the package's modules at the
top of the archive."""
from __future__ import annotations

import os
import zipfile
from pathlib import Path

from runner.files import atomic_output
from solver.errors import InputError

#: the add-on's folder (package data of runner.blender.addon)
ADDON_DIR = Path(__file__).resolve().parent / "addon"
#: the files of the add-on that go into the zip (no caches)
ADDON_FILES = ("blender_manifest.toml", "__init__.py", "actions.py", "job.py")


def write_addon_zip(out: str | os.PathLike) -> Path:
    """Write the add-on as an extension zip to `out` (atomically). Returns the path.

    Raises:
        InputError: `out` does not end in .zip, or its folder does not exist.
    """
    out = Path(out)
    if out.suffix.lower() != ".zip":
        raise InputError(f"--out {out}: the add-on is a .zip file (Blender installs extensions from a zip); "
                         f"give e.g. --out {out.with_suffix('.zip').name}")
    if not out.parent.is_dir():
        raise InputError(f"--out {out}: the folder {out.parent} does not exist; create it first")
    with atomic_output(out) as tmp, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        for name in ADDON_FILES:
            z.write(ADDON_DIR / name, name)
    return out
