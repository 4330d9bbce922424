"""`dynsplines blender-addon --out FILE.zip`: write the Blender add-on (runner/blender/) as an
installable extension zip."""
from __future__ import annotations

from pathlib import Path

from runner.exit_codes import EXIT_OK


def register(sub) -> None:
    """Add `blender-addon` to the `dynsplines` parser."""
    p = sub.add_parser("blender-addon", help="write the Blender add-on (an extension zip to install in Blender)",
                       description="Write the Blender add-on as an extension zip (Blender 4.2+: Edit > Preferences > "
                                   "Get Extensions > Install from Disk). In the 3D viewport's sidebar (tab "
                                   "dynsplines) it solves the active armature's action with this `dynsplines` "
                                   "command: in-betweens of the keyed frames, or a capture cleaned.")
    p.add_argument("--out", type=Path, required=True, metavar="FILE.zip", help="the zip to write")
    p.set_defaults(func=run)


def run(args) -> int:
    """Write the zip; returns 0. Raises InputError on a bad --out."""
    from runner.blender.package import write_addon_zip

    out = write_addon_zip(args.out)
    print(f"dynsplines: wrote {out} (the Blender add-on; install it from Edit > Preferences > Get Extensions > "
          "Install from Disk, and set the path of this dynsplines command in its preferences if it is not on PATH)")
    return EXIT_OK
