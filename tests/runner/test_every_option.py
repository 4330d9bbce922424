"""Every option of every subcommand is used: the test walks the parser, gives each command every one of
its options (with a value other than the default), and records which parsed arguments the command reads.
An option that no code reads is one that silently does nothing (exit 0, no effect) - the kind of defect
this guards against (`mocap --export` once wrote nothing). The expensive hand-off of each command (the
solve, the batch, the server) is replaced by a recorder, so what is checked is the argument glue; the
effects themselves are tested where each output is (test_animate_outputs, test_mocap_command, ...).

`ClipOptions` gets the same treatment one level down: every field is read by `process_clip`."""
from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import pytest
from bvh_edit import edit_bvh

import runner.cli
from runner.cli import build_parser, main
from runner.paths import MODELS

CLIP = MODELS / "cmu" / "127_33.bvh"
KEYFRAMES = MODELS / "run_and_step.keyframes.json"
IGNORED = {"help", "debug"}  # argparse's own, and the global --debug (tested in test_errors)


class Recorder(argparse.Namespace):
    """A Namespace that records the attributes read after parsing (argparse's own reads while parsing
    are not counted)."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        object.__setattr__(self, "_reads", set())
        object.__setattr__(self, "_on", False)

    def __getattribute__(self, name):
        if not name.startswith("_") and object.__getattribute__(self, "_on"):
            object.__getattribute__(self, "_reads").add(name)
        return object.__getattribute__(self, name)


def option_dests(command: list[str]) -> set[str]:
    """The dests of every option of the subcommand `command` (e.g. ["bench", "contacts"])."""
    parser = build_parser()
    for word in command:
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        parser = sub.choices[word]
    return {a.dest for a in parser._actions if a.option_strings and a.dest not in IGNORED}


@pytest.fixture
def reads(monkeypatch):
    """Run `main(argv)` with a Recorder namespace; returns a function argv -> (exit code, reads)."""
    real = runner.cli.build_parser

    def recording_parser():
        parser = real()
        parse = parser.parse_args

        def parse_args(argv=None, namespace=None):
            ns = parse(argv, Recorder())
            object.__setattr__(ns, "_on", True)
            seen.append(ns)
            return ns

        parser.parse_args = parse_args
        return parser

    seen = []
    monkeypatch.setattr(runner.cli, "build_parser", recording_parser)

    def run(argv):
        seen.clear()
        code = main([str(a) for a in argv])
        return code, set(seen[-1]._reads) if seen else set()

    return run


class Done:
    """What a replaced hand-off returns: exit code 0, and any attribute the command reads of it."""

    exit_code = 0

    def __init__(self, **kw):
        self.__dict__.update(kw)


def solve_glue(tmp_path) -> list[str]:
    """Every optimization option, each away from its default."""
    return ["--terms", "all", "--max-time", "30", "--tol", "0.05", "--max-evals", "7", "--rate", "300"]


def output_glue(tmp_path, render: bool) -> list[str]:
    out = ["--save-path", tmp_path / "p.npz", "--plot", tmp_path / "plots", "--export", tmp_path / "a.bvh",
           "--quiet", "--no-summary", "--fps", "24", "--size", "320x180", "--speed", "1",
           "--panels", "plain,optimized,reference"]
    return out + (["--out", tmp_path / "v.mp4"] if render else ["--no-render"])


def check(dests: set[str], reads_: set[str], command: str) -> None:
    unread = sorted(dests - reads_)
    assert not unread, f"`dynsplines {command}` never reads option(s) {unread}: they do nothing"


@pytest.mark.parametrize("command", ["animate", "run-and-step"])
def test_animate_reads_every_option(command, tmp_path, reads, monkeypatch):
    import runner.commands.animate as cmd

    monkeypatch.setattr(cmd, "execute", lambda *a, **k: Done())
    head = [command] + ([KEYFRAMES, "--scene", MODELS / "run_and_step.xml"] if command == "animate" else [])
    seen = set()
    for render in (True, False):
        code, r = reads([*head, *output_glue(tmp_path, render), *solve_glue(tmp_path)])
        assert code == 0
        seen |= r
    # --reference-panel stores into --panels' dest
    check(option_dests([command]), seen, command)


@pytest.mark.parametrize("command", ["mocap", "batch"])
def test_clip_commands_read_every_option(command, tmp_path, reads, monkeypatch):
    import runner.commands.batch as batch_cmd
    import runner.commands.mocap as mocap_cmd

    given = []
    monkeypatch.setattr(mocap_cmd, "process_clip", lambda clip, out, o, say=print: given.append(o) or {"exit": "ok"})
    monkeypatch.setattr(batch_cmd, "run_batch", lambda clips, out, o, **k: given.append(o) or {
        "totals": {"status": "done", "counts": {"failed": 0}}, "wall_time_s": 0.0, "summary": ("a", "b"),
        "interrupted": False})
    clip_glue = ["--keys", "contacts", "--every", "0.3", "--partial", "--scene", MODELS / "run_and_step.xml",
                 "--figure", MODELS / "humanoid39.xml", "--mass", "65", "--root-scale", "1"]
    if command == "mocap":
        variants = [["mocap", CLIP, "--out-dir", tmp_path / "o", "--metrics", tmp_path / "m.json", *clip_glue,
                     *output_glue(tmp_path, render), *solve_glue(tmp_path)] for render in (True, False)]
    else:
        variants = [["batch", CLIP, "--out", tmp_path / "b", "--workers", "2", "--engine", "ray", "--ray-address",
                     "127.0.0.1:1", "--render", "--quiet", *clip_glue, *solve_glue(tmp_path)]]
    seen = set()
    for argv in variants:
        code, r = reads(argv)
        assert code == 0
        seen |= r
    check(option_dests([command]), seen, command)
    assert given and all(o.forces and o.solve.max_evals == 7 and o.solve.rate == 300.0 for o in given)


def test_process_clip_reads_every_clip_option(tmp_path, monkeypatch):
    """Every `ClipOptions` field reaches `process_clip`'s work (a field it never reads is an option of
    `mocap` and `batch` that does nothing)."""
    import runner.pipeline as pipeline
    import runner.run

    read: set[str] = set()

    class Recording(pipeline.ClipOptions):
        def __getattribute__(self, name):
            if name in {f.name for f in dataclasses.fields(pipeline.ClipOptions)}:
                read.add(name)
            return object.__getattribute__(self, name)

    captured = {}

    def fake_execute(problem, options, source, outputs, say=print):
        captured["outputs"] = outputs
        raise _Stop

    class _Stop(Exception):
        pass

    monkeypatch.setattr(runner.run, "execute", fake_execute)
    clip = edit_bvh(CLIP, tmp_path / "short.bvh", seconds=0.6)
    o = Recording(every=0.3, forces=True, render=True, out=tmp_path / "v.mp4",
                  save_path=tmp_path / "p.npz", metrics=tmp_path / "m.json", plot=tmp_path / "plots",
                  exports=(tmp_path / "a.glb",), panels=("plain", "optimized", "reference"), fps=24.0,
                  size=(320, 180), speed=1.0, quiet=True, summary=False, command="dynsplines mocap x")
    with pytest.raises(_Stop):
        pipeline.process_clip(clip, tmp_path / "out", o, say=lambda *a: None)
    out = captured["outputs"]
    assert out.exports == (tmp_path / "a.glb",) and out.video == tmp_path / "v.mp4" and out.plot_dir == tmp_path / "plots"
    assert out.video_options.panels == ("plain", "optimized", "reference") and out.video_options.fps == 24.0
    assert not out.summary and out.quiet
    unread = sorted({f.name for f in dataclasses.fields(pipeline.ClipOptions)} - read)
    assert not unread, f"process_clip never reads ClipOptions field(s) {unread}"


def test_debug_is_accepted_after_the_subcommand(tmp_path, capsys):
    """`dynsplines animate FILE --debug` (as the README writes it) shows the traceback, like
    `dynsplines --debug animate FILE`."""
    from solver.errors import InputError

    for argv in (["animate", str(tmp_path / "none.json"), "--debug"], ["--debug", "animate", str(tmp_path / "none.json")]):
        with pytest.raises(InputError, match="none.json"):
            main(argv)
    assert main(["animate", str(tmp_path / "none.json")]) == 2
    assert "none.json" in capsys.readouterr().err


def test_mocap_help_shows_its_own_defaults(capsys, monkeypatch):
    """`mocap --help` names mocap's output files, not animate's."""
    monkeypatch.setenv("COLUMNS", "300")  # no line breaks inside a default
    with pytest.raises(SystemExit):
        build_parser().parse_args(["mocap", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "<out-dir>/<stem>.mp4" in text and "<out-dir>/<stem>.npz" in text
    assert "keyframe file name" not in text and "run_and_step" not in text


@pytest.fixture(scope="module")
def saved_npz(tmp_path_factory):
    """A saved path of a short run-and-step solve."""
    out = tmp_path_factory.mktemp("saved") / "p.npz"
    assert main(["run-and-step", "--no-render", "--quiet", "--no-summary", "--max-evals", "5",
                 "--save-path", str(out)]) == 0
    return out


def test_the_other_commands_read_every_option(tmp_path, reads, monkeypatch, saved_npz):
    """keyframes-from-bvh, export, orient, fig10, blender-addon, clean and view, run for real (view's server
    replaced)."""
    import runner.viewer.server as server

    monkeypatch.setattr(server, "serve", lambda assets, port, ready=None: None)
    clip = edit_bvh(CLIP, tmp_path / "short.bvh", seconds=0.6)
    runs = {
        "keyframes-from-bvh": [["keyframes-from-bvh", clip, "--out", tmp_path / "k.keyframes.json", "--every", "0.3",
                                "--keys", "every", "--scene", "auto", "--model", MODELS / "humanoid39.xml", "--partial",
                                "--no-root-extremes", "--quiet", "--root-scale", "1"],
                               ["keyframes-from-bvh", clip, "--out", tmp_path / "s.keyframes.json", "--figure", "subject",
                                "--mass", "65", "--quiet"]],
        "export": [["export", saved_npz, "--to", tmp_path / "e.bvh", "--fps", "24", "--which", "plain", "--quiet",
                    "--skeleton", "figure"]],
        "orient": [["orient", MODELS / "orient_example.json", "--out", tmp_path / "o.npz", "--subdivision", "adaptive",
                    "--per-segment", "2", "--tol", "1e-2", "--max-frames", "30", "--plot", tmp_path / "o.png", "--quiet"],
                   ["orient", MODELS / "orient_example.json", "--out", tmp_path / "o2.npz", "--rounds", "1",
                    "--form", "paper", "--rate", "200", "--quiet"]],
        "fig10": [["fig10", "--out", tmp_path / "f.png"]],
        "blender-addon": [["blender-addon", "--out", tmp_path / "addon.zip"]],
        "clean": [["clean", clip, "--pin", "0.3", "--pin-ends", "--out-dir", tmp_path / "clean", "--scene", "auto",
                   "--figure", "subject", "--mass", "65", "--root-scale", "1", "--no-render", "--fps", "24",
                   "--max-time", "30", "--quiet", "--no-summary"]],
        "view": [["view", saved_npz, "--port", "0"]],
    }
    for command, variants in runs.items():
        seen = set()
        for argv in variants:
            code, r = reads(argv)
            assert code == 0, argv
            seen |= r
        check(option_dests([command]), seen, command)


@pytest.mark.parametrize("bench", ["run-and-step", "docs", "orient", "scaling", "contacts"])
def test_bench_options_are_read_by_their_code(bench):
    """The benchmarks run for minutes, so their options are checked in the source: every option's
    `args.<dest>` appears in the benchmark commands' code (the benchmarks themselves are run by hand and
    by the e2e tests that time them)."""
    import inspect

    import runner.commands.bench as bench_mod
    import runner.commands.bench_contacts as contacts_mod

    source = inspect.getsource(bench_mod) + inspect.getsource(contacts_mod)
    unread = sorted(d for d in option_dests(["bench", bench]) if f"args.{d}" not in source)
    assert not unread, f"`dynsplines bench {bench}` never reads option(s) {unread}"


def test_every_subcommand_is_walked():
    """The tests above cover every subcommand; a new one must be added to them."""
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    covered = {"animate", "run-and-step", "mocap", "batch", "keyframes-from-bvh", "export", "view", "bench", "orient",
               "fig10", "blender-addon", "clean"}
    assert set(sub.choices) == covered, Path(__file__).name
