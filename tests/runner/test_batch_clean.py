"""`dynsplines batch --mode clean`: each clip cleaned into its folder with the clean's figures in the summary
(the deviation checked against MuJoCo's forward kinematics of the saved path), a bad clip a failed row, a rerun
skips what is done; --pin holds every clip at the capture there, a pin outside a clip is that clip's row; mocap's
keying options are refused in one line, and the pins with --mode mocap; the totals of hand-made rows."""
import csv
import json
from pathlib import Path

import mujoco
import numpy as np
import pytest
from bvh_edit import edit_bvh

from runner.batch import CLEAN_COLUMNS, totals
from runner.cli import main
from runner.exit_codes import EXIT_FAILED, EXIT_INPUT

CLIP = Path(__file__).resolve().parents[2] / "models" / "cmu" / "127_33.bvh"


def short_clip(dst: Path) -> Path:
    """127_33's first 0.25 s (30 frames at 120 Hz)."""
    return edit_bvh(CLIP, dst, seconds=0.25)


def read_csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def deviation_cm(npz: Path) -> tuple[float, float]:
    """Mean and max distance [cm] between every body's origin on the cleaned clip and on the capture."""
    z = np.load(npz)
    model = mujoco.MjModel.from_xml_path(str(npz.parent / Path(str(z["scene"])).name))
    data = mujoco.MjData(model)

    def xpos(q):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        return data.xpos[1:].copy()

    d = np.array([np.linalg.norm(xpos(a) - xpos(b), axis=1) for a, b in zip(z["path_qpos"], z["reference_qpos"])])
    return 100 * d.mean(), 100 * d.max()


def test_a_clean_per_clip_and_a_bad_clip_failed(tmp_path):
    clips = tmp_path / "clips"
    clips.mkdir()
    short_clip(clips / "a.bvh")
    (clips / "corrupt.bvh").write_text((clips / "a.bvh").read_text()[:3000])
    out = tmp_path / "out"
    args = ["batch", str(clips), "--out", str(out), "--mode", "clean", "--quiet"]
    assert main(args) == EXIT_FAILED
    rows = read_csv(out / "summary.csv")
    assert tuple(rows[0]) == CLEAN_COLUMNS
    by = {Path(r["clip"]).name: r for r in rows[:-1]}
    assert by["a.bvh"]["status"] == "ok" and by["corrupt.bvh"]["status"] == "failed"
    assert "HIERARCHY" in by["corrupt.bvh"]["error"] and not (out / "corrupt" / "done.json").exists()
    assert {"a.clean.npz", "a.clean.bvh", "a.clean.metrics.json", "done.json"} <= {p.name for p in (out / "a").iterdir()}
    mean, top = deviation_cm(out / "a" / "a.clean.npz")
    a = by["a.bvh"]
    assert float(a["deviation_mean_cm"]) == pytest.approx(mean, rel=1e-4, abs=1e-6)
    assert float(a["deviation_max_cm"]) == pytest.approx(top, rel=1e-4, abs=1e-6)
    assert float(a["penetration_mm"]) >= 0 and float(a["cpu_s"]) > 0 and float(a["capture_pelvis_m_s2"]) > 0
    assert rows[-1]["status"] == "1 ok, 1 failed"
    assert json.loads((out / "summary.json").read_text())["options"]["mode"] == "clean"
    # rerun: the clean is skipped, the bad clip tried again
    assert main(args) == EXIT_FAILED
    by = {Path(r["clip"]).name: r for r in read_csv(out / "summary.csv")[:-1]}
    assert (by["a.bvh"]["status"], by["corrupt.bvh"]["status"]) == ("skipped", "failed")
    assert float(by["a.bvh"]["deviation_mean_cm"]) == pytest.approx(mean, rel=1e-4, abs=1e-6)


