"""`dynsplines batch`: a folder of short clips into one folder per clip and a summary; a rerun skips what is
done; bad clips are rows with their errors (exit 3); two workers give the per-clip results of one."""
import csv
import json
from pathlib import Path

import pytest

from runner.batch import COLUMNS, clip_duration, clip_folders, find_clips, longest_first
from runner.cli import main
from runner.exit_codes import EXIT_FAILED, EXIT_INPUT, EXIT_INTERRUPTED, EXIT_OK
from solver.errors import InputError

REPO = Path(__file__).resolve().parents[2]
CLIP = REPO / "models" / "cmu" / "127_33.bvh"
FAST = ["--every", "0.25", "--max-evals", "30", "--quiet"]
#: per-clip figures that must not depend on the worker count
RESULTS = ("status", "keyframes", "variable_frames", "solver_status", "max_penetration_mm", "plain_float_contact_mm",
           "optimized_float_contact_mm", "plain_skate_mm", "optimized_skate_mm")


def short_bvh(dst: Path, frames: int = 60) -> Path:
    """127_33's header and its first `frames` frames (0.5 s at 120 Hz)."""
    lines = CLIP.read_text().splitlines()
    m = next(i for i, ln in enumerate(lines) if ln.strip() == "MOTION")
    head = "\n".join(lines[:m + 1])
    dst.write_text("\n".join([head, f"Frames: {frames}", lines[m + 2], *lines[m + 3:m + 3 + frames]]) + "\n")
    return dst


@pytest.fixture
def clips(tmp_path):
    d = tmp_path / "clips"
    d.mkdir()
    short_bvh(d / "a.bvh")
    short_bvh(d / "b.bvh", frames=50)
    return d


def read_csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_find_clips_and_folders(tmp_path, clips):
    (clips / "notes.txt").write_text("x")
    found = find_clips([clips, clips / "a.bvh"])
    assert [c.name for c in found] == ["a.bvh", "b.bvh"]  # no repeats, only .bvh
    with pytest.raises(InputError, match="nope"):
        find_clips([tmp_path / "nope"])
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="no .bvh clips"):
        find_clips([tmp_path / "empty"])
    assert [f.name for f in clip_folders([Path("x/a.bvh"), Path("y/a.bvh")], tmp_path)] == ["a", "a-2"]


def test_ray_without_ray_or_bad_address_is_one_line(tmp_path, clips, capsys):
    assert main(["batch", str(clips), "--out", str(tmp_path / "o"), "--ray-address", "x:1"]) == EXIT_INPUT
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--engine ray" in err
    try:
        import ray  # noqa: F401
    except ImportError:
        assert main(["batch", str(clips), "--out", str(tmp_path / "o"), "--engine", "ray"]) == EXIT_INPUT
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and 'pip install -e ".[cluster]"' in err


@pytest.mark.slow
def test_summary_failures_and_resumption(tmp_path, clips, capsys):
    (clips / "corrupt.bvh").write_text(short_bvh(tmp_path / "c.bvh").read_text()[:3000])
    bad = short_bvh(clips / "degenerate.bvh").read_text().splitlines()  # a shin of zero length
    at = next(i for i, ln in enumerate(bad) if ln.split() == ["JOINT", "LeftFoot"]) + 2
    bad[at] = bad[at][: bad[at].index("OFFSET")] + "OFFSET 0 0 0"
    (clips / "degenerate.bvh").write_text("\n".join(bad) + "\n")
    out = tmp_path / "out"
    assert main(["batch", str(clips), "--out", str(out), *FAST]) == EXIT_FAILED
    rows = read_csv(out / "summary.csv")
    assert tuple(rows[0]) == COLUMNS
    by = {Path(r["clip"]).name: r for r in rows[:-1]}
    assert [by[n]["status"] for n in ("a.bvh", "b.bvh", "corrupt.bvh", "degenerate.bvh")] == ["ok", "ok", "failed",
                                                                                                "failed"]
    assert "HIERARCHY" in by["corrupt.bvh"]["error"] and "LeftFoot" in by["degenerate.bvh"]["error"]
    assert all("\n" not in r["error"] for r in rows)
    assert int(by["a.bvh"]["keyframes"]) >= 3 and float(by["a.bvh"]["optimized_skate_mm"]) >= 0
    total = rows[-1]
    assert total["clip"] == "TOTAL" and total["status"] == "2 ok, 2 failed"
    assert int(total["keyframes"]) == int(by["a.bvh"]["keyframes"]) + int(by["b.bvh"]["keyframes"])
    summary = json.loads((out / "summary.json").read_text())
    assert summary["totals"]["counts"]["failed"] == 2 and not summary["interrupted"] and len(summary["clips"]) == 4
    for stem in ("a", "b"):
        assert {p.name for p in (out / stem).iterdir()} >= {f"{stem}.keyframes.json", f"{stem}.npz",
                                                            f"{stem}.metrics.json", "done.json"}
    assert not (out / "corrupt" / "done.json").exists()
    mtimes = {p: p.stat().st_mtime_ns for p in (out / "a").iterdir()}

    # rerun: a and b skipped (outputs untouched), the failed ones tried again; a changed clip is redone
    short_bvh(clips / "b.bvh", frames=55)
    assert main(["batch", str(clips), "--out", str(out), *FAST]) == EXIT_FAILED
    by = {Path(r["clip"]).name: r for r in read_csv(out / "summary.csv")[:-1]}
    assert by["a.bvh"]["status"] == "skipped" and float(by["a.bvh"]["wall_time_s"]) < 0.1
    assert by["b.bvh"]["status"] == "ok" and by["corrupt.bvh"]["status"] == "failed"
    assert {p: p.stat().st_mtime_ns for p in (out / "a").iterdir()} == mtimes
    # other options: redone
    assert main(["batch", str(clips / "a.bvh"), "--out", str(out), *FAST[:-3], "--max-evals", "31", "--quiet"]) == EXIT_OK
    assert read_csv(out / "summary.csv")[0]["status"] == "ok"


