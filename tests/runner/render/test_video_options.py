"""The video's options (`VideoOptions`, `--camera`), the camera that follows the figure smoothly from the
chosen side, keyframe numbers as in the keyframe file (from 0), and timeline labels that never overlap."""
import mujoco
import numpy as np
import pytest
from render_scenes import one_leg_scene

from runner.cli import main
from runner.exit_codes import EXIT_INPUT
from runner.render import Camera
from runner.render.gl import make_renderer
from runner.render.overlays import Overlay, Panel, timeline_labels
from runner.render.side_by_side import CAMERA_SIDES, VideoOptions, parse_camera
from runner.render.tracks import azimuth_path, lookat_path, root_poses
from solver import InputError

SCENE = one_leg_scene(leg=False)


@pytest.mark.parametrize("text, deg", [("side", 90.0), ("left", 90.0), ("right", -90.0), ("front", 0.0),
                                       ("back", 180.0), ("FRONT", 0.0), ("45", 45.0), ("-135", -135.0),
                                       ("270", -90.0), ("-180", 180.0), ("30deg", 30.0)])
def test_parse_camera_reads_names_and_degrees(text, deg):
    assert parse_camera(text) == pytest.approx(deg, abs=1e-12)


@pytest.mark.parametrize("text", ["up", "", "nan", "inf", "left-ish"])
def test_parse_camera_refuses_anything_else_naming_the_choices(text):
    with pytest.raises(InputError, match=r"--camera .*front, left, side, back, right.*degrees"):
        parse_camera(text)


def test_a_bad_camera_is_a_usage_error(capsys):
    assert main(["animate", "k.json", "--camera", "above"]) == EXIT_INPUT
    err = capsys.readouterr().err
    assert "--camera" in err and "front, left, side, back, right" in err and len(err.strip().splitlines()) == 1


def _camera_offset(side: str) -> np.ndarray:
    """(3,) [m] where MuJoCo puts the free camera of `--camera side` relative to the look-at point, for
    a figure travelling along +x (MuJoCo's own camera placement, read back from the scene)."""
    model = mujoco.MjModel.from_xml_string(SCENE)
    cam = VideoOptions(camera=parse_camera(side)).render_camera()
    renderer = make_renderer(model, 64, 48)
    try:
        panel = Panel(model, renderer)
        positions = np.stack([np.linspace(0.0, 2.0, 50), np.zeros(50), np.ones(50)], axis=1)
        az = azimuth_path(positions, 0.04, cam)[25]
        lookat = np.array([1.0, 0.0, 1.0])
        panel.set_camera(cam, lookat, az)
        panel.render(model.qpos0)
        glcam = mujoco.mjv_averageCamera(renderer.scene.camera[0], renderer.scene.camera[1])
        return np.asarray(glcam.pos) - lookat
    finally:
        renderer.close()


@pytest.mark.parametrize("side, direction", [("side", (0, 1)), ("left", (0, 1)), ("right", (0, -1)),
                                             ("front", (1, 0)), ("back", (-1, 0)), ("45", (0.7071, 0.7071))])
def test_the_camera_stands_on_the_chosen_side_of_the_direction_of_travel(side, direction):
    offset = _camera_offset(side)
    horizontal = offset[:2] / np.linalg.norm(offset[:2])
    np.testing.assert_allclose(horizontal, direction, atol=1e-3)
    assert np.linalg.norm(offset) == pytest.approx(Camera().distance, rel=1e-4)


def test_the_default_side_is_the_former_fixed_camera():
    assert VideoOptions().render_camera() == Camera()  # azimuth -90: the figure's left
    assert VideoOptions().camera == CAMERA_SIDES["side"]


