"""The video's frames drawn by several threads at once, each with its own OpenGL context.

Mesa's software renderer (llvmpipe) does much of a frame's work on the thread that issues the draw
calls (vertex processing, primitive setup, the wait for the shadow map before the lit pass reads it):
only the final rasterization is spread over llvmpipe's own threads, so one drawing thread keeps a
2-core machine about 1.5 cores busy. MuJoCo's Python bindings release the GIL in `mjr_render` and
`mjr_readPixels`, so `render_threaded` draws with `workers` threads in this process, each with its own
`mujoco.Renderer` (its own OpenGL context and scene) made from the same `FramePlan`. Each thread
takes the next frame not yet taken (at most `AHEAD_FRAMES` per thread past the one the encoder waits
for, so a thread the OS holds up does not stall the others), frame i is the same picture whichever
thread draws it, and this thread hands the frames to the one encoder in frame order (`FrameEncoder`:
overlays and H.264 in its own thread, ffmpeg in its own process). Threads rather than processes: no
interpreter to start, nothing to copy, one encoder and one file; a thread costs one more OpenGL
context (its shaders compiled once more by llvmpipe), a few tenths of a second of CPU, so short
videos use one (`worker_count`).

Errors: an error in a drawing thread (no OpenGL backend, a bad frame) is raised here, in frame order;
Ctrl-C (KeyboardInterrupt, delivered to this thread) stops the drawing threads, which free their
contexts, and the encoder drops its frames (no partial video: the caller's `atomic_output`).
"""
from __future__ import annotations

import os
import threading
from collections.abc import Callable
from dataclasses import dataclass

from runner.render.encode import FrameEncoder
from runner.render.frames import FramePlan, FrameWriter
from runner.render.overlays import Overlay

MAX_WORKERS = 4
"""Drawing threads at most: each holds an OpenGL context (and llvmpipe's rasterizer threads); beyond
the number of cores more only compete for them."""
MIN_PARALLEL_FRAMES = 24
"""Videos shorter than this (0.8 s at 30 fps) are drawn by one thread: a second OpenGL context and its
shader compilation (about 0.1-0.3 s of CPU) would cost more than it saves."""
AHEAD_FRAMES = 2
"""Frames per drawing thread that may be drawn ahead of the one the encoder waits for (each about
1.5 MB at 960x540): a thread held up by the OS does not hold up the others until they are this far
ahead."""
_POLL_S = 0.1
"""[s] how often the encoding thread, waiting for a frame, checks that a drawing thread is alive."""


