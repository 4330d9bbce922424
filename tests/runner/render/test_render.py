"""runner.render: side-by-side video of tracks, keyframe ghosts, stills, and the input checks.

A tiny inline scene (a free body with a ball-jointed leg, a floor) keeps these independent of the real
figure; sizes and frame counts are small so the file runs in a few seconds on a software renderer.
"""
import imageio.v2 as iio
import mujoco
import numpy as np
import pytest
from render_scenes import one_leg_scene

import runner.render as render
from runner.render import Camera, Track, frame_times, parse_size, render_still, render_tracks, sample_track
from solver import InputError

SCENE = one_leg_scene(toe_site=True, floor_size="5 5 .1",
                      visual='<visual><global offwidth="64" offheight="64"/></visual>')
SIZE = (160, 120)  # two panels of 80 x 120
BODY_ROWS = slice(40, 100)  # rows between the captions at the top and the timeline at the bottom


@pytest.fixture(scope="module")
def model():
    return mujoco.MjModel.from_xml_string(SCENE)


def _path(n=9, t1=0.4, leg_angle=0.0, z=1.0):
    """(n,) times and (n, 11) qpos: the body walks along +x, the leg swung by leg_angle [rad] about y."""
    t = np.linspace(0.0, t1, n)
    q = np.zeros((n, 11))
    q[:, 0] = 0.5 * t
    q[:, 2] = z
    q[:, 3] = 1.0
    q[:, 7] = np.cos(leg_angle / 2)
    q[:, 9] = np.sin(leg_angle / 2)
    return t, q


def _frames(path):
    with iio.get_reader(path) as reader:
        return np.stack(list(reader.iter_data()))


def _halves_diff(frame):
    w = SIZE[0] // 2
    a = frame[BODY_ROWS, :w].astype(float)
    b = frame[BODY_ROWS, w:].astype(float)
    return np.abs(a - b).mean()


@pytest.fixture(scope="module")
def videos(model, tmp_path_factory):
    """The videos several tests read: differing tracks, identical tracks, identical with ghosts."""
    folder = tmp_path_factory.mktemp("videos")
    t, q = _path()
    _, q_swung = _path(leg_angle=1.2)
    calls = []
    out = {}
    out["differ"] = render_tracks(model, [Track("a", t, q), Track("b", t, q_swung)], folder / "differ.mp4",
                                  fps=10, size=SIZE, speed=1.0, progress=lambda i, n: calls.append((i, n)))
    out["same"] = render_tracks(model, [Track("x", t, q), Track("x", t, q)], folder / "same.mp4",
                                fps=10, size=SIZE, speed=1.0)
    kq = _path(n=1, leg_angle=-1.0)[1]
    kq[0, 0] = 0.3
    out["ghosts"] = render_tracks(model, [Track("x", t, q), Track("x", t, q)], folder / "ghosts.mp4",
                                  fps=10, size=SIZE, speed=1.0, keyframe_times=[0.2], keyframe_qpos=kq)
    out["calls"] = calls
    return out


def test_video_frame_count_size_and_info(videos):
    info = videos["differ"]
    # 0.4 s of motion at speed 1 and 10 fps: frames at 0, 0.1, ..., 0.4
    assert info.n_frames == 5
    assert info.video_time_s == pytest.approx(0.5)
    assert info.size == SIZE and info.path.exists()
    assert info.wall_time_s > 0 and info.ms_per_panel > 0
    frames = _frames(info.path)
    assert frames.shape == (5, SIZE[1], SIZE[0], 3)


def test_progress_is_reported_per_frame(videos):
    assert videos["calls"] == [(i, 5) for i in range(1, 6)]


def test_panels_differ_when_tracks_differ(videos):
    differ = _frames(videos["differ"].path)
    same = _frames(videos["same"].path)
    assert min(_halves_diff(f) for f in differ) > 3.0
    assert max(_halves_diff(f) for f in same) < 1.5


