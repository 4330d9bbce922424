"""`dynsplines view`: the server's resources, and the page drawn by headless Chromium (slow, `client`): the
figure, drawn with no host but the local server reachable and nothing requested elsewhere; a grid on the
floor and the figure's shadow on it; `?t=` poses the figure at that time."""
import json
import os
import shutil
import subprocess
import tempfile
import urllib.request
from pathlib import Path

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


# Every host but the local server resolves to nothing: a page that needed the network would not draw.
OFFLINE = "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1"


def _chromium():
    """Debian's chromium (or chromium-browser) on PATH; skips without it (a failure in CI: conftest.py)."""
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        pytest.skip("chromium is not installed (apt-get install chromium; README \"Full test suite\")")
    return exe


def _screenshot(url, out, netlog=None):
    """(540, 960, 3) int RGB screenshot of url by headless Chromium, offline (OFFLINE); netlog: a file
    for Chromium's network log (--log-net-log), read by `_page_requests`."""
    with tempfile.TemporaryDirectory() as profile:
        cmd = [_chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
               "--disable-component-update", "--disable-sync", "--no-first-run", OFFLINE,
               f"--user-data-dir={profile}", f"--screenshot={out}", "--window-size=960,540",
               "--virtual-time-budget=5000", url]
        if netlog is not None:
            cmd[1:1] = [f"--log-net-log={netlog}", "--net-log-capture-mode=Default"]
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert Path(out).is_file(), f"chromium wrote no screenshot (exit {res.returncode}): {res.stderr[-2000:]}"
    import imageio.v3 as iio

    return iio.imread(out)[..., :3].astype(int)


def _page_requests(netlog, page_site="http://127.0.0.1"):
    """URLs of the requests a page of page_site made, from Chromium's network log (JSON: constants and
    events; docs: chromium.org "NetLog"): the URL_REQUEST_START_JOB events whose network isolation key's
    top-frame site is the page's, or whose initiator is it. The browser's own background requests (with
    no page) have another key and are left out."""
    log = json.loads(Path(netlog).read_text())
    start = log["constants"]["logEventTypes"]["URL_REQUEST_START_JOB"]
    urls = []
    for e in log["events"]:
        p = e.get("params", {})
        if e["type"] == start and "url" in p and (
                p.get("network_isolation_key", "").startswith(page_site) or p.get("initiator", "").startswith(page_site)):
            urls.append(p["url"])
    return urls


