"""Frames drawn by several threads (`runner.render.parallel`) make the video one thread makes.

- A frame's picture depends on that frame only: a fresh renderer drawing frame k gives the panels the
  single renderer gives after drawing frames 0..k-1 (the reference), on the shipped scene with its
  infinite floor (which MuJoCo places under the camera of the scene's previous update).
- The whole video from 2 or 3 drawing threads decodes to the frames of the one-thread video (within
  H.264 rounding), in order, every frame once.
- Errors and Ctrl-C in the middle reach the caller, leave no file and no drawing thread behind.
"""
import threading

import imageio.v2 as iio
import mujoco
import numpy as np
import pytest
from render_scenes import one_leg_scene

import runner.render.frames as frames
from runner.paths import MODELS
from runner.render import Camera, Track, render_tracks
from runner.render.gl import shadow_map_size
from runner.render.overlays import check_keyframes, check_model_fit
from runner.render.parallel import MAX_WORKERS, MIN_PARALLEL_FRAMES, worker_count
from solver import InputError

SCENE = one_leg_scene(light='directional="true"')


def _walk(model, n=11, distance=1.0, swing=0.6):
    """A hand-built motion over 1 s: the root moves `distance` [m] along x, the leg swings (ball
    joint about y by +-swing rad), so every panel of every frame is a different picture."""
    t = np.linspace(0.0, 1.0, n)
    q = np.tile(model.qpos0, (n, 1))
    q[:, 0] += distance * t
    a = swing * np.sin(2 * np.pi * t)
    q[:, -4], q[:, -2] = np.cos(a / 2), np.sin(a / 2)  # the last joint's quaternion
    return t, q


def _video(path):
    with iio.get_reader(path) as reader:
        return np.stack(list(reader.iter_data())).astype(int)


def test_a_frame_does_not_depend_on_the_frames_drawn_before():
    model = mujoco.MjModel.from_xml_path(str(MODELS / "run_and_step.xml"))
    t, q = _walk(model, distance=2.0)
    q[:, 2] = 0.95  # the pelvis at standing height
    tracks = [Track("a", t, q), Track("b", t, q[::-1].copy())]
    kf_t, kf_q = check_keyframes(model, [0.5], None)
    plan = frames.FramePlan.build(model, tracks, [check_model_fit(model, tr) for tr in tracks], kf_t, kf_q,
                                  fps=10, speed=1.0, camera=Camera(), quality="fast",
                                  shadow_size=shadow_map_size(model, 180, Camera().distance),
                                  size=(320, 180), panel_size=(160, 180), title=None)
    with frames.FrameWriter(plan) as writer:
        reference = [writer.frame(i)[0] for i in range(plan.n_frames)]
    for k in (1, plan.n_frames - 1):
        with frames.FrameWriter(plan) as fresh:
            images = fresh.frame(k)[0]
        for p in range(2):
            diff = np.abs(images[p].astype(int) - reference[k][p].astype(int))
            assert diff.max() <= 2, (k, p, diff.max(), int((diff > 2).sum()))
        assert np.abs(reference[k][0].astype(int) - reference[k - 1][0].astype(int)).max() > 20  # it moves


@pytest.mark.parametrize("workers", [2, 3])
def test_threads_make_the_one_thread_video(tmp_path, workers):
    model = mujoco.MjModel.from_xml_string(SCENE)
    t, q = _walk(model)
    tracks = [Track("left", t, q), Track("right", t, q[::-1].copy())]
    args = dict(fps=15, size=(320, 180), speed=1.0, keyframe_times=[0.3, 0.7], title="t",
                camera=Camera(distance=3.0))
    done = []
    one = render_tracks(model, tracks, tmp_path / "one.mp4", workers=1, **args)
    many = render_tracks(model, tracks, tmp_path / "many.mp4", workers=workers,
                         progress=lambda i, n: done.append((i, n)), **args)
    assert (one.threads, many.threads) == (1, workers)
    assert done == [(i, many.n_frames) for i in range(1, many.n_frames + 1)]
    a, b = _video(one.path), _video(many.path)
    assert a.shape == b.shape and len(a) == one.n_frames == 16
    diff = np.abs(a - b)
    assert diff.mean() < 0.2 and np.percentile(diff, 99.9) <= 4, (diff.mean(), np.percentile(diff, 99.9))
    consecutive = np.abs(a[1:] - a[:-1]).mean(axis=(1, 2, 3))
    assert consecutive.min() > 0.1  # every frame differs from the one before: a shuffled order would show