def test_a_pin_holds_the_capture_and_a_pin_outside_a_clip_is_its_error(tmp_path):
    """The same --pin for every clip: on the 0.25 s clip the cleaned path is the capture at the pinned frame
    (where the clean without pins moves it by ~0.26 in qpos), on the 0.1 s clip the pin is outside, its row."""
    clips = tmp_path / "clips"
    clips.mkdir()
    short_clip(clips / "a.bvh")
    edit_bvh(CLIP, clips / "b.bvh", seconds=0.1)
    out = tmp_path / "out"
    assert main(["batch", str(clips), "--out", str(out), "--mode", "clean", "--pin", "0.2", "--quiet"]) == EXIT_FAILED
    by = {Path(r["clip"]).name: r for r in read_csv(out / "summary.csv")[:-1]}
    assert by["a.bvh"]["status"] == "ok" and by["b.bvh"]["status"] == "failed"
    assert "--pin 0.2: outside the clip's" in by["b.bvh"]["error"] and not (out / "b" / "done.json").exists()
    z = np.load(out / "a" / "a.clean.npz")
    k = int(np.argmin(np.abs(z["path_times"] - 0.2)))
    assert abs(z["path_times"][k] - 0.2) <= 0.5 / 120  # the nearest of the 120 Hz capture's frames
    np.testing.assert_allclose(z["path_qpos"][k], z["reference_qpos"][k], rtol=0, atol=1e-9)
    assert np.abs(z["path_qpos"] - z["reference_qpos"]).max() > 1e-3  # the clean moved the clip elsewhere


def test_pins_with_mode_mocap_are_refused_in_one_line(tmp_path, capsys):
    short_clip(tmp_path / "a.bvh")
    assert main(["batch", str(tmp_path / "a.bvh"), "--out", str(tmp_path / "o"), "--pin", "0.1", "--pin-ends"]) == EXIT_INPUT
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--pin, --pin-ends" in err and "--mode clean" in err
    assert not (tmp_path / "o" / "summary.csv").exists()


def test_gauss_newton_reaches_each_clip_and_is_clean_only(tmp_path, capsys):
    """--gauss-newton sets the clean's LeastChangeOptions.newton for every clip of a batch, and batch and bench
    corpus refuse it in one line with --mode mocap, where no clean runs."""
    import argparse

    from runner.commands import batch

    sub = argparse.ArgumentParser().add_subparsers()
    batch.register(sub)
    args = sub.choices["batch"].parse_args([str(tmp_path), "--out", str(tmp_path / "o"), "--mode", "clean", "--gauss-newton"])
    assert batch.clean_options(args).solve.newton
    args = sub.choices["batch"].parse_args([str(tmp_path), "--out", str(tmp_path / "o"), "--mode", "clean"])
    assert not batch.clean_options(args).solve.newton
    short_clip(tmp_path / "a.bvh")
    for argv in (["batch", str(tmp_path / "a.bvh"), "--out", str(tmp_path / "o"), "--gauss-newton"],
                 ["bench", "corpus", str(tmp_path / "a.bvh"), "--out", str(tmp_path / "o"), "--gauss-newton"]):
        assert main(argv) == EXIT_INPUT
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "--gauss-newton" in err and "--mode clean" in err
    assert not (tmp_path / "o" / "summary.csv").exists()


def test_keying_options_are_refused_in_one_line(tmp_path, capsys):
    short_clip(tmp_path / "a.bvh")
    assert main(["batch", str(tmp_path / "a.bvh"), "--out", str(tmp_path / "o"), "--mode", "clean",
                 "--every", "0.3", "--partial"]) == EXIT_INPUT
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--every, --partial" in err and "--mode mocap" in err
    assert not (tmp_path / "o" / "summary.csv").exists()


def test_clean_totals_worst_and_mean():
    rows = [dict.fromkeys(CLEAN_COLUMNS) | dict(status="ok", displacement_frames=7, penetration_mm=0.5, float_mm=2.0,
                                                 deviation_mean_cm=1.0, deviation_max_cm=3.0, cpu_s=1.5),
            dict.fromkeys(CLEAN_COLUMNS) | dict(status="ok", displacement_frames=5, penetration_mm=0.2, float_mm=4.0,
                                                 deviation_mean_cm=2.0, deviation_max_cm=2.0, cpu_s=0.5),
            dict.fromkeys(CLEAN_COLUMNS) | dict(status="failed", error="x")]
    t = totals(rows, 9.0, CLEAN_COLUMNS)
    assert (t["penetration_mm"], t["float_mm"], t["deviation_max_cm"]) == (0.5, 4.0, 3.0)
    assert t["deviation_mean_cm"] == pytest.approx(1.5) and t["cpu_s"] == pytest.approx(2.0)
    assert t["displacement_frames"] == 12 and t["status"] == "2 ok, 1 failed" and t["skate_mm"] is None