def test_keyframe_ghosts_are_drawn(videos):
    same = _frames(videos["same"].path)
    ghosts = _frames(videos["ghosts"].path)
    diff = np.abs(same[:, BODY_ROWS].astype(float) - ghosts[:, BODY_ROWS].astype(float)).mean(axis=(1, 2, 3))
    assert np.all(diff > 0.5), diff  # the ghost is in every frame
    assert _halves_diff(ghosts[2]) < 1.5  # and the same in both panels


def _magenta(frame):
    r, g, b = (frame[..., i].astype(int) for i in range(3))
    return int(np.count_nonzero((r > 180) & (g < 110) & (b > 160)))


def test_penetrating_site_is_marked(model, tmp_path):
    t, q = _path(n=5)
    deep = np.where(t >= 0.2, 0.05, 0.0)[:, None]  # 5 cm inside a surface from t = 0.2 s on
    tracks = [Track("in", t, q, penetration=deep, sites=("toe",)), Track("out", t, q)]
    info = render_tracks(model, tracks, tmp_path / "pen.mp4", fps=10, size=SIZE, speed=1.0)
    frames = _frames(info.path)
    w = SIZE[0] // 2
    assert _magenta(frames[0]) == 0
    assert _magenta(frames[4][:, :w]) > 20
    assert _magenta(frames[4][:, w:]) == 0


def test_project_matches_the_rendered_image(model):
    renderer = render.gl.make_renderer(model, 96, 64)
    try:
        panel = render.overlays.Panel(model, renderer)
        q = _path(n=1)[1][0]
        panel.set_camera(Camera(distance=3.0), np.array([0.0, 0.0, 1.0]))
        image = panel.render(q)
        top = panel.data.xpos[1] + [0, 0, 0.5]  # top end of the pelvis capsule, centred in the image
        px, py = panel.project(np.array([[0.0, 0.0, 1.0], top]))[1].round().astype(int)
        # just below the projected top of the capsule it is the capsule's colour (0.8 0.6 0.4), above it not
        below, above = image[py + 4, px].astype(int), image[max(py - 6, 0), px].astype(int)
        assert below[0] > below[2] + 40 and not above[0] > above[2] + 40
        centre = panel.project(np.array([[0.0, 0.0, 1.0]]))[0]
        np.testing.assert_allclose(centre, [48, 32], atol=1.0)  # the look-at point is the image centre
    finally:
        renderer.close()


def test_offscreen_buffer_is_raised_and_restored(model, tmp_path):
    assert model.vis.global_.offwidth == 64
    out = render_still(model, _path(n=1)[1][0], tmp_path / "still.png", size=(200, 150), label="still")
    image = iio.imread(out)
    assert image.shape[:2] == (150, 200)
    assert model.vis.global_.offwidth == 64 and model.vis.global_.offheight == 64


def test_failed_render_leaves_earlier_video_intact(model, tmp_path, videos):
    out = tmp_path / "clip.mp4"
    out.write_bytes(videos["differ"].path.read_bytes())
    before = out.read_bytes()

    def boom(i, n):
        if i == 2:
            raise RuntimeError("interrupted")

    t, q = _path()
    with pytest.raises(RuntimeError, match="interrupted"):
        render_tracks(model, [Track("a", t, q)], out, fps=10, size=SIZE, speed=1.0, progress=boom)
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clip.mp4"]


def test_frame_times_and_sampling():
    t = frame_times(0.0, 1.0, fps=30, speed=0.5)
    assert t.size == 61 and t[0] == 0.0 and t[-1] == 1.0
    np.testing.assert_allclose(np.diff(t), 0.5 / 30)
    t = frame_times(0.0, 0.95, fps=10, speed=1.0)  # not a whole number of steps: last frame at the end
    np.testing.assert_allclose(t, [0, .1, .2, .3, .4, .5, .6, .7, .8, .9, .95])
    tr = Track("x", [0.0, 1.0, 3.0], [[0.0, 10.0], [1.0, 10.0], [5.0, 10.0]])
    np.testing.assert_allclose(sample_track(tr, [-1.0, 0.5, 2.0, 4.0]),
                               [[0, 10], [0.5, 10], [3, 10], [5, 10]])


