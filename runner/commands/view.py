"""`dynsplines view PATH.npz [--port N]`: serve a page that plays the saved path (runner/viewer)."""
from __future__ import annotations

from pathlib import Path

from runner.parser import nonnegative

__all__ = ["register", "run"]


def register(sub) -> None:
    """Add the `view` subcommand to argparse subparsers `sub`."""
    p = sub.add_parser("view", help="play a saved path in the browser (local page on 127.0.0.1)",
                       description="Serve a page on 127.0.0.1 that plays a saved path in its scene: timeline "
                                   "(play/pause, scrub, speed), plain / optimized / reference motions, keyframe "
                                   "ghosts, contact sites highlighted (green: in contact, red: penetrating). "
                                   "Ctrl-C stops the server.")
    p.add_argument("path", type=Path, help="saved path (.npz written by --save-path)")
    p.add_argument("--port", type=nonnegative(int), default=8000, help="port; 0 for a free one [%(default)s]")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run `view` until Ctrl-C; returns the exit code (0). Errors are InputError."""
    from runner.viewer.server import build_assets, serve

    if args.port > 65535:
        from solver.errors import InputError

        raise InputError(f"--port {args.port}: a port is 0..65535; e.g. --port 8000, or 0 for a free one")
    assets = build_assets(args.path)
    try:
        serve(assets, args.port, ready=lambda url: print(f"dynsplines: viewing {args.path} at {url} "
                                                          "(Ctrl-C to stop)", flush=True))
    except KeyboardInterrupt:
        print()
    return 0
