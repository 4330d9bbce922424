"""`dynsplines export PATH.npz --to FILE.bvh|FILE.glb [--fps N] [--which optimized|plain|reference]
[--skeleton source|figure]`."""
from __future__ import annotations

from pathlib import Path

from runner.parser import positive

__all__ = ["register", "run"]


def register(sub) -> None:
    """Add the `export` subcommand to argparse subparsers `sub`."""
    from runner.export.sampling import DEFAULT_FPS, WHICH

    p = sub.add_parser("export", help="write a saved path as BVH or glTF (.glb)",
                       description="Sample a saved path (.npz from --save-path) and write it as a BVH clip (.bvh: on the "
                                   "skeleton of the clip the path came from, else on the figure's own) or as an "
                                   "animated glTF binary with the scene (.glb).")
    p.add_argument("path", type=Path, help="saved path (.npz written by --save-path)")
    p.add_argument("--to", type=Path, required=True, metavar="FILE", help="output file: FILE.bvh or FILE.glb")
    p.add_argument("--fps", type=positive(float), default=None,
                   help=f"samples per second [the reference clip's rate, else {DEFAULT_FPS:g}]")
    p.add_argument("--which", choices=WHICH, default="optimized", help="which motion to export [%(default)s]")
    p.add_argument("--skeleton", choices=("source", "figure"), default=None,
                   help="BVH skeleton: 'source' the clip's own (hierarchy, names, offsets, channels, frame rate; the "
                        "default for a path made from a BVH clip), 'figure' the figure's 12 bodies plus neck and head")
    p.add_argument("--root-height", choices=("source", "solved"), default="source",
                   help="on the source skeleton: 'source' the root height in the clip's own coordinates (the "
                        "import's correction that stood the feet on the scene taken off: the file replaces the "
                        "source); 'solved' as the solve left it, the feet on the scene's surfaces (the Blender "
                        "add-on's clean) [%(default)s]")
    p.add_argument("--quiet", action="store_true", help="no summary line")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run `export`; returns the exit code (0). Errors are InputError (the caller prints one line)."""
    from runner.export import check_output_name, export_saved_path

    res = None
    as_solved = getattr(args, "root_height", "source") == "solved"  # the figure's skeleton: always as solved
    if args.skeleton == "source" or (args.skeleton is None and check_output_name(args.to) == "BVH"):
        from runner.capture.source_export import export_on_source

        res = export_on_source(args.path, args.to, args.which, args.fps, required=args.skeleton == "source",
                               as_solved=as_solved)
    if res is None:
        res = export_saved_path(args.path, args.to, args.which, args.fps)
    if not getattr(args, "quiet", False):
        print(f"dynsplines: wrote {res.describe()}")
        if res.check is not None:
            for what, figures in res.check.lines():
                print(f"  {what} read back from {res.path.name}: {figures}")
        for note in res.notes:
            print(f"  {note}")
    return 0