def available_cores() -> int:
    """Cores this process may run on (its CPU affinity where the OS tells it, else os.cpu_count())."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def worker_count(n_frames: int, requested: int | None = None) -> int:
    """How many threads draw a video of `n_frames` frames.

    Args:
        n_frames: frames of the video.
        requested: a number asked for (>= 1), or None for the default: `available_cores()` up to
            `MAX_WORKERS`, and 1 below `MIN_PARALLEL_FRAMES` frames.
    Returns:
        between 1 and max(1, n_frames).
    """
    if requested is None:
        want = 1 if n_frames < MIN_PARALLEL_FRAMES else min(MAX_WORKERS, available_cores())
    else:
        want = int(requested)
    return max(1, min(want, n_frames))


@dataclass
class DrawStats:
    """What the drawing threads did: render_s [s] wall time posing, rendering and reading back panels
    (summed over the threads), panels drawn."""

    render_s: float = 0.0
    panels: int = 0


def render_threaded(plan: FramePlan, path, workers: int,
                    progress: Callable[[int, int], None] | None = None) -> DrawStats:
    """Write the video of `plan` to `path` (H.264), its frames drawn by `workers` threads.

    Args:
        plan: the frames (`FramePlan`). path: the video file (.mp4, .mkv, .mov).
        workers: drawing threads, >= 1.
        progress: called as progress(frames_done, n_frames) after each frame is handed to the encoder.
    Returns:
        `DrawStats`.
    Raises:
        what a drawing thread raised (InputError: no OpenGL backend), in frame order; OSError: the
        video cannot be written (the encoder's error).
    """
    n = plan.n_frames
    frames = _Frames(n, AHEAD_FRAMES * workers, workers)
    stats = [DrawStats() for _ in range(workers)]
    threads = [threading.Thread(target=_draw, args=(plan, frames, stats[j]), name=f"dynsplines-video-draw-{j}",
                                daemon=True) for j in range(workers)]
    for t in threads:
        t.start()
    labels = [tr.label for tr in plan.tracks]
    try:
        with FrameEncoder(path, plan.fps, _compose_of(plan)) as encoder:
            for i in range(n):
                images, marks, dots = frames.get(i, threads)
                encoder.put(images, labels, plan.times[i], plan.speed, int(plan.currents[i]), marks, dots)
                if progress is not None:
                    progress(i + 1, n)
    finally:
        frames.stop()
        for t in threads:
            t.join()
    return DrawStats(sum(s.render_s for s in stats), sum(s.panels for s in stats))


def _compose_of(plan: FramePlan):
    """The overlay composer of the plan's frames (`Overlay.compose`)."""
    return Overlay(plan.width, plan.height, plan.panel_w, len(plan.tracks), plan.title, plan.t0, plan.t1,
                   plan.kf_t).compose


class _Frames:
    """The frames between the drawing threads and the encoder: a drawing thread takes the next frame
    not yet taken (`take`; at most `ahead` frames past the one the encoder waits for), puts its panels
    (or the exception it raised) under its index (`put`); the encoding thread gets them in order (`get`)."""

    def __init__(self, n: int, ahead: int, workers: int):
        self.n, self.ahead, self.workers = n, max(1, ahead), workers
        self.failed = 0  # drawing threads that could not make their renderer
        self.cond = threading.Condition()
        self.taken = 0  # frames 0 .. taken-1 are taken
        self.wanted = 0  # the frame the encoder waits for
        self.done: dict[int, tuple] = {}
        self.stopped = False

    def take(self) -> int | None:
        """The next frame to draw, or None when all are taken or `stop` was called."""
        with self.cond:
            while not self.stopped and self.taken < self.n and self.taken >= self.wanted + self.ahead:
                self.cond.wait()
            if self.stopped or self.taken >= self.n:
                return None
            self.taken += 1
            return self.taken - 1

    def put(self, i: int, kind: str, payload) -> None:
        with self.cond:
            self.done[i] = (kind, payload)
            self.cond.notify_all()

    def get(self, i: int, threads):
        """Frame i's panels (frames are got in order); raises what its drawing thread raised."""
        with self.cond:
            while i not in self.done:
                if not any(t.is_alive() for t in threads):
                    raise RuntimeError(f"the drawing threads ended without drawing frame {i}")
                self.cond.wait(timeout=_POLL_S)
            kind, payload = self.done.pop(i)
            self.wanted = i + 1
            self.cond.notify_all()
        if kind == "error":
            raise payload
        return payload

    def could_not_start(self) -> bool:
        """A drawing thread could not make its renderer: True if it is the last one (no thread draws)."""
        with self.cond:
            self.failed += 1
            return self.failed >= self.workers

    def stop(self) -> None:
        """Drawing threads take no more frames."""
        with self.cond:
            self.stopped = True
            self.cond.notify_all()


def _draw(plan: FramePlan, frames: _Frames, stats: DrawStats) -> None:
    """A drawing thread: make its renderer (`FrameWriter`, from its own copy of the model), then draw
    the frames it takes until none is left; an exception is put in place of the frame it was drawing.
    A thread whose renderer cannot be made ends and leaves the frames to the others; the last one to
    fail so puts its exception in place of the next frame. The renderer is freed here, in the thread
    whose OpenGL context it is."""
    writer, i = None, None
    try:
        try:
            writer = FrameWriter(plan)
        except BaseException as e:  # noqa: BLE001  (the others draw; raised if none could start)
            if not frames.could_not_start():
                return
            raise e
        while (i := frames.take()) is not None:
            frames.put(i, "ok", writer.frame(i))
    except BaseException as e:  # noqa: BLE001  (raised in the encoding thread, in frame order)
        if i is None:
            i = frames.take()
        if i is not None:
            frames.put(i, "error", e)
    finally:
        if writer is not None:
            stats.render_s, stats.panels = writer.render_s, writer.panels
            writer.close()
