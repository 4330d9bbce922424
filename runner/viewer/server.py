"""Build the viewer's resources from a saved path and serve them on 127.0.0.1 (`runner.viewer` docstring)."""
from __future__ import annotations

import http.server
import json
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from solver.errors import InputError

__all__ = ["STATIC", "CONTACT_HEIGHT", "PENETRATION", "ViewerAssets", "build_assets", "floor_height", "make_server",
           "serve"]

STATIC = Path(__file__).resolve().parent / "static"
#: a contact site this close to a surface, or closer, is drawn "in contact" [m] (1 cm: a resting foot
#: within the 2 mm keyed clearance and the capture's own mm-scale jitter, a lifting one not yet).
CONTACT_HEIGHT = 0.01
#: [m] a contact site deeper than this inside a surface is drawn "penetrating".
PENETRATION = 0.0005
#: [Hz] sample rate of the motions in the viewer when the path has no reference clip (else the clip's).
VIEW_FPS = 60.0


@dataclass(frozen=True)
class ViewerAssets:
    """glb: the scene and every motion (bytes). data: the JSON-ready description (`build_assets`)."""

    glb: bytes
    data: dict


def build_assets(npz: str | Path) -> ViewerAssets:
    """The viewer's `scene.glb` and `data.json` for a saved path.

    data: {"source", "scene", "tracks": [{"name", "start", "duration", "fps", "samples",
    "sites": {site: [state per sample]}}], "keyframe_times", "sites", "states": ["clear", "contact",
    "penetrating"], "max_penetration_mm": {track: mm}, "floor_height": [m] the height of the scene's
    horizontal floor plane (None without one; the page draws its grid there)}.

    Raises:
        InputError: unreadable path or scene (see `runner.saved_path.load_saved_path`).
    """
    from runner.export.gltf import Track, figure_gltf, glb_bytes
    from runner.export.sampling import default_fps, sample_motion
    from runner.saved_path import load_saved_path
    from solver.figure import Figure
    from solver.layout import StateLayout
    from solver.model import load_model
    from solver.terms.penetration import Penetration

    saved = load_saved_path(npz)
    model = load_model(saved.scene)
    if model.nq != saved.nq:
        raise InputError(f"{npz}: frames have {saved.nq} columns but the scene {saved.scene} has nq = {model.nq}; "
                         "the path was made for another figure")
    fps = default_fps(saved) if saved.has_reference else VIEW_FPS
    slots = StateLayout.from_model(model).quat_slots
    sites = Figure.from_model(model).contact_sites
    names = ["optimized", "plain"] + (["reference"] if saved.has_reference else [])
    motions = [sample_motion(saved, w, fps, slots) for w in names]
    pen = Penetration(model, sites=sites, margin=0.0)
    tracks, worst = [], {}
    for m in motions:
        depth = pen.depths(m.qpos, margin=0.0)  # (n, 4) [m]
        near = pen.depths(m.qpos, margin=CONTACT_HEIGHT) > 0.0
        state = np.where(depth > PENETRATION, 2, np.where(near, 1, 0))
        tracks.append({"name": m.name, "start": float(m.times[0]), "duration": float(m.times[-1] - m.times[0]),
                       "fps": m.fps, "samples": len(m.times),
                       "sites": {s: state[:, i].tolist() for i, s in enumerate(sites)}})
        worst[m.name] = round(1000.0 * float(depth.max()), 3)
    gltf = figure_gltf(model, [Track(m.name, m.times, m.qpos) for m in motions], sites=sites, skinned=False)
    data = {"source": str(saved.source), "scene": str(saved.scene), "tracks": tracks,
            "keyframe_times": [float(t) for t in saved.keyframe_times], "sites": list(sites),
            "states": ["clear", "contact", "penetrating"], "max_penetration_mm": worst,
            "contact_height_m": CONTACT_HEIGHT, "penetration_m": PENETRATION, "floor_height": floor_height(model)}
    return ViewerAssets(glb_bytes(gltf), data)


def floor_height(model) -> float | None:
    """[m] height of the scene's floor: the lowest world plane whose normal points up (within 1 degree),
    None if there is none."""
    from solver.surfaces import StaticSurfaces

    s = StaticSurfaces.from_model(model)
    up = s.plane_normal[:, 2] > np.cos(np.radians(1.0)) if len(s.plane_normal) else np.zeros(0, bool)
    return float(s.plane_point[up, 2].min()) if up.any() else None


class _Handler(http.server.SimpleHTTPRequestHandler):
    assets: ViewerAssets = None  # set per server by make_server

    def __init__(self, *a, **k):
        super().__init__(*a, directory=str(STATIC), **k)

    def do_GET(self):
        path = self.path.split("?", 1)[0]
        if path == "/scene.glb":
            return self._send(self.assets.glb, "model/gltf-binary")
        if path == "/data.json":
            return self._send(json.dumps(self.assets.data).encode(), "application/json")
        return super().do_GET()

    def _send(self, body: bytes, kind: str):
        self.send_response(200)
        self.send_header("Content-Type", kind)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        self.wfile.write(body)

    def end_headers(self):
        self.send_header("Cache-Control", "no-store")
        super().end_headers()

    def guess_type(self, path):
        return "text/javascript" if str(path).endswith(".js") else super().guess_type(path)

    def log_message(self, fmt, *args):  # quiet: the command prints the address once
        pass


def make_server(assets: ViewerAssets, port: int = 0) -> http.server.ThreadingHTTPServer:
    """An HTTP server on 127.0.0.1:`port` (0: a free port) serving the viewer for `assets`.

    Raises:
        InputError: the port is in use or not allowed.
    """
    handler = type("Handler", (_Handler,), {"assets": assets})
    try:
        return http.server.ThreadingHTTPServer(("127.0.0.1", port), handler)
    except OSError as e:
        raise InputError(f"--port {port}: cannot listen on 127.0.0.1:{port} ({e.strerror or e}); choose another "
                         "port, or --port 0 for a free one") from None


def serve(assets: ViewerAssets, port: int = 0, ready=None) -> None:
    """Serve until interrupted (Ctrl-C). `ready(url)` is called once listening."""
    server = make_server(assets, port)
    url = f"http://127.0.0.1:{server.server_address[1]}/"
    if ready is not None:
        ready(url)
    try:
        server.serve_forever()
    finally:
        server.server_close()


def serve_in_thread(assets: ViewerAssets, port: int = 0):
    """(server, url) with the server running in a daemon thread (tests; stop with server.shutdown())."""
    server = make_server(assets, port)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, f"http://127.0.0.1:{server.server_address[1]}/"
