"""`dynsplines view`: the server's resources, and the page drawn by headless Chromium (slow): the figure,
a grid on the floor and the figure's shadow on it."""
import json
import shutil
import subprocess
import tempfile
import urllib.request

import numpy as np
import pytest

from runner.viewer.server import STATIC, build_assets, make_server, serve_in_thread
from solver.errors import InputError


def _saved(tmp_path):
    import mujoco

    from runner.paths import MODELS

    model = mujoco.MjModel.from_xml_path(str(MODELS / "run_and_step.xml"))
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 1.0, 5)
    frames = np.zeros((5, model.nq))
    frames[:, 0] = np.linspace(-2.5, -1.5, 5)
    frames[:, 2] = 1.0
    frames[:, 3::4][:, :12] = 1.0  # identity quaternions: w at 3, 7, 11, ...
    frames[:, 8] = rng.normal(0, 0.2, 5)  # a little hip motion
    path = tmp_path / "view.npz"
    np.savez(path, frame_times=t, frames=frames, plain_frame_times=t[::2], plain_frames=frames[::2],
             keyframe_times=t[::2], keyframes=frames[::2], reference_times=np.zeros(0),
             reference_qpos=np.zeros((0, model.nq)), scene=np.array("models/run_and_step.xml"))
    return path


def test_static_files_are_vendored_and_small():
    size = sum(p.stat().st_size for p in STATIC.iterdir())
    assert size < 1.5e6
    assert {"index.html", "viewer.js", "query.js", "three.module.min.js", "GLTFLoader.js", "OrbitControls.js"} <= {
        p.name for p in STATIC.iterdir()}
    for page in ("index.html", "viewer.js", "query.js"):  # offline: nothing is fetched from another host
        assert "http://" not in (STATIC / page).read_text() and "https://" not in (STATIC / page).read_text()


def test_server_serves_page_scene_and_data(tmp_path):
    assets = build_assets(_saved(tmp_path))
    assert [t["name"] for t in assets.data["tracks"]] == ["optimized", "plain"]  # no reference in this path
    assert len(assets.data["tracks"][0]["sites"]["l_heel"]) == assets.data["tracks"][0]["samples"]
    server, url = serve_in_thread(assets, 0)
    try:
        assert url.startswith("http://127.0.0.1:")
        page = urllib.request.urlopen(url).read().decode()
        assert "viewer.js" in page
        glb = urllib.request.urlopen(url + "scene.glb").read()
        assert glb[:4] == b"glTF" and glb == assets.glb
        data = json.loads(urllib.request.urlopen(url + "data.json").read())
        assert data["keyframe_times"] == [0.0, 0.5, 1.0]
        assert data["floor_height"] == 0.0  # models/run_and_step.xml: the floor plane at z = 0
        js = urllib.request.urlopen(url + "viewer.js")
        assert js.headers["Content-Type"].startswith("text/javascript")
        with pytest.raises(InputError, match=f"--port {server.server_address[1]}: cannot listen"):
            make_server(assets, server.server_address[1])
    finally:
        server.shutdown()
        server.server_close()


def _screenshot(url, out):
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    with tempfile.TemporaryDirectory() as profile:
        subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                        "--disable-component-update", "--disable-sync", "--no-first-run",
                        f"--user-data-dir={profile}", f"--screenshot={out}", "--window-size=960,540",
                        "--virtual-time-budget=5000", url], capture_output=True, timeout=120)
    import imageio.v3 as iio

    return iio.imread(out)[..., :3].astype(int)


def _figure_red(img):
    """Pixels of the figure's right side (material 'right', rgba 0.85 0.30 0.25) in the middle region."""
    h, w, _ = img.shape
    mid = img[h // 10: 9 * h // 10, w // 4: 3 * w // 4]
    r, g, b = mid[..., 0], mid[..., 1], mid[..., 2]
    return int(((r - g > 50) & (r - b > 50)).sum())


@pytest.mark.slow
def test_headless_chromium_draws_the_figure(tmp_path):
    if not (shutil.which("chromium") or shutil.which("chromium-browser")):
        pytest.skip("chromium is not installed (apt-get install chromium)")
    server, url = serve_in_thread(build_assets(_saved(tmp_path)), 0)
    try:
        shown = _screenshot(url, tmp_path / "shown.png")
        hidden = _screenshot(url + "?show=none", tmp_path / "hidden.png")  # the scene without figures
    finally:
        server.shutdown()
        server.server_close()
    assert shown.shape == (540, 960, 3)
    background = shown[5, shown.shape[1] // 2]
    assert np.abs(shown - background).sum(axis=-1).max() > 100  # something is drawn over the sky
    shutil.copy(tmp_path / "shown.png", "/tmp/export_view_test.png") if __import__("os").environ.get(
        "KEEP_VIEWER_SCREENSHOT") else None
    h, w, _ = shown.shape
    changed = np.abs(shown - hidden)[h // 10: 9 * h // 10, w // 4: 3 * w // 4].sum(axis=-1) > 60
    assert changed.sum() > 2000, changed.sum()  # the figure (and its ghosts) cover the middle region
    red_shown, red_hidden = _figure_red(shown), _figure_red(hidden)
    assert red_shown > 100, red_shown  # the figure's own colours, not a tint
    assert red_hidden < red_shown / 10, (red_shown, red_hidden)


def _chromium_or_skip():
    if not (shutil.which("chromium") or shutil.which("chromium-browser")):
        pytest.skip("chromium is not installed (apt-get install chromium)")


def _dark_runs(line, floor, drop=25):
    """Number of runs of pixels darker than `floor` by more than `drop` along a scan line (n, 3)."""
    dark = (floor - line.mean(axis=-1)) > drop
    return int(np.count_nonzero(np.diff(dark.astype(int)) == 1))


@pytest.mark.slow
def test_the_floor_has_a_grid_and_the_figure_a_shadow(tmp_path):
    """The grid: dark 1 m lines crossing a scan row of the floor (lines running away from the camera)
    and a scan column (lines across the view). The shadow: floor pixels under the figure darkened by the
    same factor in every channel (a grey floor in shade; the figure's own red, blue and skin colours do
    not scale so), in the lower part of the image, against the same view without the figure."""
    _chromium_or_skip()
    server, url = serve_in_thread(build_assets(_saved(tmp_path)), 0)
    try:
        shown = _screenshot(url + "?show=optimized&hide=keyframes,contacts", tmp_path / "shown.png")
        empty = _screenshot(url + "?show=none&hide=keyframes,contacts", tmp_path / "empty.png")
    finally:
        server.shutdown()
        server.server_close()
    h, w, _ = empty.shape
    floor = float(np.median(empty[int(0.8 * h), : w // 3].mean(axis=-1)))
    assert _dark_runs(empty[int(0.8 * h), : w // 2], floor) >= 3  # lines towards the horizon
    assert _dark_runs(empty[int(0.5 * h): int(0.88 * h), w // 8], floor) >= 3  # lines across the view
    ratio = (shown + 1.0) / (empty + 1.0)
    grey = (empty.max(-1) - empty.min(-1)) < 30
    shade = grey & (ratio.max(-1) < 0.85) & (ratio.min(-1) > 0.3) & (np.ptp(ratio, axis=-1) < 0.08)
    shade[: int(0.55 * h)] = False
    assert shade.sum() > 200, shade.sum()