@pytest.mark.parametrize("hz, phase", [(1.0, 0.7), (1.0, 1.9), (3.0, 0.0), (3.0, 1.9)])
def test_the_camera_follows_the_pelvis_smoothly(hz, phase):
    """A run along +x at 3 m/s with a bob (2 cm) and a sway (3 cm) at a stride's frequency: the look-at
    point follows the trend (the Gaussian's transfer at 1 Hz, exp(-(2 pi 1 Hz 0.3 s)^2 / 2) = 0.17,
    leaves at most 5 mm of the sway) and the camera's heading does not swing with the sway (no jitter;
    the instantaneous direction of travel swings by up to 2 x 3.6 deg at 1 Hz, 2 x 10.7 deg at 3 Hz)."""
    dt = 1.0 / 60
    t = np.arange(0.0, 2.0, dt)
    wave = np.sin(2 * np.pi * hz * t + phase)
    wobble = np.stack([np.zeros_like(t), 0.03 * wave, 0.02 * wave], 1)
    trend = np.stack([3.0 * t, np.zeros_like(t), np.ones_like(t)], 1)
    cam = VideoOptions(camera=parse_camera("front")).render_camera()
    look = lookat_path(None, None, None, dt, cam, positions=trend + wobble)
    inner = slice(30, -30)  # 0.5 s from the ends, where the padding's mean velocity sees the wobble
    np.testing.assert_allclose(look[inner], trend[inner], atol=6e-3)
    az = azimuth_path(trend + wobble, dt, cam)
    assert np.ptp(az) < 4.0, np.ptp(az)
    assert np.ptp(az[inner]) < 1.5, np.ptp(az[inner])


def test_video_options_from_the_parsed_command_line():
    from runner.animate_options import add_options
    from runner.parser import OneLineParser

    p = OneLineParser()
    add_options(p)
    v = VideoOptions.from_args(p.parse_args(["--camera", "front", "--size", "480x270", "--fps", "12",
                                             "--reference-panel", "--quiet"]))
    assert v == VideoOptions(fps=12.0, size=(480, 270), speed=0.5, panels=("plain", "optimized", "reference"),
                             camera=0.0, quiet=True)
    assert VideoOptions.from_args(p.parse_args([])) == VideoOptions()
    with pytest.raises(SystemExit) as e:
        p.parse_args(["--camera", "above"])
    assert e.value.code == EXIT_INPUT


def test_keyframes_are_numbered_from_0_as_in_the_keyframe_file():
    """The caption and the timeline say "keyframe 0" for the file's first keyframe (its index in the
    "keyframes" list, the number its error messages use)."""
    kf_t = np.array([0.0, 0.5, 1.0])
    overlay = Overlay(480, 270, 240, 2, "title", 0.0, 1.0, kf_t)
    panel = np.zeros((270 - overlay.band, 240, 3), np.uint8)
    overlay.compose([panel, panel], ["a", "b"], 0.0, 1.0, current=0, marks=[None, None])
    drawn = {key[0] for key in overlay._patches}
    assert "keyframe 0  (t = 0.00 s)" in drawn
    assert {"0", "1", "2"} <= drawn and "3" not in drawn


def test_timeline_labels_of_close_keyframes_do_not_overlap():
    centres = [10.0, 14.0, 18.0, 60.0, 61.0, 100.0]
    widths = [10.0] * 6
    kept = timeline_labels(centres, widths, gap=2.0)
    assert kept == [0, 3, 5]
    for i, j in zip(kept, kept[1:]):
        assert centres[j] - centres[i] >= (widths[i] + widths[j]) / 2 + 2.0
    assert timeline_labels(centres, widths, first=1, gap=2.0) == [1, 3, 5]  # the current one always
    assert timeline_labels([0.0, 50.0], [10.0, 10.0]) == [0, 1]


def test_the_video_draws_no_overlapping_keyframe_numbers():
    """Keyframes 9 and 10 are 0.05 s apart on a 1.2 s timeline: "9" and "10" would touch ("910")."""
    kf_t = np.array([0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95, 1.2])
    overlay = Overlay(480, 270, 240, 2, None, 0.0, 1.2, kf_t)
    panel = np.zeros((270, 240, 3), np.uint8)
    overlay.compose([panel, panel], ["a", "b"], 0.0, 1.0, current=-1, marks=[None, None])
    drawn = {key[0] for key in overlay._patches}
    assert not {"9", "10"} <= drawn
    assert {"0", "11"} <= drawn


