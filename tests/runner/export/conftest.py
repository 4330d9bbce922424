"""A small saved path (.npz, the fields `runner.animate.save_path_npz` writes) on the real figure and scene."""
import mujoco
import numpy as np
import pytest

from runner.paths import MODELS
from solver.layout import StateLayout
from solver.quaternion import normalize

SCENE = MODELS / "run_and_step.xml"


def random_frames(model, m, rng, spread=0.6):
    """(m, nq) frames: root moving along +x above the floor, random joint rotations up to ~spread rad."""
    layout = StateLayout.from_model(model)
    q = np.zeros((m, model.nq))
    q[:, 0] = np.linspace(-2.0, 2.0, m)
    q[:, 1] = rng.normal(0.0, 0.1, m)
    q[:, 2] = 1.0 + rng.normal(0.0, 0.03, m)
    for idx in layout.quat_slots:
        v = rng.normal(0.0, spread / 2, (m, 3))
        q[:, idx] = normalize(np.concatenate([np.ones((m, 1)), v], axis=1))
    return q


@pytest.fixture(scope="session")
def scene_model():
    return mujoco.MjModel.from_xml_path(str(SCENE))


@pytest.fixture(scope="session")
def saved_npz(tmp_path_factory, scene_model):
    """Path of a saved path with optimized, plain and reference motions over 1 s (reference at 120 Hz)."""
    rng = np.random.default_rng(7)
    model = scene_model
    t = np.linspace(0.0, 1.0, 7)
    frames = random_frames(model, 7, rng)
    plain_t = t[::2]
    ref_t = np.arange(121) / 120.0
    ref = random_frames(model, 121, rng, spread=0.2)
    path = tmp_path_factory.mktemp("saved") / "path.npz"
    np.savez(path, frame_times=t, frames=frames, frame_is_keyframe=np.isin(t, plain_t),
             keyframe_times=plain_t, keyframes=frames[::2], keyframe_mask=np.ones((4, model.nq), bool),
             plain_frame_times=plain_t, plain_frames=frames[::2], reference_times=ref_t, reference_qpos=ref,
             scene=np.array("models/run_and_step.xml"))
    return path
