"""Regression tests for the main job: the shipped run-and-step clip, through the command line.

The written path is checked with independent code: scipy's natural cubic spline through the saved
frames, MuJoCo kinematics called directly, and the floor/box geometry read from the model - not the
project's metrics module.
"""
import json
from pathlib import Path

import mujoco
import numpy as np
import pytest
from scipy.interpolate import make_interp_spline

from runner.cli import main

REPO = Path(__file__).resolve().parents[2]


RESULT_DIR = []  # the folder of the module's saved path (its scene is named relative to it)


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    out = tmp_path_factory.mktemp("rs") / "run_and_step.npz"
    RESULT_DIR[:] = [out.parent]
    code = main(["run-and-step", "--no-render", "--quiet", "--save-path", str(out)])
    assert code == 0
    z = np.load(out)
    model = mujoco.MjModel.from_xml_path(str((out.parent / str(z["scene"])).resolve()))  # relative to the .npz
    return z, model


def dense(frame_times, frames, rate=1000.0):
    t = np.linspace(frame_times[0], frame_times[-1], int(round((frame_times[-1] - frame_times[0]) * rate)) + 1)
    return t, make_interp_spline(frame_times, frames, k=3, bc_type="natural")(t)


def max_penetration_m(model, Y):
    """Deepest contact site below the floor (z = 0 plane) or inside the step box, by direct geometry."""
    d = mujoco.MjData(model)
    sites = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s) for s in ("l_heel", "l_toe", "r_heel", "r_toe")]
    box = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "step")
    mujoco.mj_kinematics(model, d)
    c, half = d.geom_xpos[box].copy(), model.geom_size[box].copy()
    assert np.allclose(d.geom_xmat[box], np.eye(3).ravel())  # axis-aligned box in this scene
    worst = 0.0
    for y in Y:
        d.qpos[:] = y
        mujoco.mj_kinematics(model, d)
        for s in sites:
            p = d.site_xpos[s]
            worst = max(worst, -p[2])  # floor
            inside = half - np.abs(p - c)
            if np.all(inside > 0):
                worst = max(worst, inside.min())
    return worst


def test_plain_spline_penetrates_by_centimetres(result):
    z, model = result
    _, Y = dense(z["plain_frame_times"], z["plain_frames"])
    assert max_penetration_m(model, Y) > 0.04  # several cm: the demo has something to fix


def test_optimized_path_clears_floor_and_step(result):
    z, model = result
    _, Y = dense(z["frame_times"], z["frames"])
    assert max_penetration_m(model, Y) <= 0.001


def test_keyframes_met_exactly(result):
    z, _ = result
    Yk = make_interp_spline(z["frame_times"], z["frames"], k=3, bc_type="natural")(z["keyframe_times"])
    mask = z["keyframe_mask"]
    assert mask.sum() > 0 and not mask.all()  # the clip has a partial keyframe
    assert np.abs(Yk - z["keyframes"])[mask].max() <= 1e-9


def test_quaternion_norms_and_hyperextension(result):
    z, model = result
    _, Y = dense(z["frame_times"], z["frames"])
    for j in range(model.njnt):
        adr = model.jnt_qposadr[j] + (3 if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE else 0)
        n = np.linalg.norm(Y[:, adr:adr + 4], axis=1)
        assert np.abs(1 - n).max() <= 0.05
    # knees flex about +y, elbows about -y (models/README.md): hyperextension = negative flexion angle
    for name, axis in (("l_knee", 1), ("r_knee", 1), ("l_elbow", -1), ("r_elbow", -1)):
        adr = model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)]
        q = Y[:, adr:adr + 4] * np.sign(Y[:, adr:adr + 1])
        flex = np.degrees(2 * np.arctan2(axis * q[:, 2], q[:, 0]))
        assert flex.min() >= -2.0, name


def test_saved_path_fields(result):
    z, model = result
    m, nq = z["frames"].shape
    assert nq == model.nq == 51 and z["frame_times"].shape == (m,)
    k = len(z["keyframe_times"])
    assert z["keyframes"].shape == z["keyframe_mask"].shape == (k, nq)
    assert np.all(np.diff(z["frame_times"]) > 0) and m > k
    assert z["reference_qpos"].shape == (len(z["reference_times"]), nq) and len(z["reference_times"]) > 100
    assert (RESULT_DIR[0] / str(z["scene"])).resolve() == (REPO / "models/run_and_step.xml").resolve()
    assert float(z["wall_time_s"]) > 0
    versions = json.loads(str(z["versions_json"]))
    assert {"dynsplines", "mujoco", "nlopt", "numpy"} <= set(versions)
