"""The faster video keeps what it shows.

- The floor drawn as one quad (`coarse_floor`) gives the picture MuJoCo's own 200 x 200 grid gives
  (the reference: the same panel rendered with `coarse_floor` switched off), on the shipped scenes
  (checker floor, shadows, the horizon haze), and scenes whose floor lighting varies keep the grid.
- Frames composed and encoded in a background thread (`FrameEncoder`) all arrive, in order, with their
  overlays: the timeline's playback dot moves right in every frame of a hand-built motion.
- An error in the encoder thread reaches the caller, and no half-written video is left.
"""
import imageio.v2 as iio
import mujoco
import numpy as np
import pytest
from render_scenes import one_leg_scene

import runner.render.overlays as overlays
from runner.paths import MODELS
from runner.render import Camera, Track, render_tracks
from runner.render.gl import coarse_floor, make_renderer, shadow_map_size
from runner.render.tracks import forward_direction, root_body


def _pose(model):
    q = model.qpos0.copy()
    q[:3] = [-1.3, 0.4, 0.95]
    return q


@pytest.mark.parametrize("height, distance", [(514, 4.0), (1040, 4.0), (514, 2.0), (120, 4.0), (4000, 1.0)])
def test_the_shadow_map_texel_is_no_larger_than_a_pixel(height, distance):
    model = mujoco.MjModel.from_xml_path(str(MODELS / "run_and_step.xml"))
    side = shadow_map_size(model, height, distance)
    texel = 2 * model.vis.map.shadowclip * model.stat.extent / side  # mjr_render's glOrtho square
    pixel = 2 * distance * np.tan(np.radians(model.vis.global_.fovy) / 2) / height
    assert side & (side - 1) == 0 and 256 <= side <= 4096
    assert texel <= pixel or side == 4096
    assert 2 * texel > pixel or side == 256  # the smallest such map


def test_the_smaller_shadow_map_draws_the_same_shadow():
    """At the default video size and camera the shadow map of `shadow_map_size` (512 px) against the
    "fast" preset's 1024 px: the same picture up to a few pixels of the shadow's edge."""
    model = mujoco.MjModel.from_xml_path(str(MODELS / "run_and_step.xml"))
    images = []
    for side in (None, shadow_map_size(model, 514, Camera().distance)):
        renderer = make_renderer(model, 480, 514, "fast", side)
        try:
            panel = overlays.Panel(model, renderer, "fast")
            q = _pose(model)
            forward_direction(model, panel.data, q)
            panel.set_camera(Camera(), panel.data.xpos[root_body(model)].copy(), -90.0)
            panel.render(q)
            images.append(panel.render(q).astype(int))
        finally:
            renderer.close()
    diff = np.abs(images[0] - images[1])
    assert diff.mean() < 0.1 and np.percentile(diff, 99.9) <= 2, (diff.mean(), np.percentile(diff, 99.9))


def _panel_images(model, size=(240, 260), quality="fast"):
    """(image with coarse_floor, image with MuJoCo's grid, the scene's floor geom after coarse_floor)."""
    renderer = make_renderer(model, *size, quality)
    try:
        panel = overlays.Panel(model, renderer, quality)
        q = _pose(model)
        forward_direction(model, panel.data, q)
        panel.set_camera(Camera(), panel.data.xpos[root_body(model)].copy(), -70.0)
        panel.render(q)  # MuJoCo moves an infinite plane under the camera of the scene's previous update
        coarse = panel.render(q).astype(int)
        floor = renderer.scene.geoms[0]
        floor = (floor.dataid, float(floor.size[0]), renderer.scene.ngeom)
        original = overlays.coarse_floor
        overlays.coarse_floor = lambda model, scene: None
        try:
            grid = panel.render(q).astype(int)
        finally:
            overlays.coarse_floor = original
    finally:
        renderer.close()
    return coarse, grid, floor


@pytest.mark.parametrize("scene, repeat", [("run_and_step.xml", None), ("floor.xml", None),
                                           ("run_and_step.xml", (2.0, 3.0)), ("floor.xml", (0.5, 0.5))])
def test_the_one_quad_floor_looks_like_mujocos_grid(scene, repeat):
    model = mujoco.MjModel.from_xml_path(str(MODELS / scene))
    if repeat is not None:  # the floor texture repeated 2 and 3 times per 2 m, or once per 4 m
        floor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "floor")
        model.mat_texrepeat[model.geom_matid[floor]] = repeat
    coarse, grid, (dataid, half, ngeom) = _panel_images(model)
    zfar = model.vis.map.zfar * model.stat.extent
    assert dataid == -1 and half >= 1.05 * zfar  # replaced, reaching as far as MuJoCo's grid (2.1 zfar / 2)
    assert ngeom == model.ngeom + 1  # + the zero-size plane that keeps the horizon haze
    diff = np.abs(coarse - grid)
    assert diff.mean() < 0.1, diff.mean()  # rounding only (checker, shadow, haze all in place)
    assert np.percentile(diff, 99.9) <= 3, np.percentile(diff, 99.9)
    assert grid.std() > 20  # not an empty picture


