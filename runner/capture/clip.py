"""A motion-capture clip read once per run: the `Capture` value every step of `mocap` takes.

`read_capture` checks and parses the BVH file (`runner.capture.bvh.read_bvh`: the HIERARCHY, channels,
offsets and every frame's local rotations and translations) and keeps the file's text (the export onto the
source skeleton copies its HIERARCHY and rest frames). The figure, the scene fit, the retargeting, the
contacts and stance, the keys and the way back (runner/capture/source_export.py) all take this value, so a
run parses its clip once; the way back still reads the file it *writes* (runner/capture/source_check.py).
The roles, unit, up axis and rest frames are recognised from it (`runner.capture.figure_record.clip_skeleton`),
the repairs are the `Reference`'s (runner/capture/reference_motion.py).
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from runner.capture.bvh import BvhClip, read_bvh
from solver.errors import InputError

__all__ = ["Capture", "read_capture", "as_capture"]


@dataclass(frozen=True)
class Capture:
    """A BVH clip as read from its file (`read_capture`).

    Attributes:
        clip: the parse (`runner.capture.bvh.BvhClip`: J joints, n frames with the file's rest frames, file
            units and axes).
        text: the file's whole text (as read; the export onto the source skeleton copies its HIERARCHY).
    """

    clip: BvhClip
    text: str

    @property
    def source(self) -> str:
        """The file the clip was read from, as given."""
        return self.clip.source


def read_capture(path: str | os.PathLike) -> Capture:
    """Read and parse a BVH file once (`read_bvh`, then its text).

    Raises:
        InputError: the file is missing, unreadable or malformed (`read_bvh`: the message names the line).
    """
    clip = read_bvh(path)
    try:
        text = Path(path).read_text(encoding="utf-8-sig")  # without a byte-order mark, as read_bvh
    except (OSError, UnicodeDecodeError) as e:  # read a moment ago by read_bvh: only a file changed meanwhile
        raise InputError(f"{path}: cannot read the BVH clip again ({e}); check the file") from None
    return Capture(clip, text)


def as_capture(clip: str | os.PathLike | Capture) -> Capture:
    """`clip` itself if it is a `Capture`, else the file it names read (`read_capture`): the functions of a
    run take the run's Capture; a path is read for callers that have one file and one use for it."""
    return clip if isinstance(clip, Capture) else read_capture(clip)