@pytest.mark.parametrize("command", ["animate", "mocap"])
def test_the_commands_pass_the_camera_to_the_video(command, monkeypatch, tmp_path):
    """`--camera front` reaches `render_video` from both commands that render (no option that does nothing)."""
    import runner.run
    from runner.paths import MODELS
    from runner.render import RenderInfo

    seen = []

    def fake_render(out, run, video, quiet=False):
        seen.append(video)
        return RenderInfo(path=out, n_frames=0, video_time_s=0.0, wall_time_s=0.0, ms_per_panel=0.0, size=video.size)

    monkeypatch.setattr(runner.run, "render_with_progress", fake_render)  # the one run both commands go through
    fast = ["--max-evals", "2", "--quiet", "--no-summary", "--camera", "front", "--size", "480x270"]
    if command == "animate":
        args = ["animate", str(MODELS / "run_and_step.keyframes.json"), "--out", str(tmp_path / "v.mp4"),
                "--save-path", str(tmp_path / "p.npz")]
    else:
        args = ["mocap", str(MODELS / "cmu" / "127_33.bvh"), "--out-dir", str(tmp_path)]
    assert main(args + fast) == 0
    assert len(seen) == 1 and seen[0].camera == 0.0 and seen[0].size == (480, 270)
    assert seen[0].render_camera().azimuth == pytest.approx(180.0)


def test_a_figure_that_hardly_moves_is_seen_from_its_own_sides():
    """A sidestep in place (0.1 m/s, under the heading's speed threshold) by a figure facing -y: "back"
    puts the camera behind the figure (on +y), whatever way the slow drift goes."""
    model = mujoco.MjModel.from_xml_string(SCENE)
    data = mujoco.MjData(model)
    t = np.arange(0.0, 2.0, 0.05)
    q = np.tile(model.qpos0, (t.size, 1))
    q[:, 0] = 0.1 * t  # a slow drift along +x: the figure's right when it faces -y
    q[:, 3:7] = [np.cos(-np.pi / 4), 0.0, 0.0, np.sin(-np.pi / 4)]  # yaw -90 deg: facing -y
    positions, facing = root_poses(model, data, [q])
    assert facing == pytest.approx(-90.0, abs=1e-9)
    np.testing.assert_allclose(positions[:, 0], 0.1 * t, atol=1e-12)
    cam = VideoOptions(camera=parse_camera("back")).render_camera()
    az = azimuth_path(positions, 0.05, cam, facing)
    looks = np.array([np.cos(np.radians(az[0])), np.sin(np.radians(az[0]))])
    np.testing.assert_allclose(looks, [0.0, -1.0], atol=1e-9)  # looking the way the figure faces


def test_a_legend_says_what_the_ghosts_are():
    """With keyframes, the first panel (only) says in the ghosts' colours that they are keyframe poses
    and that the yellow one is the next, between the picture and its timeline; without, no legend."""
    def yellow(img):
        r, g, b = (img[..., i].astype(int) for i in range(3))
        return int(np.count_nonzero((r > 150) & (g > 110) & (b < 100) & (r - b > 80)))

    for kf_t, expected in ((np.array([0.0, 0.5, 1.0]), True), (np.zeros(0), False)):
        overlay = Overlay(480, 270, 240, 2, None, 0.0, 1.0, kf_t)
        panel = np.full((270, 240, 3), 90, np.uint8)
        f = overlay.compose([panel, panel], ["a", "b"], 0.2, 1.0, current=-1, marks=[None, None])
        drawn = {key[0] for key in overlay._patches}
        assert ("ghosts: keyframe poses" in drawn) == expected
        above_timeline = f[200:250]  # no keyframe is current: nothing else there is yellow
        assert (yellow(above_timeline[:, :240]) > 20) == expected, yellow(above_timeline[:, :240])
        assert yellow(above_timeline[:, 240:]) == 0
