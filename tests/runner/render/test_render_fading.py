"""What a new user sees in the video: keyframe ghosts only near their keyframe, fading;
the "keyframe k" caption gone once the keyframe has passed; the title above the panels, not across a
divider; a camera that turns with the direction of travel; no illegible text at small sizes; the
motion capture as a third panel."""
import json
from pathlib import Path

import imageio.v2 as iio
import mujoco
import numpy as np
import pytest
from render_scenes import one_leg_scene

from runner.cli import main
from runner.exit_codes import EXIT_INPUT
from runner.render import Camera, Track, render_tracks
from runner.render import tracks as tracks_module

SCENE = one_leg_scene()
SIZE = (480, 270)  # labels shown (LABELS_MIN_SIZE is 320x180)
REPO = Path(__file__).resolve().parents[3]
MODELS = REPO / "models"


@pytest.fixture(scope="module")
def model():
    return mujoco.MjModel.from_xml_string(SCENE)


def path(t1=1.0, n=11, direction=(1.0, 0.0)):
    t = np.linspace(0.0, t1, n)
    q = np.zeros((n, 11))
    q[:, :2] = 1.0 * t[:, None] * np.asarray(direction)
    q[:, 2] = 1.0
    q[:, 3] = 1.0
    q[:, 7] = 1.0
    return t, q


def frames(p):
    with iio.get_reader(p) as r:
        return np.stack(list(r.iter_data()))


def yellow_pixels(img):
    r, g, b = (img[..., i].astype(int) for i in range(3))
    return int(np.count_nonzero((r > 150) & (g > 110) & (b < 100) & (r - b > 80)))


@pytest.fixture(scope="module")
def pair(model, tmp_path_factory):
    """The same motion without and with one keyframe ghost (at t = 0.2 s, leg swung)."""
    folder = tmp_path_factory.mktemp("fading")
    t, q = path()
    kq = q[2:3].copy()
    kq[0, 7], kq[0, 9] = np.cos(0.5), np.sin(0.5)
    kw = dict(fps=10, size=SIZE, speed=1.0, camera=Camera(distance=3.0))
    plain = render_tracks(model, [Track("a", t, q), Track("b", t, q)], folder / "plain.mp4", **kw)
    ghost = render_tracks(model, [Track("a", t, q), Track("b", t, q)], folder / "ghost.mp4",
                          keyframe_times=[0.2], keyframe_qpos=kq, **kw)
    return frames(plain.path), frames(ghost.path)


def test_a_ghost_is_shown_only_near_its_keyframe(pair):
    plain, ghost = pair  # frames at t = 0.0, 0.1, ..., 1.0; the keyframe at 0.2
    body = slice(60, 230)
    diff = np.abs(plain[:, body].astype(float) - ghost[:, body].astype(float)).mean(axis=(1, 2, 3))
    assert diff[2] > 0.5, diff  # at the keyframe
    assert diff[2] > diff[1] > diff[0] and diff[2] > diff[3] > diff[4], diff  # fading in and out
    assert np.all(diff[6:] < 0.15 * diff[2]), diff  # gone 0.3 s and more after it (video coding noise left)


def test_the_keyframe_caption_does_not_linger_after_the_keyframe(pair):
    _, ghost = pair
    captions = slice(15, 40)  # the caption line under the labels (the timeline is at the bottom)
    counts = [yellow_pixels(f[captions]) for f in ghost]
    assert counts[2] > 20, counts  # at the keyframe: "keyframe 0 (t = 0.20 s)"
    assert all(c < 10 for c in counts[3:]), counts  # gone once it has passed


def test_the_title_sits_above_the_panels(tmp_path):
    sky = '<asset><texture type="skybox" builtin="flat" rgb1=".2 .4 .9" rgb2=".2 .4 .9" width="8" height="8"/></asset>'
    model = mujoco.MjModel.from_xml_string(SCENE.replace("<worldbody>", sky + "<worldbody>", 1))
    t, q = path(t1=0.2, n=3)
    info = render_tracks(model, [Track("a", t, q), Track("b", t, q)], tmp_path / "t.mp4", fps=10, size=SIZE,
                         speed=1.0, title="a title long enough to cross the divider between the panels")
    f = frames(info.path)[0]
    band = f[:12].astype(int)  # the title's band: dark background and text, no scene (no sky)
    sky = (band[..., 2] > 120) & (band[..., 2] > band[..., 0] + 30)
    assert sky.mean() < 0.02
    below = f[30:60].astype(int)  # the panels (the sky) start under the band
    assert ((below[..., 2] > 120) & (below[..., 2] > below[..., 0] + 30)).mean() > 0.5


def test_the_camera_turns_with_the_direction_of_travel():
    t = np.arange(0, 2.0, 0.02)
    pos = np.stack([1.5 * t, 1.5 * t, np.ones_like(t)], axis=1)  # a diagonal run, 45 degrees
    az = tracks_module.azimuth_path(pos, 0.02, Camera())
    np.testing.assert_allclose(az, -45.0, atol=1e-6)  # -90 relative to a heading of +45
    still = np.tile([0.0, 0.0, 1.0], (len(t), 1))
    np.testing.assert_allclose(tracks_module.azimuth_path(still, 0.02, Camera()), -90.0)  # no travel: +x
    np.testing.assert_allclose(tracks_module.azimuth_path(pos, 0.02, Camera(follow=False)), -90.0)


def test_small_videos_have_no_text(model, tmp_path):
    t, q = path(t1=0.2, n=3)
    a = render_tracks(model, [Track("plain spline", t, q)], tmp_path / "a.mp4", fps=10, size=(64, 48),
                      speed=1.0, keyframe_times=[0.0], title="dynsplines: a long title")
    b = render_tracks(model, [Track("x", t, q)], tmp_path / "b.mp4", fps=10, size=(64, 48), speed=1.0,
                      keyframe_times=[0.0])
    fa, fb = frames(a.path), frames(b.path)
    np.testing.assert_array_equal(fa[:, :30], fb[:, :30])  # labels, caption and title not drawn


def small_keyframes(tmp_path, clip=True):
    doc = json.loads((MODELS / "run_and_step.keyframes.json").read_text())
    doc["keyframes"] = doc["keyframes"][:3]
    doc["scene"] = str(MODELS / "run_and_step.xml")
    doc.pop("model", None)
    doc["source"] = {"clip": str(MODELS / "cmu" / "127_33.bvh")} if clip else {}
    p = tmp_path / "k.json"
    p.write_text(json.dumps(doc))
    return p


def test_reference_panel_needs_a_clip(tmp_path, capsys):
    code = main(["animate", str(small_keyframes(tmp_path, clip=False)), "--panels", "plain,optimized,reference",
                 "--out", str(tmp_path / "v.mp4"), "--quiet"])
    err = capsys.readouterr().err
    assert code == EXIT_INPUT and "--panels reference" in err and "names no motion-capture clip" in err


def test_reference_panel_is_rendered(tmp_path):
    out = tmp_path / "v.mp4"
    assert main(["animate", str(small_keyframes(tmp_path)), "--reference-panel", "--out", str(out),
                 "--size", "480x270", "--fps", "4", "--speed", "1", "--max-evals", "2", "--quiet"]) == 0
    f = frames(out)
    assert f.shape[1:] == (270, 480, 3)
    w = 160  # three panels
    third, first = f[:, 40:250, 2 * w:].astype(float), f[:, 40:250, :w].astype(float)
    assert np.abs(third - first).mean() > 1.0  # the motion capture is not the plain spline
