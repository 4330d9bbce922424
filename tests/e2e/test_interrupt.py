"""Interruption, limits and failures lose nothing: Ctrl-C (SIGINT) and --max-time keep the best path
(which meets every keyframe) and write the outputs; a non-finite objective is reported by term with
the last good iterate kept; a failed write leaves an earlier output intact; identical runs give
bit-identical paths.

The SIGINT tests run the real command in a subprocess and signal it once its progress shows the
optimization under way. The subprocess starts with SIGINT at its default action, as a command typed at a
terminal does: a shell without job control (a CI script, `cmd &`) starts its background jobs with SIGINT
ignored, and Python then keeps ignoring it outside the optimization's own handler.
"""
import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import mujoco
import numpy as np
import pytest

import runner.commands.animate
import runner.saved_path
from runner.cli import main
from runner.exit_codes import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK
from solver.errors import InputError
from solver.frames import FrameSet
from solver.keyframes import Keyframes
from solver.layout import StateLayout
from solver.least_change import LeastChangeOptions
from solver.objective import Objective
from solver.optimize import Status
from solver.paper.solve import SolveOptions, solve
from solver.spline import interpolate
from solver.terms import CovariantAcceleration, UnitQuaternion
from solver.terms.base import Term, TermEval

REPO = Path(__file__).resolve().parents[2]
MODELS = REPO / "models"
SCENE = MODELS / "run_and_step.xml"


#: options that keep run-and-step optimizing for several seconds (it converges in about 1.5 s), so the
#: signal surely arrives during the optimization
LONG = ("--tol", "1e-9",)


def keyframe_error(z) -> float:
    """Largest |path(t_k) - keyframe| over fixed components, re-interpolating the saved frames."""
    Y = interpolate(z["frame_times"], z["frames"], z["keyframe_times"])
    mask = z["keyframe_mask"]
    assert mask.any()
    return float(np.abs(Y - z["keyframes"])[mask].max())


def small_keyframes(tmp_path, n=3) -> Path:
    doc = json.loads((MODELS / "run_and_step.keyframes.json").read_text())
    doc["keyframes"] = doc["keyframes"][:n]
    doc["scene"] = str(SCENE)
    doc["model"] = str(MODELS / "humanoid39.xml")
    doc["source"] = {}
    p = tmp_path / "small.json"
    p.write_text(json.dumps(doc))
    return p