def _figure_red(img):
    """Pixels of the figure's right side (material 'right', rgba 0.85 0.30 0.25) in the middle region."""
    h, w, _ = img.shape
    mid = img[h // 10: 9 * h // 10, w // 4: 3 * w // 4]
    r, g, b = mid[..., 0], mid[..., 1], mid[..., 2]
    return int(((r - g > 50) & (r - b > 50)).sum())


@pytest.mark.slow
@pytest.mark.client
def test_headless_chromium_draws_the_figure_offline(tmp_path):
    """The figure is drawn with no host but the local server reachable (OFFLINE), and every request of
    the page went to the local server (Chromium's network log)."""
    _chromium()
    server, url = serve_in_thread(build_assets(_saved(tmp_path)), 0)
    try:
        shown = _screenshot(url, tmp_path / "shown.png", netlog=tmp_path / "net.json")
        hidden = _screenshot(url + "?show=none", tmp_path / "hidden.png")  # the scene without figures
    finally:
        server.shutdown()
        server.server_close()
    assert shown.shape == (540, 960, 3)
    background = shown[5, shown.shape[1] // 2]
    assert np.abs(shown - background).sum(axis=-1).max() > 100  # something is drawn over the sky
    if os.environ.get("KEEP_VIEWER_SCREENSHOT"):  # a file to look at: KEEP_VIEWER_SCREENSHOT=out.png
        shutil.copy(tmp_path / "shown.png", os.environ["KEEP_VIEWER_SCREENSHOT"])
    h, w, _ = shown.shape
    changed = np.abs(shown - hidden)[h // 10: 9 * h // 10, w // 4: 3 * w // 4].sum(axis=-1) > 60
    assert changed.sum() > 2000, changed.sum()  # the figure (and its ghosts) cover the middle region
    red_shown, red_hidden = _figure_red(shown), _figure_red(hidden)
    assert red_shown > 100, red_shown  # the figure's own colours, not a tint
    assert red_hidden < red_shown / 10, (red_shown, red_hidden)
    requests = _page_requests(tmp_path / "net.json")
    assert {url + name for name in ("", "viewer.js", "three.module.min.js", "scene.glb", "data.json")} <= set(requests)
    assert all(r.startswith(url) for r in requests), [r for r in requests if not r.startswith(url)]


def _dark_runs(line, floor, drop=25):
    """Number of runs of pixels darker than `floor` by more than `drop` along a scan line (n, 3)."""
    dark = (floor - line.mean(axis=-1)) > drop
    return int(np.count_nonzero(np.diff(dark.astype(int)) == 1))


@pytest.mark.slow
@pytest.mark.client
def test_the_floor_has_a_grid_and_the_figure_a_shadow(tmp_path):
    """The grid: dark 1 m lines crossing a scan row of the floor (lines running away from the camera)
    and a scan column (lines across the view). The shadow: floor pixels under the figure darkened by the
    same factor in every channel (a grey floor in shade; the figure's own red, blue and skin colours do
    not scale so), in the lower part of the image, against the same view without the figure."""
    _chromium()
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


def _red_mask(img):
    """(h, w) bool: pixels of the figure's right side (material 'right', rgba 0.85 0.30 0.25) in the middle
    of the view (the figure stands there; the bar's red legend swatch is outside)."""
    h, w, _ = img.shape
    mid = img[h // 10: 9 * h // 10, w // 4: 3 * w // 4]
    r, g, b = mid[..., 0], mid[..., 1], mid[..., 2]
    return (r - g > 50) & (r - b > 50)


def _swinging(tmp_path):
    """A saved path on the run-and-step scene: the pelvis still at (-2.5, 0, 1) m, the right hip and
    shoulder (the figure's red side) swinging about their flexion axis (y) from +50 to -50 deg over 1 s."""
    import mujoco

    from runner.paths import MODELS

    model = mujoco.MjModel.from_xml_path(str(MODELS / "run_and_step.xml"))
    t = np.linspace(0.0, 1.0, 5)
    frames = np.zeros((5, model.nq))
    frames[:, 0], frames[:, 2] = -2.5, 1.0
    frames[:, 3::4][:, :12] = 1.0  # identity quaternions: w at 3, 7, 11, ...
    angle = np.radians(50.0) * np.cos(np.pi * t)
    for joint in ("r_hip", "r_shoulder"):
        adr = model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, joint)]
        frames[:, adr], frames[:, adr + 2] = np.cos(angle / 2), np.sin(angle / 2)
    path = tmp_path / "swing.npz"
    np.savez(path, frame_times=t, frames=frames, plain_frame_times=t, plain_frames=frames,
             keyframe_times=t[::2], keyframes=frames[::2], reference_times=np.zeros(0),
             reference_qpos=np.zeros((0, model.nq)), scene=np.array("models/run_and_step.xml"))
    return path


@pytest.mark.slow
@pytest.mark.client
def test_scrubbing_to_two_times_moves_the_figure(tmp_path):
    """?t= (query.js) poses the figure at that time: the figure's red pixels at t = 0.1 s and 0.9 s differ
    (the right leg and arm swung through 80 deg), while two pages at t = 0.1 s agree: the difference is the
    time, not the renderer."""
    _chromium()
    server, url = serve_in_thread(build_assets(_swinging(tmp_path)), 0)
    view = url + "?show=optimized&hide=keyframes,contacts&t="
    try:
        early, late, again = (_screenshot(view + t, tmp_path / f"{name}.png")
                              for name, t in (("early", "0.1"), ("late", "0.9"), ("again", "0.1")))
        early, late, again = _red_mask(early), _red_mask(late), _red_mask(again)
    finally:
        server.shutdown()
        server.server_close()
    assert early.sum() > 300 and late.sum() > 300, (early.sum(), late.sum())  # the figure is drawn at both times
    moved, same = int((early ^ late).sum()), int((early ^ again).sum())
    assert moved > 0.3 * early.sum(), (moved, int(early.sum()))
    assert same < moved / 20, (same, moved)
