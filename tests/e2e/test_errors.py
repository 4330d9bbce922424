"""Bad input at every entry point: one clear message (file, field, value, what was expected, the fix),
a non-zero exit code, never a traceback; and the solver API's own checks.

The command-line cases run `runner.cli.main([...])` in-process and read stderr; each stops before the
optimization, so the whole file takes a few seconds. Messages of the keyframe reader and the BVH
importer are checked in detail in test_keyframe_io.py and test_bvh_import.py; here each error class is
checked once more where the user meets it, at the command line.
"""
import json
from pathlib import Path

import mujoco
import numpy as np
import pytest

from runner.cli import main
from runner.exit_codes import EXIT_INPUT, EXIT_INTERNAL
from solver.errors import InputError
from solver.frames import FrameSet
from solver.keyframes import Keyframes
from solver.layout import StateLayout
from solver.objective import Objective
from solver.paper.solve import SolveOptions, solve
from solver.quadrature import MAX_QUADRATURE_POINTS
from solver.terms import UnitQuaternion

REPO = Path(__file__).resolve().parents[2]
MODELS = REPO / "models"
SCENE = MODELS / "run_and_step.xml"
JOINTS = "root, l_hip, l_knee, l_ankle, r_hip, r_knee, r_ankle, torso, l_shoulder, l_elbow, r_shoulder, r_elbow"


def small_doc(n=3):
    """The first n keyframes of the shipped clip, with the scene and the figure as absolute paths."""
    doc = json.loads((MODELS / "run_and_step.keyframes.json").read_text())
    doc["keyframes"] = doc["keyframes"][:n]
    doc["scene"] = str(SCENE)
    doc["model"] = str(MODELS / "humanoid39.xml")  # "model" must name a file relative to the copy
    doc["source"] = {}
    return doc


def write(tmp_path, doc, name="k.json"):
    p = tmp_path / name
    if isinstance(doc, bytes):
        p.write_bytes(doc)
    else:
        p.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return p


def run(capsys, *argv):
    """(exit code, stderr) of the command line; asserts the error is one line without a traceback."""
    code = main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return code, err


def expect_input_error(capsys, argv, *fragments):
    code, err = run(capsys, *argv)
    assert code == EXIT_INPUT, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err  # one message
    assert lines[0].startswith("dynsplines"), err
    for f in fragments:
        assert f in lines[0], f"{f!r} not in {lines[0]!r}"
    return lines[0]


def animate(path, *more):
    return ["animate", path, "--no-render", "--quiet", *more]


# ------------------------------------------------------------------------------ keyframe files
def test_missing_keyframe_file(tmp_path, capsys):
    expect_input_error(capsys, animate(tmp_path / "nope.json"), "nope.json: no such keyframe file", "check the path")


def test_keyframe_file_is_a_folder(tmp_path, capsys):
    expect_input_error(capsys, animate(tmp_path), f"{tmp_path}: is a folder", "give the path of a .json")


def test_keyframe_file_not_text(tmp_path, capsys):
    p = write(tmp_path, b"\x89PNG\r\n\x1a\n\x00\x00")
    expect_input_error(capsys, animate(p), "k.json: not a text file (byte 0 is not UTF-8)")


