"""Sampling a saved path: times, default rate, unit quaternions, the reference at its own rate."""
import numpy as np
import pytest

from runner.export.sampling import DEFAULT_FPS, default_fps, sample_motion, sample_times_at
from runner.saved_path import load_saved_path
from solver.errors import InputError
from solver.layout import StateLayout


def test_sample_times_keep_a_rounded_end_and_clamp_it():
    t = sample_times_at(0.0, 1.699993, 1 / 0.0083333)
    assert len(t) == 205 and t[-1] == 1.699993
    assert np.allclose(sample_times_at(0.0, 1.0, 4.0), [0, 0.25, 0.5, 0.75, 1.0])
    with pytest.raises(InputError, match="--fps 0"):
        sample_times_at(0.0, 1.0, 0)


def test_reference_at_its_own_rate_is_its_frames(saved_npz, scene_model):
    saved = load_saved_path(saved_npz)
    assert default_fps(saved) == pytest.approx(120.0)
    m = sample_motion(saved, "reference", default_fps(saved), StateLayout.from_model(scene_model).quat_slots)
    assert np.allclose(m.qpos[:, :3], saved.reference_qpos[:, :3], atol=1e-12)


def test_samples_have_unit_quaternions_and_default_rate_without_reference(tmp_path, saved_npz, scene_model):
    with np.load(saved_npz) as z:
        fields = dict(z)
    fields["reference_times"] = np.zeros(0)
    fields["reference_qpos"] = np.zeros((0, scene_model.nq))
    path = tmp_path / "noref.npz"
    np.savez(path, **fields)
    saved = load_saved_path(path)
    assert default_fps(saved) == DEFAULT_FPS
    slots = StateLayout.from_model(scene_model).quat_slots
    m = sample_motion(saved, "optimized", 30.0, slots)
    assert np.allclose(np.linalg.norm(m.qpos[:, slots], axis=-1), 1.0)
    with pytest.raises(InputError, match="no reference motion"):
        sample_motion(saved, "reference", 30.0, slots)
