"""The H.264 encoder of the side-by-side video: frames are composed and piped to ffmpeg in a background
thread, so that the next frame's OpenGL rendering (which releases the GIL) overlaps them."""
from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable

import imageio.v2 as iio
import numpy as np

X264_PRESET = "ultrafast"
"""x264 speed preset. "ultrafast" takes about a third of the CPU time of "veryfast" on these videos
(flat colours, a checker floor, thin text); with `X264_CRF` its picture is as close to the rendered
frames as "veryfast" at CRF 10 was (PSNR 37.1 dB on the run-and-step video, where it was chosen,
36.9 dB on a three-panel front view of CMU clip 16_23; near the limit set by H.264's 4:2:0 colour
subsampling), for a file 1.6-1.75x as large (about 10-14 Mbit/s at 960x540, 30 fps)."""
X264_CRF = 14
"""x264 constant rate factor (0-51, lower is better; 18 is often called visually lossless)."""
QUEUE_FRAMES = 3
"""Frames rendered ahead of the encoder at most (each 1.5 MB at 960x540)."""


class FrameEncoder:
    """Writes frames to an H.264 video in a background thread: `put` hands over the arguments of
    `compose` (which returns the (h, w, 3) uint8 frame), the thread composes and encodes them in order.

    The thread holds at most `QUEUE_FRAMES` frames: `put` waits when it is that far behind. An error
    in the thread (a full disk, ffmpeg failing) is raised by the next `put` or by `close`; the frames
    after it are dropped. Use as a context manager: leaving it normally closes the video (waiting for
    the last frames); leaving it by an exception (Ctrl-C included) stops the thread and ffmpeg.

    Attributes:
        child_cpu_s: [s] CPU time of the ffmpeg process (user + system), known after `close`.
        compose_s: [s] wall time the thread spent in `compose`.
    """

    def __init__(self, path, fps: float, compose: Callable[..., np.ndarray]):
        self._compose = compose
        self._queue: queue.Queue = queue.Queue(maxsize=QUEUE_FRAMES)
        self._error: BaseException | None = None
        self._abort = False
        self._children0 = children_cpu()
        self.child_cpu_s = 0.0
        self.compose_s = 0.0
        self._writer = iio.get_writer(
            path, format="FFMPEG", mode="I", fps=fps, codec="libx264", quality=None, macro_block_size=1,
            ffmpeg_log_level="error", output_params=["-preset", X264_PRESET, "-crf", str(X264_CRF)])
        self._thread = threading.Thread(target=self._run, name="dynsplines-video-encoder", daemon=True)
        self._thread.start()

    def put(self, *args) -> None:
        """Queue one frame (the arguments of `compose`); raises the thread's error if it failed."""
        while True:
            if self._error is not None:
                raise self._error
            try:
                self._queue.put(args, timeout=0.1)
                return
            except queue.Full:
                continue

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            if self._error is not None or self._abort:
                continue  # drain: `put` never waits on a dead thread
            try:
                t0 = time.perf_counter()
                frame = self._compose(*item)
                self.compose_s += time.perf_counter() - t0
                self._writer.append_data(frame)
            except BaseException as e:  # noqa: BLE001  (handed to the main thread by put/close)
                self._error = e

    def close(self, abort: bool = False) -> None:
        """Finish the video (abort: drop the queued frames); raises the thread's error if it failed."""
        self._abort = self._abort or abort
        self._queue.put(None)
        self._thread.join()
        try:
            self._writer.close()
        finally:
            self.child_cpu_s = children_cpu() - self._children0
        if self._error is not None and not abort:
            raise self._error

    def __enter__(self) -> FrameEncoder:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
            return
        try:
            self.close(abort=True)
        except Exception:  # noqa: BLE001  (the exception that ends the video is the one to report)
            pass


def children_cpu() -> float:
    """[s] user + system CPU time of this process's finished (waited-for) child processes; 0 where
    the `resource` module is missing (Windows)."""
    try:
        import resource
    except ImportError:
        return 0.0
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime
