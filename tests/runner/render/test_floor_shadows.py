"""The floor of the shipped scenes has no black shadow specks (shadow-map self-shadowing of the floor
plane, "shadow acne"), and the figure's own shadow is still drawn.

Reference: the same frame rendered with the sun's shadow switched off. Pixels of the floor (MuJoCo's
segmentation rendering) that the shadow darkens form the figure's shadow: a few large connected blobs.
Specks are shadowed floor pixels in components of fewer than 40 pixels.
"""
import mujoco
import numpy as np
import pytest
from scipy import ndimage

from runner.paths import MODELS
from runner.render.gl import make_renderer
from runner.render.overlays import Panel
from runner.render.tracks import Camera, forward_direction, root_body

SIZE = (480, 540)  # one panel of the default 960x540 video


def _runner_pose(model):
    """A running pose on the floor (identity joints but a swung leg), the root at x = -2.7 m."""
    q = model.qpos0.copy()
    q[:3] = [-2.7, 0.0, 0.95]
    hip = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "l_hip")
    a = model.jnt_qposadr[hip]
    q[a:a + 4] = [np.cos(0.35), 0.0, np.sin(0.35), 0.0]
    return q


def _frames(model, q):
    """(lit gray image, unshadowed gray image, floor mask) of the panel at pose q."""
    renderer = make_renderer(model, *SIZE, "fast")
    try:
        panel = Panel(model, renderer, "fast")
        forward_direction(model, panel.data, q)
        panel.set_camera(Camera(), panel.data.xpos[root_body(model)].copy(), -90.0)
        sun = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_LIGHT, "sun")
        lit = panel.render(q).astype(float).mean(axis=2)
        model.light_castshadow[sun] = 0
        flat = panel.render(q).astype(float).mean(axis=2)
        model.light_castshadow[sun] = 1
        renderer.enable_segmentation_rendering()
        seg = panel.render(q)
    finally:
        renderer.close()
    floor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    return lit, flat, (seg[..., 0] == floor) & (seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM))


@pytest.mark.parametrize("scene", ["run_and_step.xml", "floor.xml"])
def test_the_floor_has_no_shadow_specks_and_keeps_the_figures_shadow(scene):
    model = mujoco.MjModel.from_xml_path(str(MODELS / scene))
    lit, flat, floor = _frames(model, _runner_pose(model))
    shadow = ((flat - lit) > 15) & floor
    labels, n = ndimage.label(shadow)
    sizes = np.asarray(ndimage.sum(shadow, labels, range(1, n + 1)))
    specks = int(sizes[sizes < 40].sum())
    assert specks <= 10, (specks, sorted(sizes.astype(int)))
    assert sizes.max() > 500, sizes.max()  # the figure's shadow is there