def _default_sigint():
    """In the child before exec: SIGINT back to its default action (module docstring)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


class Command:
    """`python -m runner ARGS` in a subprocess; its output is collected as it comes (progress lines
    end in "\\r" while rendering, so this reads bytes, not lines)."""

    def __init__(self, *args, cwd=REPO):
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        self.proc = subprocess.Popen([sys.executable, "-m", "runner", *map(str, args)], cwd=cwd, env=env,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, preexec_fn=_default_sigint)
        self.out, self.err = bytearray(), bytearray()
        self._threads = [threading.Thread(target=self._pump, args=(s, b), daemon=True)
                         for s, b in ((self.proc.stdout, self.out), (self.proc.stderr, self.err))]
        for t in self._threads:
            t.start()

    @staticmethod
    def _pump(stream, buf):
        while chunk := stream.read1(4096):
            buf.extend(chunk)

    def wait_for(self, predicate, timeout=60.0):
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            if predicate(self.out.decode(errors="replace")):
                return
            if self.proc.poll() is not None:
                break
            time.sleep(0.05)
        self.proc.kill()
        pytest.fail(f"not seen within {timeout} s; stdout:\n{self.out.decode()}\nstderr:\n{self.err.decode()}")

    def interrupt(self):
        self.proc.send_signal(signal.SIGINT)

    def finish(self, timeout=90.0) -> int:
        try:
            code = self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            pytest.fail("the command did not end after the interrupt (a hang)")
        for t in self._threads:
            t.join(5)
        return code


def optimizing(text: str) -> bool:
    """A progress line (off a terminal: a round's "done" or "(still optimizing)" line) with at least one
    evaluation done."""
    return any(int(n) > 0 for n in re.findall(r"round \d+.*?: (?:done, )?(\d+) evaluations", text))


def test_sigint_during_optimization_keeps_the_best_path(tmp_path):
    out = tmp_path / "rs.npz"
    cmd = Command("run-and-step", "--no-render", "--save-path", out, *LONG)
    cmd.wait_for(optimizing)
    cmd.interrupt()
    code = cmd.finish()
    stdout, stderr = cmd.out.decode(), cmd.err.decode()
    assert code == EXIT_INTERRUPTED, stderr
    assert "Traceback" not in stderr
    assert "stopping: keeping the best path so far" in stderr
    assert "stopped: interrupted (Ctrl-C), best path so far kept" in stdout
    assert "change E" in stdout and "wrote" in stdout  # the summary, then the file
    z = np.load(out)
    assert str(z["status"]) == "interrupted"
    assert keyframe_error(z) <= 1e-9
    assert np.isfinite(z["frames"]).all()
    E = z["objective_trace"]
    assert E.size > 0 and np.isfinite(E).all()  # the augmented Lagrangian: it changes between subproblems
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rs.npz"]  # no temporary files left


def test_sigint_while_rendering_leaves_no_partial_video(tmp_path):
    video, path = tmp_path / "rs.mp4", tmp_path / "rs.npz"
    video.write_bytes(b"an earlier video")
    cmd = Command("run-and-step", "--save-path", path, "--out", video, "--size", "160x96", "--fps", "60",
                  "--speed", "0.02", *LONG)
    cmd.wait_for(optimizing)
    cmd.interrupt()  # first: stop optimizing, keep the best path, go on to write the outputs
    cmd.wait_for(lambda text: re.search(r"rendering .*: [1-9]\d*/", text) is not None)  # frames are being written
    cmd.interrupt()  # second, while rendering: abandon the video
    code = cmd.finish()
    stderr = cmd.err.decode()
    assert code == EXIT_INTERRUPTED, stderr
    assert "Traceback" not in stderr
    assert "interrupted while rendering:" in stderr and "rs.mp4 not written (an earlier file there is unchanged)" in stderr
    assert video.read_bytes() == b"an earlier video"
    assert keyframe_error(np.load(path)) <= 1e-9  # the path was saved before the render started
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rs.mp4", "rs.npz"]  # no temporary video left


def test_max_time_stops_with_outputs_and_exit_0(tmp_path, capsys):
    out = tmp_path / "rs.npz"
    code = main(["run-and-step", "--no-render", "--max-time", "0.5", "--save-path", str(out), *LONG])
    stdout = capsys.readouterr().out
    assert code == EXIT_OK
    assert "stopped: time limit of 0.5 s reached" in stdout
    z = np.load(out)
    assert str(z["status"]) == "max_time"
    assert keyframe_error(z) <= 1e-9
    assert json.loads(str(z["options_json"]))["solve"]["max_time_s"] == 0.5


# -------------------------------------------------------------------------- non-finite objective
class Poison(Term):
    """Zero on paths within 1e-3 of the first path it sees; NaN further away (a term that breaks down
    away from the start, deterministically)."""

    name = "poison"
    needs = (0,)

    def __init__(self):
        self.Y0 = None

    def evaluate(self, t, Y, Y1, Y2, grad=True):
        if self.Y0 is None:
            self.Y0 = Y.copy()
        bad = np.abs(Y - self.Y0).max() > 1e-3
        f = np.full(len(t), np.nan if bad else 0.0)
        return TermEval(f, dY=np.zeros_like(Y) if grad else None)


def test_nonfinite_term_is_named_and_last_good_iterate_kept():
    model = mujoco.MjModel.from_xml_path(str(SCENE))
    layout = StateLayout.from_model(model)
    import tempfile

    from solver.keyframe_file import read_keyframes

    with tempfile.TemporaryDirectory() as d:
        kf, _ = read_keyframes(small_keyframes(Path(d)), layout)
    smooth = CovariantAcceleration(layout.quat_slots, layout.linear_index)
    obj = Objective([UnitQuaternion(layout.quat_slots), smooth, Poison()], [1.0, 0.05, 1.0], kf.times[0], kf.times[-1],
                    rate=400.0)
    initial = FrameSet.from_keyframes(kf, layout.quat_slots)
    sol = solve(obj, initial, SolveOptions(rounds=1))
    assert sol.status is Status.NONFINITE
    assert "objective term 'poison' produced a non-finite value" in sol.message
    assert np.isfinite(sol.frames.values).all() and np.isfinite(sol.E_final)
    Y = sol.frames.path(kf.times)
    assert np.abs(Y - kf.values)[kf.mask].max() <= 1e-9  # keyframes met by the kept iterate
    assert sol.E_final <= sol.E_initial * (1 + 1e-12)  # never worse (up to round-off of re-evaluation)


def poisoned_evaluate(monkeypatch, from_the_start: bool):
    """`AugmentedLagrangian.evaluate` made NaN away from the first path it sees (or everywhere)."""
    from solver.lagrangian import AugmentedLagrangian

    real, first = AugmentedLagrangian.evaluate, {}

    def poisoned(self, basis, P, grad=True):
        phi, G, D = real(self, basis, P, grad)
        first.setdefault("P", P.copy())
        if from_the_start or P.shape != first["P"].shape or np.abs(P - first["P"]).max() > 1e-3:
            phi = float("nan")
        return phi, G, D

    monkeypatch.setattr(AugmentedLagrangian, "evaluate", poisoned)


def test_nonfinite_objective_at_the_command_line(tmp_path, capsys, monkeypatch):
    poisoned_evaluate(monkeypatch, from_the_start=False)
    out = tmp_path / "p.npz"
    code = main(["animate", str(small_keyframes(tmp_path)), "--no-render", "--save-path", str(out)])
    captured = capsys.readouterr()
    assert code == EXIT_FAILED
    assert "stopped: the objective or its gradient is not finite" in captured.out
    assert captured.err.startswith("dynsplines: warning: the optimization failed (the objective or its gradient")
    assert "Traceback" not in captured.err
    z = np.load(out)
    assert str(z["status"]) == "nonfinite" and keyframe_error(z) <= 1e-9


# ----------------------------------------------------------------------------- atomic writes
def saved_problem(tmp_path):
    """Arguments of `save_path_npz` (a run) for a tiny two-keyframe solve."""
    from runner.run import Run, Source
    from solver.problem import Problem
    from solver.terms import UnitQuaternion

    kf = Keyframes([0.0, 0.5], [[1, 0, 0, 0], [0.9, 0.1, 0, 0]], np.ones((2, 4), bool))
    obj = Objective([UnitQuaternion([[0, 1, 2, 3]])], [1.0], 0.0, 0.5, rate=50)
    initial = FrameSet.from_keyframes(kf, [[0, 1, 2, 3]])
    sol = solve(obj, initial, SolveOptions(rounds=0))
    problem = Problem(None, kf, (), False, initial)
    return (Run(problem, LeastChangeOptions(), sol, Source(SCENE), {}),)


@pytest.mark.parametrize("failure", [OSError(28, "No space left on device"), KeyboardInterrupt()],
                         ids=["disk full", "Ctrl-C"])
def test_failed_npz_write_leaves_the_earlier_file_intact(tmp_path, monkeypatch, failure):
    out = tmp_path / "p.npz"
    args = saved_problem(tmp_path)
    runner.saved_path.save_path_npz(*args, out)
    good = out.read_bytes()

    def savez_then_fail(fh, **fields):
        fh.write(b"PK\x03\x04 half a zip file")
        raise failure

    monkeypatch.setattr(np, "savez", savez_then_fail)
    if isinstance(failure, OSError):
        with pytest.raises(InputError, match=r"cannot write .*p\.npz: No space left on device; an earlier file "
                                             "there is unchanged"):
            runner.saved_path.save_path_npz(*args, out)
    else:
        with pytest.raises(KeyboardInterrupt):
            runner.saved_path.save_path_npz(*args, out)
    assert out.read_bytes() == good
    assert [p.name for p in tmp_path.iterdir()] == ["p.npz"]


# ---------------------------------------------------------------------------- reproducibility
def test_identical_runs_give_bit_identical_paths_and_record_versions(tmp_path):
    kf = small_keyframes(tmp_path)
    outs = [tmp_path / f"run{i}.npz" for i in range(2)]
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
                                                            "MKL_NUM_THREADS")}
    procs = [subprocess.Popen([sys.executable, "-m", "runner", "animate", str(kf), "--no-render", "--quiet",
                               "--save-path", str(o)], cwd=REPO, env=env, stderr=subprocess.PIPE)
             for o in outs]
    for p in procs:
        _, err = p.communicate(timeout=120)
        assert p.returncode == EXIT_OK, err.decode()
    a, b = (np.load(o) for o in outs)
    for key in ("frame_times", "frames", "objective_trace", "plain_frames"):
        assert a[key].tobytes() == b[key].tobytes(), key
    versions = json.loads(str(a["versions_json"]))
    for pkg in ("dynsplines", "mujoco", "nlopt", "numpy", "scipy"):
        assert versions[pkg] and versions[pkg] != "unknown", pkg
    assert versions["blas_threads_env"]["OPENBLAS_NUM_THREADS"] == "1"  # pinned by solver/__init__.py
    options = json.loads(str(a["options_json"]))
    assert options["terms"] == "default"
    assert options["solve"]["tol"] == LeastChangeOptions().tol and options["command"]["keyframes"] == str(kf)


def test_nonfinite_on_the_plain_spline_keeps_the_plain_spline(tmp_path, capsys, monkeypatch):
    """Not one finite evaluation: the optimization fails, the path written is the plain spline (every
    keyframe met), the exit code says so."""
    poisoned_evaluate(monkeypatch, from_the_start=True)
    out = tmp_path / "p.npz"
    code = main(["animate", str(small_keyframes(tmp_path)), "--no-render", "--save-path", str(out)])
    err = capsys.readouterr().err
    assert code == EXIT_FAILED
    assert err.startswith("dynsplines: warning: the optimization failed") and "Traceback" not in err
    z = np.load(out)
    assert str(z["status"]) == "nonfinite" and keyframe_error(z) <= 1e-9