def _no_drawing_threads():
    return not [t for t in threading.enumerate() if t.name.startswith("dynsplines-video-draw")]


def test_an_error_in_a_drawing_thread_reaches_the_caller(tmp_path, monkeypatch):
    model = mujoco.MjModel.from_xml_string(SCENE)
    t, q = _walk(model)
    original = frames.FrameWriter.frame

    def frame(self, i):
        if i == 5:
            raise ValueError("bad frame 5")
        return original(self, i)

    monkeypatch.setattr(frames.FrameWriter, "frame", frame)
    with pytest.raises(ValueError, match="bad frame 5"):
        render_tracks(model, [Track("a", t, q)], tmp_path / "v.mp4", fps=15, size=(160, 120), speed=1.0,
                      workers=2)
    assert list(tmp_path.iterdir()) == [] and _no_drawing_threads()


def test_a_thread_without_a_renderer_leaves_its_frames_to_the_others(tmp_path, monkeypatch):
    """One of two threads cannot make its OpenGL context: the other draws every frame (the video of
    one thread); when none can, the error reaches the caller."""
    model = mujoco.MjModel.from_xml_string(SCENE)
    t, q = _walk(model)
    original, made, lock = frames.FrameWriter.__init__, [], threading.Lock()

    def init(self, plan, fail_first=1):
        with lock:
            made.append(1)
            fail = len(made) <= fail_first
        if fail:
            raise InputError("offscreen rendering failed (test)")
        original(self, plan)

    args = dict(fps=15, size=(160, 120), speed=1.0)
    one = render_tracks(model, [Track("a", t, q)], tmp_path / "one.mp4", workers=1, **args)
    monkeypatch.setattr(frames.FrameWriter, "__init__", init)
    two = render_tracks(model, [Track("a", t, q)], tmp_path / "two.mp4", workers=2, **args)
    assert len(made) == 2 and two.n_frames == one.n_frames
    assert np.abs(_video(one.path) - _video(two.path)).mean() < 0.2
    monkeypatch.setattr(frames.FrameWriter, "__init__", lambda self, plan: init(self, plan, fail_first=99))
    with pytest.raises(InputError, match="offscreen rendering failed"):
        render_tracks(model, [Track("a", t, q)], tmp_path / "none.mp4", workers=2, **args)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["one.mp4", "two.mp4"] and _no_drawing_threads()


def test_ctrl_c_stops_the_drawing_threads(tmp_path):
    model = mujoco.MjModel.from_xml_string(SCENE)
    t, q = _walk(model)

    def progress(i, n):
        if i == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        render_tracks(model, [Track("a", t, q)], tmp_path / "v.mp4", fps=15, size=(160, 120), speed=1.0,
                      workers=2, progress=progress)
    assert list(tmp_path.iterdir()) == [] and _no_drawing_threads()


def test_worker_count(monkeypatch):
    import runner.render.parallel as parallel

    monkeypatch.setattr(parallel, "available_cores", lambda: 2)
    assert worker_count(MIN_PARALLEL_FRAMES - 1) == 1  # a short video: one context
    assert worker_count(MIN_PARALLEL_FRAMES) == 2 and worker_count(10_000) == 2
    monkeypatch.setattr(parallel, "available_cores", lambda: 64)
    assert worker_count(10_000) == MAX_WORKERS
    assert worker_count(5, requested=8) == 5 and worker_count(0, requested=3) == 1


@pytest.mark.parametrize("workers", [0, -1, 1.5, "2", True])
def test_bad_workers(tmp_path, workers):
    model = mujoco.MjModel.from_xml_string(SCENE)
    t, q = _walk(model)
    with pytest.raises(InputError, match="workers must be a whole number >= 1"):
        render_tracks(model, [Track("a", t, q)], tmp_path / "v.mp4", size=(160, 120), workers=workers)
