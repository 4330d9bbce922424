"""End to end: on run-and-step, the contact schedule of the clip (reference_contacts) makes the
optimized path's planted feet float and skate less than the same solve without it."""
import numpy as np
import pytest

from runner.capture.contact_detection import reference_contacts
from runner.capture.reference_motion import load_bvh_reference
from runner.motion_metrics import motion_metrics
from runner.paths import MODELS
from runner.problem_file import RUN_AND_STEP_KEYFRAMES, load_problem
from solver.animate import animate

#: [mm] how deep a point between two of the solve's can be beyond the depth its penetration bound measured: the
#: bound holds the deepest point of each site's cubic Hermite curve between two quadrature points exactly, and the
#: curve departs from the path by h^4/384 max |p''''|, under a micrometre at 200 Hz
SEARCH_RESOLUTION_MM = 1e-3


@pytest.mark.slow
def test_run_and_step_with_contacts_floats_and_skates_less():
    keyframes, _info, model, _layout, _scene = load_problem(RUN_AND_STEP_KEYFRAMES, None)
    ref = load_bvh_reference(MODELS / "cmu" / "127_33.bvh", model)
    contacts = tuple(reference_contacts(model, ref.qpos, ref.frame_time))
    on = ref.times <= keyframes.times[-1] + 1e-9
    got, unmet = {}, {}
    for label, cs in (("without", ()), ("with", contacts)):
        sol = animate(model, keyframes, contacts=cs)  # with a schedule: planted, slide, flight and ground
        got[label] = motion_metrics(model, sol.frames.path(ref.times[on]), 1 / ref.frame_time, ref.qpos[on],
                                    contacts)["path"]
        unmet[label] = sol.unmet
    assert got["with"]["float_contact_mm"] < got["without"]["float_contact_mm"]
    assert got["with"]["skate_contact_mm"] < got["without"]["skate_contact_mm"]
    # penetration within its 1 mm tolerance, up to what the solve reports out of reach [m] (`Solution.unmet`), at
    # the capture's frames, which the solve's points and search resolve to SEARCH_RESOLUTION_MM
    assert got["with"]["penetration_mm"]["max"] <= 1.0 + SEARCH_RESOLUTION_MM + 1e3 * unmet["with"].get("penetration", 0.0)
    assert np.isfinite(got["with"]["flight_time_s"])


@pytest.mark.slow
def test_sparse_keys_float_under_5_mm(tmp_path):
    """127_33 keyed every 0.33 s (a keying the defaults were not chosen on) as `dynsplines mocap CLIP
    --every 0.33 --scene auto --figure default` makes it: mean float in the capture's contacts at most
    5.5 mm (on the shipped figure, whose reference stands on the fitted scene frame by frame; the fitted
    floor is tilted by 1 degree, as the source's own feet show, runner/capture/scene_fit.py).
    """
    import json

    from runner.cli import main

    out = tmp_path / "out"
    assert main(["mocap", str(MODELS / "cmu" / "127_33.bvh"), "--every", "0.33", "--scene", "auto", "--figure", "default", "--out-dir",
                 str(out), "--no-render", "--quiet", "--no-summary", "--metrics", str(tmp_path / "m.json")]) == 0
    motion = json.loads((tmp_path / "m.json").read_text())["metrics"]["motion"]["optimized"]
    assert motion["path"]["float_contact_mm"] <= 5.5
    assert motion["path"]["skate_contact_mm"] <= motion["reference"]["skate_contact_mm"] + 0.5