@pytest.mark.parametrize("size, message", [
    ("960x540", None), ((960, 540), None), ("abc", "WIDTHxHEIGHT"), ("0x10", "positive"),
    ((10.5, 20), "integers"), ((10,), r"\(width, height\)"), ("-4x4", "positive"),
])
def test_parse_size(size, message):
    if message is None:
        assert parse_size(size) == (960, 540)
    else:
        with pytest.raises(InputError, match=message):
            parse_size(size)


def test_track_checks_shapes():
    with pytest.raises(InputError, match=r"qpos must have shape \(n, nq\) = \(3, nq\)"):
        Track("a", [0, 1, 2], np.zeros((2, 11)))
    with pytest.raises(InputError, match="strictly increasing"):
        Track("a", [0, 1, 1], np.zeros((3, 11)))
    with pytest.raises(InputError, match="finite"):
        Track("a", [0, 1], [[0.0], [np.nan]])
    with pytest.raises(InputError, match=r"penetration must have shape"):
        Track("a", [0, 1], np.zeros((2, 11)), penetration=np.zeros((2, 2)), sites=("toe",))


@pytest.mark.parametrize("kwargs, message", [
    (dict(size="big"), "WIDTHxHEIGHT"),
    (dict(size=(161, 120)), "even"),
    (dict(fps=0), "fps must be a positive number"),
    (dict(fps=-30), "fps must be a positive number"),
    (dict(speed=float("nan")), "speed must be a positive number"),
    (dict(size=(30, 120)), "at least 16x16"),
    (dict(keyframe_times=[0.1], keyframe_qpos=np.zeros((2, 11))),
     r"keyframe_qpos must have shape \(m, nq\) = \(1, 11\)"),
    (dict(keyframe_qpos=np.zeros((1, 11))), "needs keyframe_times"),
    (dict(quality="ultra"), r"unknown render quality 'ultra'; choose one of \['fast', 'high'\]"),
])
def test_render_tracks_input_errors(model, tmp_path, kwargs, message):
    t, q = _path()
    tracks = [Track("a", t, q), Track("b", t, q)]
    with pytest.raises(InputError, match=message):
        render_tracks(model, tracks, tmp_path / "x.mp4", **{"size": SIZE, **kwargs})
    assert list(tmp_path.iterdir()) == []


def test_render_tracks_model_mismatch(model, tmp_path):
    t, q = _path()
    with pytest.raises(InputError, match=r"qpos has 10 columns but the model has nq = 11"):
        render_tracks(model, [Track("a", t, q[:, :10])], tmp_path / "x.mp4", size=SIZE)
    with pytest.raises(InputError, match=r"site 'heel' is not in the model; sites: \['toe'\]"):
        render_tracks(model, [Track("a", t, q, penetration=np.zeros(len(t)), sites=("heel",))],
                      tmp_path / "x.mp4", size=SIZE)


def test_bad_output_paths(model, tmp_path):
    t, q = _path()
    with pytest.raises(InputError, match=r"must end in one of \['.mp4', '.mkv', '.mov'\]"):
        render_tracks(model, [Track("a", t, q)], tmp_path / "x.gif", size=SIZE)
    (tmp_path / "renders").write_text("a file, not a folder")
    with pytest.raises(InputError, match="cannot write .*choose another --out"):
        render_tracks(model, [Track("a", t, q)], tmp_path / "renders" / "x.mp4", size=SIZE)
    with pytest.raises(InputError, match=r"qpos must have shape \(nq,\) = \(11,\)"):
        render_still(model, q, tmp_path / "x.png")


def test_missing_opengl_is_explained(model, tmp_path, monkeypatch):
    class NoGL:
        def __init__(self, *args, **kwargs):
            raise RuntimeError("Cannot initialize a EGL device display")

    monkeypatch.setattr(render.gl.mujoco, "Renderer", NoGL)
    t, q = _path()
    message = r"needs EGL \(Mesa\): set MUJOCO_GL=egl or osmesa; or use --no-render"
    with pytest.raises(InputError, match=message):
        render_tracks(model, [Track("a", t, q)], tmp_path / "x.mp4", size=SIZE)
    assert list(tmp_path.iterdir()) == []
