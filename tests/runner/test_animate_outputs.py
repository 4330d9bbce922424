"""What `animate` / `run-and-step` write and say: --export, --quiet (progress only), the default video,
progress lines off a terminal. The optimization is cut short (--max-evals 3) and the renderer
is replaced where a video would be made, to keep these fast."""
import re

import pytest

from runner.capture.bvh import read_bvh
from runner.cli import main
from runner.exit_codes import EXIT_INPUT
from runner.problem_file import RUN_AND_STEP_KEYFRAMES

FAST = ["--max-evals", "3"]


def animate(capsys, *argv):
    code = main(["animate", str(RUN_AND_STEP_KEYFRAMES), *FAST, *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def test_export_writes_each_file_after_the_path(tmp_path, capsys):
    code, out, err = animate(capsys, "--no-render", "--export", tmp_path / "a.bvh", "--export", tmp_path / "a.glb")
    assert code == 0, err
    assert (tmp_path / "a.glb").read_bytes()[:4] == b"glTF"
    clip = read_bvh(tmp_path / "a.bvh")
    assert len(clip.names) == 14 and clip.frame_time == pytest.approx(1 / 120, rel=1e-4)  # 12 bodies, fixed neck and head
    assert f"wrote {tmp_path / 'a.bvh'} (BVH, optimized:" in out and f"wrote {tmp_path / 'a.glb'} (glTF" in out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.bvh", "a.glb"]  # no temporary path left


@pytest.mark.parametrize("name, fragment", [("a.fbx", "--export"), ("a", "no extension")])
def test_bad_export_name_fails_before_optimizing(tmp_path, capsys, name, fragment):
    code, out, err = animate(capsys, "--no-render", "--export", tmp_path / name)
    assert code == EXIT_INPUT and fragment in err and name in err
    assert "round" not in out and "stopped" not in out


def test_quiet_silences_progress_but_not_results(tmp_path, capsys):
    code, out, err = animate(capsys, "--no-render", "--quiet", "--save-path", tmp_path / "p.npz")
    assert code == 0, err
    assert "plain spline" in out and "change E" in out  # the summary table
    assert "wrote" in out and "p.npz" in out and "stopped:" in out
    assert "round 1" not in out and "importing" not in out  # progress
    code, out, _ = animate(capsys, "--no-render", "--no-summary")
    assert "change E" not in out and re.search(r"round 1: \d+ frames \(\d+ variable\): done, \d+ evaluations, Phi", out)


def test_animate_without_out_renders_to_the_default_path(tmp_path, capsys, monkeypatch):
    """The default video is renders/<name>.mp4 in the current folder (not the checkout's), printed as
    the user would type it."""
    from pathlib import Path

    import runner.run
    from runner.commands import animate as cmd

    seen = []

    class Info:
        n_frames, wall_time_s = 3, 0.0

        def summary(self):
            return "3 frames in 0.0 s"

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(runner.run, "render_with_progress", lambda out, *a, **k: seen.append(out) or Info())
    code, out, err = animate(capsys)
    assert code == 0, err
    assert seen == [Path("renders/run_and_step.mp4")] and "wrote renders/run_and_step.mp4" in out
    assert (tmp_path / "renders").is_dir()  # the folder the video goes into is made where the user is
    assert cmd.default_video("walk.keyframes.json") == Path("renders/walk.mp4")
    assert cmd.default_video("dir/jump.json") == Path("renders/jump.mp4")
    code, out, err = animate(capsys, "--no-render")
    assert len(seen) == 1 and "no video (--no-render)" in out


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def test_progress_off_a_terminal_prints_rounds_once_and_a_still_line_every_5_s(monkeypatch):
    import io

    import runner.progress as progress

    clock = Clock()
    monkeypatch.setattr(progress.time, "perf_counter", clock)
    stream = io.StringIO()  # not a terminal
    p = progress.Progress(stream=stream)
    p("round", {"round": 0, "frames": 15, "variable": 7})
    for i in range(1, 121):  # 12 s of evaluations, 10 a second
        clock.t = i / 10
        p("eval", {"evals": i, "E": 1.0 / i})
    p("constraints", {"round": 0, "worst": "flight wrench", "value": 10.9123, "rho": 0.84})
    p("round", {"round": 1, "frames": 20, "variable": 12})
    clock.t = 13.0
    p.done()
    lines = stream.getvalue().splitlines()
    assert [line.split(":")[0].strip() for line in lines] == [
        "round 1", "round 1 (still optimizing)", "round 1 (still optimizing)", "round 1", "round 2"]
    # the long round says when it started, before its first "still" line; the short one prints one line
    assert "15 frames (7 variable): started, 0.0 s" in lines[0] and "done, 120 evaluations" in lines[3]
    assert "worst flight wrench 10.9 x tol" in lines[3] and ", Phi " in lines[3] and ", E " not in lines[3]
    assert "20 frames (12 variable): done, 0 evaluations" in lines[4] and "worst" not in lines[4]
    assert progress.Progress(quiet=True, stream=stream) is not None


def test_the_least_violation_shows_its_progress_off_a_terminal(monkeypatch):
    """The search after a round (the "search" event, its "eval"s with F, then "certify") prints lines of its
    own while it runs, with F, not a round that seems to stand still."""
    import io

    import runner.progress as progress

    clock = Clock()
    monkeypatch.setattr(progress.time, "perf_counter", clock)
    stream = io.StringIO()
    p = progress.Progress(stream=stream)
    p("round", {"round": 7, "frames": 130, "variable": 120})
    p("eval", {"evals": 100, "E": 0.5})
    p("search", {"round": 7, "frames": 130})
    for i in range(1, 81):  # 8 s of the search, 10 evaluations a second
        clock.t = i / 10
        p("eval", {"evals": 100 + i, "F": 10.0 / i})
    p("certify", {"round": 7, "frames": 961, "raised": {"planted": 0.0127}, "evals": 180, "spent": 80})
    lines = stream.getvalue().splitlines()
    assert lines[0].startswith("  round 8: 130 frames (120 variable): done, 100 evaluations, Phi 0.5")
    assert "least violation after round 8: from 130 frames: started" in lines[1]
    assert "least violation (still optimizing): 50 evaluations, F 0.2" in lines[2]
    assert "least violation: done, 80 evaluations, F 0.125, 8.0 s" in lines[-2]
    assert lines[-1] == ("  round 8: least violation sought (80 evaluations, 961 frames): out of reach, limits "
                         "raised by [SI]: planted 0.0127")
    p("finer", {"rate": 400.0, "segment": 0.005})  # then the check at a finer spacing says what it does
    assert stream.getvalue().splitlines()[-1] == ("  limits raised: the least violation sought again at 400 points/s "
                                                  "(segments down to 5 ms), from the path found")
    from solver.animate import _counted_on

    check = _counted_on(p, 180)  # the check's search counts its evaluations from 0: they count on from the solve's
    check("search", {"round": 0, "frames": 961})
    for i in range(1, 13):
        check("eval", {"evals": i, "F": 1.0 / i})
    check("certify", {"round": 0, "frames": 961, "raised": {}, "evals": 12, "spent": 12})
    assert stream.getvalue().splitlines()[-2].startswith("  least violation after round 1: from 961 frames: done, "
                                                         "12 evaluations")


def test_steps_off_a_terminal_start_still_and_end_lines(monkeypatch):
    import io

    import runner.progress as progress

    clock = Clock()
    monkeypatch.setattr(progress.time, "perf_counter", clock)
    stream = io.StringIO()
    with progress.Steps("rendering a.mp4", 100, stream=stream, unit=" frames") as bar:
        for i in range(1, 101):
            clock.t = i / 10
            bar.update(i)
    lines = stream.getvalue().splitlines()
    assert lines[0] == "  rendering a.mp4: 0/100" and lines[-1].startswith("  rendering a.mp4: 100/100 done")
    assert len(lines) == 3 and "(still working): 50/100" in lines[1]
    quiet = io.StringIO()
    with progress.Steps("x", 3, quiet=True, stream=quiet) as bar:
        bar.update(3)
    assert quiet.getvalue() == ""


def test_failed_export_names_the_file_and_keeps_the_saved_path(tmp_path, capsys, monkeypatch):
    import runner.export.bvh

    def full_disk(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(runner.export.bvh, "write_bvh", full_disk)
    code, out, err = animate(capsys, "--no-render", "--save-path", tmp_path / "p.npz", "--export", tmp_path / "a.bvh")
    assert code == EXIT_INPUT
    assert f"--export {tmp_path / 'a.bvh'}: not written: cannot write" in err and "No space left" in err
    assert "the path is saved in" in err and (tmp_path / "p.npz").is_file() and not (tmp_path / "a.bvh").exists()