@pytest.mark.slow
def test_two_workers_same_results(tmp_path, clips):
    rows = {}
    for n in (1, 2):
        assert main(["batch", str(clips), "--out", str(tmp_path / f"w{n}"), "--workers", str(n), *FAST]) == EXIT_OK
        rows[n] = [{k: r[k] for k in ("clip", *RESULTS)} for r in read_csv(tmp_path / f"w{n}" / "summary.csv")[:-1]]
    assert rows[1] == rows[2] and [r["status"] for r in rows[1]] == ["ok", "ok"]


def test_ctrl_c_stops_handing_out_clips(tmp_path, clips, monkeypatch):
    """Ctrl-C during the first clip: it is recorded as interrupted (not done), the next is not started, the
    summary is written, exit 130."""
    import runner.batch

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(runner.batch, "process_clip", interrupted)
    out = tmp_path / "out"
    assert main(["batch", str(clips), "--out", str(out), *FAST]) == EXIT_INTERRUPTED
    rows = read_csv(out / "summary.csv")
    assert [r["status"] for r in rows[:-1]] == ["interrupted", "not run"]
    assert json.loads((out / "summary.json").read_text())["interrupted"]
    assert not list(out.glob("*/done.json")) and not list(out.glob("**/.*.tmp*"))


def test_clip_duration_from_the_header(tmp_path, clips):
    assert clip_duration(clips / "a.bvh") == pytest.approx(60 * 0.0083333)
    assert clip_duration(clips / "b.bvh") == pytest.approx(50 * 0.0083333)
    (tmp_path / "junk.bvh").write_text("HIERARCHY\nMOTION\nFrames: many\n")
    assert clip_duration(tmp_path / "junk.bvh") == 0.0 and clip_duration(tmp_path / "missing.bvh") == 0.0
    assert longest_first(["x", "y", "z", "w"], [1.0, 3.0, 1.0, 2.0]) == ["y", "w", "x", "z"]  # ties keep order


def test_longest_clips_are_handed_out_first(tmp_path, clips, monkeypatch):
    """The longest-processing-time rule: clips start in order of decreasing duration (with two workers
    a long clip that started last would run alone at the end); the summary keeps the clips' order."""
    import runner.batch

    started = []

    def record(clip, *a, **k):
        started.append(Path(clip).name)
        raise ValueError("not solved in this test")

    monkeypatch.setattr(runner.batch, "process_clip", record)
    short_bvh(clips / "c.bvh", frames=90)
    assert main(["batch", str(clips), "--out", str(tmp_path / "out"), *FAST]) == EXIT_FAILED
    assert started == ["c.bvh", "a.bvh", "b.bvh"]
    assert [Path(r["clip"]).name for r in read_csv(tmp_path / "out" / "summary.csv")[:-1]] == ["a.bvh", "b.bvh", "c.bvh"]


def test_workers_are_forked_only_from_a_single_thread():
    """Forking copies one thread: with another thread running (a lock it holds would stay held in the
    child) the local engine spawns its workers instead."""
    import threading

    import runner.batch

    go = threading.Event()
    t = threading.Thread(target=go.wait)
    t.start()
    try:
        assert not runner.batch._single_threaded()
    finally:
        go.set()
        t.join()


@pytest.mark.slow
def test_ray_engine_same_results(tmp_path, clips):
    """--engine ray (a local Ray, 2 CPUs): the rows of the local engine."""
    pytest.importorskip("ray")
    rows = {}
    for engine in ("local", "ray"):
        assert main(["batch", str(clips), "--out", str(tmp_path / engine), "--engine", engine, "--workers", "2",
                     *FAST]) == EXIT_OK
        rows[engine] = [{k: r[k] for k in ("clip", *RESULTS)} for r in read_csv(tmp_path / engine / "summary.csv")[:-1]]
    assert rows["local"] == rows["ray"]
