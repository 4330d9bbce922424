"""`dynsplines bench corpus` end to end on a tuning clip and a cut of it (a validation clip: other bytes):
a pair per (clip, keying) in its own folder, the report's figures read from each pair's outputs, both sets
reported apart, a rerun skips what is done, bad options are one line."""
import json
from pathlib import Path

import numpy as np
import pytest
from shipped_sites import SITES

from runner.cli import main
from runner.exit_codes import EXIT_INPUT, EXIT_OK

REPO = Path(__file__).resolve().parents[2]
CLIP = REPO / "models" / "cmu" / "35_17.bvh"
FAST = ["--max-evals", "30", "--quiet"]


def cut(dst: Path, frames: int) -> Path:
    """35_17's header and its first `frames` frames."""
    lines = CLIP.read_text().splitlines()
    m = next(i for i, ln in enumerate(lines) if ln.strip() == "MOTION")
    dst.write_text("\n".join([*lines[:m + 1], f"Frames: {frames}", lines[m + 2], *lines[m + 3:m + 3 + frames]]) + "\n")
    return dst


@pytest.mark.slow
def test_a_corpus_of_two_clips_reports_tuning_and_validation_apart(tmp_path, capsys):
    short = cut(tmp_path / "jog_start.bvh", 80)
    out = tmp_path / "out"
    args = ["bench", "corpus", str(CLIP), str(short), "--every", "0.25", "--keys", "every", "--out", str(out), *FAST]
    assert main(args) == EXIT_OK
    doc = json.loads((out / "corpus.json").read_text())
    assert [(Path(p["clip"]).name, p["keying"], p["set"], p["status"]) for p in doc["pairs"]] == [
        ("35_17.bvh", "every 0.25", "tuning", "ok"), ("jog_start.bvh", "every 0.25", "validation", "ok")]
    text = (out / "corpus.md").read_text()
    assert "## Tuning clips" in text and "## Validation clips" in text and text in capsys.readouterr().out
    for p in doc["pairs"]:
        folder = out / p["folder"]
        report = json.loads((folder / f"{Path(p['clip']).stem}.metrics.json").read_text())
        assert p["figures"]["penetration_mm"] == report["metrics"]["optimized"]["max_penetration_mm"]
        # the longest round: one of the solve's rounds, so within its whole time and more than none of it
        assert 0.0 < report["longest_round_s"] <= report["solve_time_s"]
        # the schedule's flight counted by hand from the keyframe file: frames with no site in contact
        kf = json.loads((folder / f"{Path(p['clip']).stem}.keyframes.json").read_text())
        motion = report["metrics"]["motion"]["plain"]
        t = kf["keyframes"][0]["time"] + np.arange(motion["frames"]) / motion["fps"]
        on = np.zeros(len(t), bool)
        for c in kf["contacts"]:
            assert c["site"] in SITES
            on |= (t >= c["start"] - 1e-9) & (t <= c["end"] + 1e-9)
        assert p["figures"]["schedule_flight_s"] == pytest.approx((~on).sum() / motion["fps"], abs=1e-12)
        checks = {c["bound"]: c for c in p["checks"]}
        assert checks["penetration"]["limit"] == 1.0
        assert checks["penetration"]["held"] == (report["metrics"]["optimized"]["max_penetration_mm"] <= 1.0)
        # off the hinge: each knee and elbow against the capture's own at that joint (the anatomy figures)
        path, cap = (report["metrics"]["motion"][k][w]["off_hinge_deg"] for k, w in (("optimized", "path"), ("plain", "reference")))
        excess = max(path[j] - cap[j] for j in path)
        assert checks["off_hinge"]["held"] == (excess <= 3.0)
        # no jolts: the optimized path's RMS torque against the larger of the plain spline's and the capture's
        mm = report["metrics"]["motion"]
        limit = 1.25 * max(mm["plain"]["path"]["rms_joint_torque_Nm"], mm["plain"]["reference"]["rms_joint_torque_Nm"])
        assert checks["torque_rms"]["held"] == (mm["optimized"]["path"]["rms_joint_torque_Nm"] <= limit)
        assert all(checks[b]["held"] is not None for b in ("pelvis_acc", "joint_acc", "torque_rms"))
    # a rerun solves nothing: every pair is skipped, the report is the same
    assert main(args) == EXIT_OK
    again = json.loads((out / "corpus.json").read_text())
    assert [p["status"] for p in again["pairs"]] == ["skipped", "skipped"]
    assert [p["checks"] for p in again["pairs"]] == [p["checks"] for p in doc["pairs"]]


@pytest.mark.parametrize("option, value", [("--every", "0.25,x"), ("--every", "-1"), ("--keys", "hops")])
def test_bad_keyings_are_one_line(tmp_path, capsys, option, value):
    assert main(["bench", "corpus", str(CLIP), option, value, "--out", str(tmp_path)]) == EXIT_INPUT
    err = capsys.readouterr().err.strip().splitlines()
    assert option in err[-1] and "Traceback" not in "".join(err)


def test_a_missing_clip_is_one_line(tmp_path, capsys):
    assert main(["bench", "corpus", str(tmp_path / "none.bvh"), "--out", str(tmp_path / "o")]) == EXIT_INPUT
    assert "none.bvh: no such clip or folder" in capsys.readouterr().err


def test_the_command_hands_its_options_to_the_corpus(tmp_path, monkeypatch):
    """The argument glue: keyings, workers, engine, scene and the optimization options reach `run_corpus`
    (which is replaced by a recorder: no solve)."""
    import runner.corpus

    seen = {}

    def record(clips, out, keyings_, base, **kw):
        seen.update(clips=clips, out=out, keyings=keyings_, base=base, **kw)
        return {"markdown": "", "paths": (out / "corpus.md", out / "corpus.json"), "batch": {
            "interrupted": False, "totals": {"counts": {"failed": 0}}}}

    monkeypatch.setattr(runner.corpus, "run_corpus", record)
    scene = REPO / "models" / "floor.xml"
    assert main(["bench", "corpus", str(CLIP), "--every", "0.2,0.33", "--keys", "every,contacts", "--workers", "2",
                 "--out", str(tmp_path), "--scene", str(scene), "--terms", "all",
                 "--max-evals", "7", "--rate", "200", "--figure", "default", "--mass", "60", "--root-scale", "1",
                 "--quiet"]) == EXIT_OK
    assert seen["clips"] == [CLIP] and seen["out"] == tmp_path and seen["workers"] == 2 and seen["engine"] == "local"
    assert [k.label for k in seen["keyings"]] == ["every 0.2", "every 0.33", "contacts"]
    base = seen["base"]
    assert (base.scene, base.forces, base.solve.max_evals, base.solve.rate) == (str(scene), True, 7, 200.0)
    assert (base.figure, base.mass, base.root_scale) == ("default", 60.0, 1.0)
    assert seen["quiet"] is True