def test_malformed_json_names_line_and_column(tmp_path, capsys):
    text = json.dumps(small_doc(), indent=1)
    p = write(tmp_path, text[: len(text) // 2])  # truncated: what an interrupted editor save leaves
    msg = expect_input_error(capsys, animate(p), "k.json: line ", ", column ", "malformed JSON")
    assert "no 'scene'" not in msg  # the file's own problem is reported, not a consequence of it


def test_not_a_keyframe_file(tmp_path, capsys):
    p = write(tmp_path, [1, 2, 3])
    expect_input_error(capsys, animate(p, "--scene", SCENE), "the top level is a list; a keyframe file is a JSON object")


def test_unknown_joint_lists_the_valid_ones(tmp_path, capsys):
    doc = small_doc()
    doc["keyframes"][1]["joints"]["l_kne"] = doc["keyframes"][1]["joints"].pop("l_knee")
    expect_input_error(capsys, animate(write(tmp_path, doc)),
                       "k.json: keyframe 1 (t=0.241666 s), joints: unknown joint 'l_kne'",
                       f"the figure's joints are: {JOINTS}")


def test_wrong_number_of_components(tmp_path, capsys):
    doc = small_doc()
    doc["keyframes"][1]["joints"]["l_knee"] = [1, 0, 0]
    expect_input_error(capsys, animate(write(tmp_path, doc)),
                       "keyframe 1 (t=0.241666 s), joint 'l_knee': [1, 0, 0] has 3 components",
                       "a ball joint takes a list of 4 (qw qx qy qz), null for a free component")


@pytest.mark.parametrize("literal, shown", [("NaN", "nan"), ("Infinity", "inf"), ("-Infinity", "-inf")])
def test_non_finite_value(tmp_path, capsys, literal, shown):
    doc = small_doc()
    doc["keyframes"][2]["joints"]["torso"][1] = 12345.5
    p = write(tmp_path, json.dumps(doc).replace("12345.5", literal))
    expect_input_error(capsys, animate(p), f"keyframe 2 (t=0.483331 s), joint 'torso', component 1 (qx): {shown} is "
                                           "not a finite number; give a number, or null to leave it free")


def test_non_finite_time(tmp_path, capsys):
    doc = small_doc()
    doc["keyframes"][1]["time"] = 12345.5
    p = write(tmp_path, json.dumps(doc).replace("12345.5", "Infinity"))
    expect_input_error(capsys, animate(p), "keyframe 1: 'time' is inf; give a finite number of seconds")


@pytest.mark.parametrize("q", [[0, 0, 0, 0], [1e-9, 0, 0, 0]], ids=["zero", "near-zero"])
def test_zero_quaternion(tmp_path, capsys, q):
    doc = small_doc()
    doc["keyframes"][2]["joints"]["l_hip"] = q
    expect_input_error(capsys, animate(write(tmp_path, doc)),
                       "keyframe 2 (t=0.483331 s) has a zero quaternion at qpos [7, 8, 9, 10]",
                       "give a unit quaternion (w x y z), e.g. [1, 0, 0, 0] for no rotation")


def test_times_not_increasing(tmp_path, capsys):
    doc = small_doc()
    doc["keyframes"][2]["time"] = 0.1
    expect_input_error(capsys, animate(write(tmp_path, doc)),
                       "keyframe 2 (t=0.1 s) comes before keyframe 1 (t=0.241666 s)",
                       "keyframe times must be strictly increasing")


def test_duplicated_time(tmp_path, capsys):
    doc = small_doc()
    doc["keyframes"][2]["time"] = doc["keyframes"][1]["time"]
    expect_input_error(capsys, animate(write(tmp_path, doc)),
                       "keyframe 2 (t=0.241666 s) duplicates keyframe 1 (t=0.241666 s)")


def test_negative_time(tmp_path, capsys):
    doc = small_doc()
    doc["keyframes"][0]["time"] = -0.1
    expect_input_error(capsys, animate(write(tmp_path, doc)),
                       "keyframe 0 has negative time -0.1 s; times start at 0 or later")


@pytest.mark.parametrize("n", [0, 1])
def test_fewer_than_two_keyframes(tmp_path, capsys, n):
    expect_input_error(capsys, animate(write(tmp_path, small_doc(n))),
                       f"k.json: need at least two keyframes to interpolate, got {n}")


@pytest.mark.parametrize("joints", [{}, {"l_knee": [None, None, None, None]}], ids=["no joints", "all null"])
def test_partial_keyframe_that_fixes_nothing(tmp_path, capsys, joints):
    doc = small_doc()
    doc["keyframes"][1]["joints"] = joints
    expect_input_error(capsys, animate(write(tmp_path, doc)),
                       "keyframe 1 (t=0.241666 s) fixes no component",
                       "a partial keyframe must fix at least one joint (or delete the keyframe)")


def test_keyframe_times_far_too_long(tmp_path, capsys):
    doc = small_doc(2)
    doc["keyframes"][1]["time"] = 1000.0  # frames, not seconds
    expect_input_error(capsys, animate(write(tmp_path, doc)),
                       "the keyframes span 1000 s", f"(at most {MAX_QUADRATURE_POINTS})",
                       "check the keyframe times (seconds, not frames) or lower the rate (--rate)")


# ------------------------------------------------------------------------------------ scenes
def test_no_scene(tmp_path, capsys):
    doc = small_doc()
    del doc["scene"]
    expect_input_error(capsys, animate(write(tmp_path, doc)), "k.json: no 'scene' in the file",
                       "give one with --scene SCENE.xml")


def test_scene_missing(tmp_path, capsys):
    p = write(tmp_path, small_doc())
    expect_input_error(capsys, animate(p, "--scene", tmp_path / "nope.xml"),
                       "nope.xml does not exist; give an MJCF file with --scene")


def test_scene_malformed(tmp_path, capsys):
    scene = write(tmp_path, "<mujoco><worldbody>", "bad.xml")
    expect_input_error(capsys, animate(write(tmp_path, small_doc()), "--scene", scene),
                       "scene file", "bad.xml could not be loaded by MuJoCo: XML parse error")


def test_scene_without_the_figure(tmp_path, capsys):
    scene = write(tmp_path, '<mujoco><worldbody><geom type="plane" size="1 1 .1"/></worldbody></mujoco>', "s.xml")
    expect_input_error(capsys, animate(write(tmp_path, small_doc()), "--scene", scene),
                       "s.xml has no free joint: does it include the figure (humanoid39.xml)?")


def test_scene_without_contact_sites(tmp_path, capsys):
    scene = write(tmp_path, '<mujoco><worldbody><body><freejoint/><geom size=".1"/><site name="l_toe"/>'
                            '</body></worldbody></mujoco>', "s.xml")
    expect_input_error(capsys, animate(write(tmp_path, small_doc()), "--scene", scene),
                       "s.xml: the figure has no feet", 'text name="figure:foot:left" data="l_heel l_toe"',
                       "Does it include the figure (humanoid39.xml)?")


# ------------------------------------------------------------------------- the constraint set
def test_unknown_term_set(tmp_path, capsys):
    expect_input_error(capsys, animate(write(tmp_path, small_doc()), "--terms", "penetration,smooth"),
                       "--terms is 'penetration,smooth'; give 'all'")


@pytest.mark.parametrize("terms", [{"penetration": 1}, "everything", 3])
def test_bad_terms_in_the_keyframe_file_name_the_file(tmp_path, capsys, terms):
    doc = small_doc()
    doc["terms"] = terms
    expect_input_error(capsys, animate(write(tmp_path, doc)), f"k.json: field 'terms' is {terms!r}; give",
                       "or remove the field")


# --------------------------------------------------------------------------------- outputs
def test_output_folder_cannot_be_created(tmp_path, capsys):
    (tmp_path / "afile").write_text("")
    expect_input_error(capsys, animate(write(tmp_path, small_doc()), "--save-path", tmp_path / "afile" / "x.npz"),
                       "cannot write", "x.npz: folder", "(a file is in the way", "choose another --save-path")


def test_output_is_a_folder(tmp_path, capsys):
    expect_input_error(capsys, ["animate", write(tmp_path, small_doc()), "--out", tmp_path],
                       "it is an existing folder; choose a file name for --out")


def test_video_name_and_size_checked_before_optimizing(tmp_path, capsys, monkeypatch):
    import runner.run

    monkeypatch.setattr(runner.run, "solve_problem", lambda *a, **k: pytest.fail("optimized before the check"))
    p = write(tmp_path, small_doc())
    expect_input_error(capsys, ["animate", p, "--out", tmp_path / "x.avi"],
                       "--out", "x.avi: a video file must end in one of .mp4, .mkv, .mov")
    expect_input_error(capsys, ["animate", p, "--out", tmp_path / "x.mp4", "--size", "961x540"],
                       "--size 961x540: width and height must be even", "--size 962x540")
    assert not (tmp_path / "x.avi").exists() and not (tmp_path / "x.mp4").exists()


@pytest.mark.skipif(hasattr(__import__("os"), "geteuid") and __import__("os").geteuid() == 0,
                    reason="root writes read-only folders")
def test_read_only_output_folder(tmp_path, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        expect_input_error(capsys, animate(write(tmp_path, small_doc()), "--save-path", ro / "x.npz"),
                           "is not writable")
    finally:
        ro.chmod(0o700)


# ---------------------------------------------------------------------- command-line values
@pytest.mark.parametrize("argv, fragment", [
    (["--fps", "0"], "argument --fps: '0' must be > 0"),
    (["--max-time", "-1"], "argument --max-time: '-1' must be >= 0"),
    (["--max-time", "nan"], "argument --max-time: 'nan' must be >= 0"),
    (["--size", "10x"], "argument --size: --size '10x': expected WIDTHxHEIGHT, e.g. 960x540"),
    (["--max-evals", "two"], "argument --max-evals: 'two' is not a whole number"),
    (["--tol", "0"], "argument --tol: '0' must be > 0"),
])
def test_bad_option_values(tmp_path, capsys, argv, fragment):
    msg = expect_input_error(capsys, ["animate", tmp_path / "k.json", *argv], fragment)
    assert msg.startswith("dynsplines animate: error: ") and msg.endswith("(see 'dynsplines animate --help')")


@pytest.mark.parametrize("argv, prog, fragment", [
    (["mocap", "clip.bvh", "--evry", "0.25"], "mocap", "unrecognized arguments: --evry 0.25; did you mean --every?"),
    (["mocap", "clip.bvh", "--evry=0.25"], "mocap", "unrecognized arguments: --evry=0.25; did you mean --every?"),
    (["animate", "k.json", "--no-rendr"], "animate", "did you mean --no-render?"),
    (["bench", "corpus", "--evry", "0.2"], "bench corpus", "did you mean --every?"),
    (["animate", "k.json", "--zzz"], "animate", "unrecognized arguments: --zzz (see"),  # nothing near: no guess
    (["export", "a.npz", "b.npz", "--to", "x.glb"], "export", "unrecognized arguments: b.npz (see"),
])
def test_an_unknown_option_is_the_subcommands_with_the_nearest_one(capsys, argv, prog, fragment):
    """Arguments no parser knows are reported by the subcommand given, which points to its own --help."""
    msg = expect_input_error(capsys, argv, fragment)
    assert msg.startswith(f"dynsplines {prog}: error: ") and msg.endswith(f"(see 'dynsplines {prog} --help')"), msg


def test_unknown_command_and_missing_argument(capsys):
    expect_input_error(capsys, ["animat"], "invalid choice: 'animat'", "(see 'dynsplines --help')")
    expect_input_error(capsys, ["animate"], "the following arguments are required: keyframes")


# ------------------------------------------------------------------------------------ BVH
def test_bvh_errors_at_the_command_line(tmp_path, capsys):
    out = tmp_path / "k.json"
    expect_input_error(capsys, ["keyframes-from-bvh", tmp_path / "nope.bvh", "--out", out],
                       "nope.bvh: cannot read the BVH clip: no such file")
    bvh = write(tmp_path, "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0\n", "x.bvh")
    expect_input_error(capsys, ["keyframes-from-bvh", bvh, "--out", out], "x.bvh: line 4:", "OFFSET takes three numbers")
    expect_input_error(capsys, ["keyframes-from-bvh", "--out", out, bvh], "x.bvh: line 4:")  # options first work
    expect_input_error(capsys, ["keyframes-from-bvh", bvh], "dynsplines keyframes-from-bvh: error: the following "
                       "arguments are required: --out (see 'dynsplines keyframes-from-bvh --help')")
    expect_input_error(capsys, ["keyframes-from-bvh", MODELS / "cmu" / "127_33.bvh", "--out", out, "--every", "-1"],
                       "keyframe spacing every=-1.0; give a positive number of seconds")
    assert not out.exists()


# -------------------------------------------------------------------------- debug, bugs
def test_debug_shows_the_traceback(tmp_path):
    with pytest.raises(InputError, match="need at least two keyframes"):
        main(["--debug", *map(str, animate(write(tmp_path, small_doc(1))))])


def test_internal_error_is_one_message_with_exit_1(tmp_path, capsys, monkeypatch):
    import runner.run

    def bug(*a, **k):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(runner.run, "solve_problem", bug)
    code, err = run(capsys, *animate(write(tmp_path, small_doc())))
    assert code == EXIT_INTERNAL
    assert err.startswith("dynsplines: internal error: ZeroDivisionError: a bug")
    assert "--debug" in err


# ============================================================================ solver API
@pytest.fixture(scope="module")
def model():
    return mujoco.MjModel.from_xml_path(str(SCENE))


@pytest.fixture(scope="module")
def problem(model):
    import tempfile

    from solver.keyframe_file import read_keyframes

    layout = StateLayout.from_model(model)
    with tempfile.TemporaryDirectory() as d:
        kf, _ = read_keyframes(write(Path(d), small_doc()), layout)
    return kf, layout


@pytest.mark.parametrize("times, values, mask, fragment", [
    ([0.0], [[1.0]], [[True]], "need at least two keyframes to interpolate, got 1"),
    ([0.0, np.nan], [[1.0], [1.0]], [[True], [True]], "keyframe 1 has time nan; times must be finite"),
    ([0.0, np.inf], [[1.0], [1.0]], [[True], [True]], "keyframe 1 has time inf"),
    ([-1.0, 1.0], [[1.0], [1.0]], [[True], [True]], "keyframe 0 has negative time -1.0 s"),
    ([0.0, 1.0, 1.0], [[1.0]] * 3, [[True]] * 3, "keyframe 2 (t=1.0 s) duplicates keyframe 1"),
    ([0.0, 2.0, 1.0], [[1.0]] * 3, [[True]] * 3, "keyframe 2 (t=1.0 s) comes before keyframe 1"),
    ([0.0, 1.0], [[1.0], [1.0]], [[True], [False]], "keyframe 1 (t=1.0 s) fixes no component"),
    ([0.0, 1.0], [[1.0], [np.nan]], [[True], [True]], "keyframe 1 (t=1.0 s) component 0 is nan"),
    ([0.0, 1.0], [1.0, 1.0], [True, True], "keyframe values must have shape (k=2, nq), got (2,)"),
    ([0.0, 1.0], [[1.0], [1.0]], [[True, True], [True, True]], "keyframe mask shape (2, 2) != values shape (2, 1)"),
])
def test_keyframes_api(times, values, mask, fragment):
    with pytest.raises(InputError) as e:
        Keyframes(np.array(times), np.array(values), np.array(mask), source="api")
    assert str(e.value).startswith("api: ") and fragment in str(e.value), str(e.value)


def test_zero_quaternion_and_bad_slots_api():
    kf = Keyframes([0.0, 1.0], [[0, 0, 0, 0], [1, 0, 0, 0]], np.ones((2, 4), bool), source="api")
    with pytest.raises(InputError, match=r"api: keyframe 0 \(t=0.0 s\) has a zero quaternion at qpos \[0, 1, 2, 3\]"):
        FrameSet.from_keyframes(kf, [[0, 1, 2, 3]])
    with pytest.raises(InputError, match=r"quaternion slots \[\[1, 2, 3, 4\]\] do not fit keyframes of nq=4"):
        FrameSet.from_keyframes(kf, [[1, 2, 3, 4]])


def test_objective_api():
    with pytest.raises(InputError, match="weight of objective term 'unit' is -2.0; weights must be >= 0"):
        Objective([UnitQuaternion(np.array([[0, 1, 2, 3]]))], [-2.0], 0, 1)
    with pytest.raises(InputError, match=r"objective interval \[1, 1\] s is empty"):
        Objective([UnitQuaternion(np.array([[0, 1, 2, 3]]))], [1.0], 1, 1)


@pytest.mark.parametrize("kwargs, fragment", [
    ({"subdivision": "random"}, "unknown subdivision 'random'; choose one of: none, global, adaptive"),
    ({"rounds": -1}, "rounds must be a whole number >= 0, got -1"),
    ({"rounds": "2"}, "rounds must be a whole number >= 0, got '2'"),
    ({"max_time_s": float("nan")}, "max_time_s must be >= 0, got nan"),
    ({"algorithm": "bfgs"}, "unknown algorithm 'bfgs'; choose one of: lbfgs, mma"),
    ({"ftol_rel": -1e-3}, "ftol_rel must be >= 0"),
])
def test_solve_options_api(kwargs, fragment):
    with pytest.raises(InputError) as e:
        SolveOptions(**kwargs)
    assert fragment in str(e.value)


def test_solve_api_checks(model, problem):
    kf, layout = problem
    def objective(t0, t1):
        return Objective([UnitQuaternion(layout.quat_slots)], [1.0], t0, t1, rate=400.0)

    obj = objective(kf.times[0], kf.times[-1])
    fs = FrameSet.from_keyframes(kf, layout.quat_slots)
    with pytest.raises(InputError, match=r"initial must be a FrameSet, got Keyframes \(make one with "
                                         r"FrameSet.from_keyframes"):
        solve(obj, kf)
    with pytest.raises(InputError, match="options must be a SolveOptions, got dict"):
        solve(obj, fs, {"rounds": 0})
    with pytest.raises(InputError, match=r"the objective integrates over \[0, 5\] s but the frames span \[0, 0.483331\] s"):
        solve(objective(0.0, 5.0), fs)
    other = Keyframes([0.0, kf.times[-1]], [[1, 0, 0, 0]] * 2, np.ones((2, 4), bool))
    with pytest.raises(InputError, match=r"cannot be evaluated on frames of shape \(2, 4\).*same nq"):
        solve(obj, FrameSet.from_keyframes(other, [[0, 1, 2, 3]]))


def test_keyframe_inside_a_surface_is_warned_about(tmp_path, capsys):
    """Keyframes are hard constraints: one that puts a foot in the floor gets a warning naming it
    (the run still completes: the in-betweens are optimized)."""
    doc = small_doc(3)
    doc["keyframes"][1]["joints"]["root"][2] = 0.5  # pelvis 0.5 m up: the legs go ~0.4 m into the floor
    code, err = run(capsys, "animate", write(tmp_path, doc), "--no-render", "--max-evals", "5")
    assert code == 0
    assert "keyframe 1 (t=0.241666 s) puts" in err and "mm inside a surface" in err
    assert "keyframe 0" not in err and "keyframe 2" not in err


def test_a_crash_in_native_code_prints_where_each_thread_was():
    """A segmentation fault (here a read of address 0, as a GL driver's would be) is no user mistake and
    cannot be caught: the command line has `faulthandler` print every thread's Python stack first, so
    that a report of the crash says where it was."""
    import subprocess
    import sys

    code = ("import ctypes, runner.cli as cli\n"
            "cli._crash_tracebacks()\n"
            "def where_it_crashed():\n"
            "    ctypes.string_at(0)\n"
            "where_it_crashed()\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert done.returncode != 0
    assert "Fatal Python error" in done.stderr and "where_it_crashed" in done.stderr