def test_a_floor_under_a_spot_light_keeps_mujocos_grid():
    """Under a spot light the floor's (per-vertex) lighting varies over it: one quad would lose the
    pool of light, so the grid stays."""
    model = mujoco.MjModel.from_xml_string(one_leg_scene())
    coarse, grid, (dataid, _, ngeom) = _panel_images(model)
    assert dataid >= 0 and ngeom == model.ngeom
    assert np.abs(coarse - grid).max() == 0


def test_the_high_quality_keeps_mujocos_grid():
    """With reflections ("high") one quad would change the floor's brightness a little: grid kept."""
    model = mujoco.MjModel.from_xml_path(str(MODELS / "run_and_step.xml"))
    coarse, grid, (dataid, _, ngeom) = _panel_images(model, quality="high")
    assert dataid >= 0 and ngeom == model.ngeom and np.abs(coarse - grid).max() == 0


def test_coarse_floor_needs_a_free_scene_geom():
    model = mujoco.MjModel.from_xml_string(one_leg_scene(light='directional="true"'))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    scene = mujoco.MjvScene(model, maxgeom=model.ngeom)
    mujoco.mjv_updateScene(model, data, mujoco.MjvOption(), None, mujoco.MjvCamera(),
                           mujoco.mjtCatBit.mjCAT_ALL, scene)
    coarse_floor(model, scene)  # no room for the haze plane: the floor is left as it is
    assert scene.ngeom == model.ngeom and scene.geoms[0].dataid >= 0


def _timeline_dot_x(frame, panel_x0, panel_w):
    """x [px] of the white playback dot on the timeline near the bottom of a panel (rows of the
    timeline: the last 20 of a 480x270 video)."""
    rows = frame[-20:, panel_x0:panel_x0 + panel_w].astype(int)
    white = (rows.min(axis=2) > 235)
    cols = np.flatnonzero(white.any(axis=0))
    return panel_x0 + cols.mean() if cols.size else np.nan


def test_every_frame_arrives_in_order_with_its_overlays(tmp_path):
    model = mujoco.MjModel.from_xml_string(one_leg_scene(light='directional="true"'))
    t = np.linspace(0.0, 1.0, 11)
    q = np.zeros((11, model.nq))
    q[:, 0], q[:, 2], q[:, 3], q[:, 7] = t, 1.0, 1.0, 1.0
    tracks = [Track("a", t, q), Track("b", t, q)]
    info = render_tracks(model, tracks, tmp_path / "v.mp4", fps=20, size=(480, 270), speed=1.0,
                         keyframe_times=[0.5], camera=Camera(distance=3.0))
    with iio.get_reader(info.path) as reader:
        frames = np.stack(list(reader.iter_data()))
    assert len(frames) == info.n_frames == 21
    x = np.array([_timeline_dot_x(f, 0, 240) for f in frames])
    assert np.all(np.isfinite(x)) and np.all(np.diff(x) > 0), x  # one new frame each, in order
    assert info.cpu_time_s > 0 and np.isfinite(info.cpu_time_s)
    assert info.fps == pytest.approx(info.n_frames / info.wall_time_s)
    assert info.summary().startswith("21 frames in ") and " fps, CPU " in info.summary()


def test_an_encoder_error_reaches_the_caller_and_leaves_no_file(tmp_path, monkeypatch):
    model = mujoco.MjModel.from_xml_string(one_leg_scene(light='directional="true"'))
    t = np.linspace(0.0, 1.0, 11)
    q = np.zeros((11, model.nq))
    q[:, 2], q[:, 3], q[:, 7] = 1.0, 1.0, 1.0
    calls = []

    def compose(self, *args, **kwargs):
        calls.append(1)
        if len(calls) == 3:
            raise OSError(28, "No space left on device")
        return original(self, *args, **kwargs)

    original = overlays.Overlay.compose
    monkeypatch.setattr(overlays.Overlay, "compose", compose)
    with pytest.raises(OSError, match="No space left"):
        render_tracks(model, [Track("a", t, q)], tmp_path / "v.mp4", fps=20, size=(160, 120), speed=1.0)
    assert list(tmp_path.iterdir()) == []
