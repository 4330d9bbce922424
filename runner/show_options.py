"""`ShowOptions`: how a clip's run is shown (its video and its console), shared by `mocap` and `clean`.

`runner.pipeline.ClipOptions` (`dynsplines mocap`, `batch`) and `runner.clean.CleanOptions` (`dynsplines
clean`, `batch --mode clean`) both extend it, so the video and console options are defined once and read
the same way by both (`o.fps`, `dataclasses.replace(o, quiet=True)`), and a batch's options fingerprint
(`runner.batch.options_fingerprint`) stays the flat dict of their fields.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["ShowOptions"]


@dataclass(frozen=True)
class ShowOptions:
    """The video and console options of a clip's run.

    Attributes:
        render: write the video. fps: [1/s] video frames per second. size: (width, height) [px].
            speed: playback speed (motion seconds per video second). camera: [deg] where the camera stands
            around the figure from straight ahead (`runner.render.side_by_side.VideoOptions`).
        quiet: no progress bars (results are still printed). summary: print the summary tables.
        command: the command line, recorded with the outputs.
    """

    render: bool = True
    fps: float = 30.0
    size: tuple[int, int] = (960, 540)
    speed: float = 0.5
    camera: float = 90.0
    quiet: bool = False
    summary: bool = True
    command: str = ""
