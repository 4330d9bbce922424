"""The tracking bound end to end: a shipped clip keyed at its contacts whose feet the contact constraints move
(83_02, a capture whose feet float 8 mm and slide), solved as `bench corpus` solves it. Its contact sites end
no further from the capture than the plain spline's, by the motion metrics (MuJoCo's kinematics at the
capture's frames, `runner.motion_metrics`), where without the bound they ended 22 % further (0.659 cm
against 0.538)."""
import json
from pathlib import Path

import numpy as np
import pytest

from runner.cli import main
from runner.exit_codes import EXIT_OK

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_a_keyed_capture_keeps_its_contact_sites_as_near_the_capture_as_the_plain_spline(tmp_path):
    clip = REPO / "models" / "cmu" / "83_02.bvh"
    out = tmp_path / "out"
    assert main(["bench", "corpus", str(clip), "--keys", "contacts", "--out", str(out), "--quiet"]) == EXIT_OK
    (pair,) = json.loads((out / "corpus.json").read_text())["pairs"]
    report = json.loads((out / pair["folder"] / "83_02.metrics.json").read_text())
    error = {k: report["metrics"]["motion"][k]["error"]["site_position_cm"] for k in ("plain", "optimized")}
    plain, opt = (float(np.mean([s["mean"] for s in error[k].values()])) for k in ("plain", "optimized"))
    assert report["status"] == "converged"  # nothing raised: the bound is met
    assert opt < plain, (opt, plain)
