"""Property: any keyframe file - random structure or a corrupted copy of a good one - gives either
clean keyframes or one clean InputError naming the file; never another exception, never a hang.

Two levels: the reader and the solver's checks (many examples, milliseconds each), and the whole
command line with a two-evaluation optimization (fewer examples): exit code 0 (a path meeting its
keyframes), 2 (one error message) or 3 (the optimizer failed partway: one warning, the best path
before it written), never a traceback or stray numpy warnings.
"""
import contextlib
import io
import json
import os
import tempfile
from pathlib import Path

import mujoco
import numpy as np
import pytest
from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st

from runner.cli import main
from runner.exit_codes import EXIT_FAILED, EXIT_INPUT, EXIT_OK
from solver.errors import InputError
from solver.frames import FrameSet
from solver.keyframe_file import read_keyframes
from solver.layout import StateLayout
from solver.spline import interpolate

REPO = Path(__file__).resolve().parents[2]
MODELS = REPO / "models"
SCENE = MODELS / "run_and_step.xml"
LAYOUT = StateLayout.from_model(mujoco.MjModel.from_xml_path(str(SCENE)))
NAMES = [j.name for j in LAYOUT.joints]

#: examples of the reader property (the command-line property runs an eighth of them); raise it for a
#: longer hunt, e.g. DYNSPLINES_HYPOTHESIS_EXAMPLES=5000
EXAMPLES = int(os.environ.get("DYNSPLINES_HYPOTHESIS_EXAMPLES", 400))

GOOD = json.loads((MODELS / "run_and_step.keyframes.json").read_text())
GOOD["keyframes"] = GOOD["keyframes"][:3]
GOOD["scene"] = str(SCENE)
GOOD["model"] = str(MODELS / "humanoid39.xml")  # "model" must name a file relative to the copy
GOOD_TEXT = json.dumps(GOOD, indent=1)

# ------------------------------------------------------------------------------------ strategies
numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-2, 2),
    st.sampled_from([0.0, -0.0, 1e-9, 1e-300, 1e300]),
    st.integers(-10**6, 10**6),
)
junk = st.one_of(st.none(), st.booleans(), st.text(max_size=5), st.lists(st.integers(), max_size=2),
                 st.dictionaries(st.text(max_size=3), st.integers(), max_size=2))


def joint_values(name):
    nq = LAYOUT.joint(name).nq if name in NAMES else 4
    good_len = st.lists(st.one_of(numbers, st.none()), min_size=nq, max_size=nq)
    plausible = st.lists(st.floats(-1, 1), min_size=nq, max_size=nq)
    return st.one_of(plausible, good_len, st.lists(st.one_of(numbers, st.none(), junk), max_size=9), junk)


joint_name = st.one_of(st.sampled_from(NAMES), st.sampled_from(["l_kne", "Root", "", "hips"]), st.text(max_size=6))


@st.composite
def joints(draw):
    names = draw(st.lists(joint_name, max_size=6, unique=True))
    return {n: draw(joint_values(n)) for n in names}


@st.composite
def documents(draw):
    k = draw(st.integers(0, 5))
    base = sorted(draw(st.lists(st.floats(0, 3), min_size=k, max_size=k, unique=True)))
    frames = []
    for i in range(k):
        kf = {}
        if draw(st.integers(0, 9)):  # mostly a plausible time
            kf["time"] = base[i] if draw(st.booleans()) else draw(st.one_of(numbers, junk))
        if draw(st.integers(0, 9)):
            kf["joints"] = draw(joints()) if draw(st.integers(0, 4)) else draw(junk)
        if not draw(st.integers(0, 9)):
            kf[draw(st.sampled_from(["comment", "tme", "Joints"]))] = draw(junk)
        frames.append(kf)
    doc = {"keyframes": frames if draw(st.integers(0, 9)) else draw(junk)}
    for key in draw(st.lists(st.sampled_from(["format", "model", "scene", "source", "terms", "extra"]),
                             max_size=3, unique=True)):
        doc[key] = draw(st.one_of(junk, st.sampled_from(["dynsplines.keyframes/1", "run_and_step.xml"])))
    text = json.dumps(doc, allow_nan=True)
    return text.encode() if draw(st.integers(0, 9)) else draw(st.sampled_from([b"[", b"\xff\xfe", b""]))


@st.composite
def plausible(draw):
    """Well-formed files with odd but legal content: gaps from a microsecond to seconds, partial
    keyframes, non-unit quaternions, far-away roots."""
    k = draw(st.integers(2, 4))
    gaps = draw(st.lists(st.one_of(st.floats(0.05, 1.0), st.sampled_from([1e-6, 1e-3, 0.01, 3.0])),
                         min_size=k - 1, max_size=k - 1))
    times = np.concatenate([[draw(st.sampled_from([0.0, 0.5]))], np.cumsum(gaps)]).tolist()
    frames = []
    for t in times:
        joints = {}
        for name in draw(st.lists(st.sampled_from(NAMES), min_size=1, max_size=len(NAMES), unique=True)):
            nq = LAYOUT.joint(name).nq
            comps = draw(st.lists(st.floats(-1, 1), min_size=nq, max_size=nq))
            if name == "root":
                comps[:3] = draw(st.lists(st.one_of(st.floats(-3, 3), st.sampled_from([1e3, -1e3])),
                                          min_size=3, max_size=3))
            for i in draw(st.lists(st.integers(0, nq - 1), max_size=nq - 1, unique=True)):
                comps[i] = None
            joints[name] = comps
        frames.append({"time": t, "joints": joints})
    return json.dumps({"format": "dynsplines.keyframes/1", "scene": str(SCENE), "keyframes": frames}).encode()


@st.composite
def corrupted(draw):
    """The good file with a few random edits: deletions, insertions, replaced bytes, truncation."""
    data = bytearray(GOOD_TEXT.encode())
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(["delete", "insert", "replace", "truncate", "swap_number"]))
        i = draw(st.integers(0, len(data)))
        if op == "delete":
            del data[i:i + draw(st.integers(1, 40))]
        elif op == "insert":
            data[i:i] = draw(st.sampled_from([b",", b"]", b"{", b'"', b"NaN", b"-", b"0", b"null", b"\n", b"1e400",
                                              b"\x00", b"\xc3", b'"l_knee": [1]', b"-Infinity"]))
        elif op == "replace" and i < len(data):
            data[i] = draw(st.integers(0, 255))
        elif op == "truncate":
            del data[i:]
        elif op == "swap_number":
            text = data.decode(errors="replace")
            text = text.replace("0.241666", draw(st.sampled_from(["0.0", "-1", "0.483331", "1e9", "NaN"])), 1)
            data = bytearray(text.encode())
    return bytes(data)


files = st.one_of(documents(), corrupted(), plausible())

# ---------------------------------------------------------------------------------------- checks
def check_clean(path: Path) -> str:
    """Read and validate `path`; 'ok' or 'error', asserting the error is a clean InputError."""
    try:
        kf, _ = read_keyframes(path, LAYOUT)
        fs = FrameSet.from_keyframes(kf, LAYOUT.quat_slots)
    except InputError as e:
        msg = str(e)
        assert str(path) in msg, msg  # names the file
        assert "\n" not in msg and msg.strip() == msg, msg  # one line
        return "error"
    assert kf.count >= 2 and np.all(np.diff(kf.times) > 0) and kf.times[0] >= 0
    assert np.isfinite(kf.values[kf.mask]).all() and np.isnan(kf.values[~kf.mask]).all()
    assert kf.mask.any(axis=1).all()
    assert np.isfinite(fs.values).all()
    norms = np.linalg.norm(fs.values[:, LAYOUT.quat_slots], axis=-1)
    assert (norms >= 1e-6).all()
    target = kf.values.copy()  # the frames keep every fixed component (quaternions up to sign)
    for slot in LAYOUT.quat_slots:
        flip = np.nansum(fs.values[:, slot] * target[:, slot], axis=1) < 0
        target[np.ix_(flip, slot)] *= -1
    assert np.array_equal(fs.values[kf.mask], target[kf.mask])
    return "ok"


@pytest.mark.slow
@settings(max_examples=EXAMPLES, deadline=2000, suppress_health_check=[HealthCheck.too_slow])
@given(data=files)
def test_reader_gives_keyframes_or_a_clean_error(data):
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "k.json"
        p.write_bytes(data)
        outcome = check_clean(p)
    event(f"outcome: {outcome}")


@pytest.mark.slow
@settings(max_examples=EXAMPLES // 8, deadline=10000, suppress_health_check=[HealthCheck.too_slow])
@given(data=files)
@example(data=b'{"format": "dynsplines.keyframes/1", "keyframes": [], "scene": "\\u0000"}')  # found: a NUL in a path was a ValueError
@example(data=json.dumps({"format": "dynsplines.keyframes/1", "keyframes": [  # found: a knee at a half turn with 1e-167 components: twist gradient 0/0
    {"time": 0.0, "joints": {"l_knee": [-2.2855872811881898e-167, 0.0, 8.0795528188009805e-174, 1.0]}},
    {"time": 1.0, "joints": {"root": [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]}}]}).encode())
@example(data=json.dumps({"format": "dynsplines.keyframes/1", "keyframes": [  # found: a keyframe inside the step warns before the failure line
    {"time": 0.0, "joints": {"l_hip": [0, 0, 0, 1], "r_knee": [0, 0, 2.812893771223057e-194, 1],
                             "r_ankle": [None, 0, 0, 0]}},
    {"time": 1.0, "joints": {"l_hip": [None, 0, 0, 0]}}]}).encode())
@example(data=json.dumps({"format": "dynsplines.keyframes/1", "keyframes": [  # found: [0, null, 0, 0] lost its fixed w = 0
    {"time": 0.0, "joints": {"root": [0, 0, 0, 0, 0, 0, 1], "l_ankle": [0, None, 0, 0]}},
    {"time": 1.0, "joints": {"l_hip": [None, 0, 0, 0]}}]}).encode())
def test_command_line_exits_cleanly(data):
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "k.json"
        p.write_bytes(data)
        stderr = io.StringIO()
        with contextlib.redirect_stderr(stderr), contextlib.redirect_stdout(io.StringIO()):
            code = main(["animate", str(p), "--scene", str(SCENE), "--no-render", "--quiet", "--max-evals", "2",
                         "--save-path", os.path.join(d, "out.npz")])
        err = stderr.getvalue()
        assert "Traceback" not in err and "internal error" not in err, err
        assert code in (EXIT_OK, EXIT_INPUT, EXIT_FAILED), (code, err)
        if code == EXIT_INPUT:
            assert len(err.strip().splitlines()) == 1 and err.startswith("dynsplines: error: "), err
        else:  # a result; with exit 3 (the optimizer failed partway) the best path before it
            if code == EXIT_FAILED:  # the failure line, after at most the keyframe-penetration warnings
                lines = err.strip().splitlines()
                assert lines[-1].startswith("dynsplines: warning: the optimization failed ("), err
                assert all(" puts " in line and "inside a surface" in line for line in lines[:-1]), err
            z = np.load(os.path.join(d, "out.npz"))
            assert np.isfinite(z["frames"]).all()
            t = z["keyframe_times"]  # round-off of re-interpolation grows with |values| and span / gap
            scale = max(1.0, float(np.nanmax(np.abs(z["keyframes"])))) * (t[-1] - t[0]) / np.diff(t).min()
            assert keyframe_error(z) <= 1e-10 * scale
    event(f"exit code: {code}")


def keyframe_error(z) -> float:
    """Largest |path(t_k) - keyframe| over fixed components (quaternions up to sign)."""
    Y = interpolate(z["frame_times"], z["frames"], z["keyframe_times"])
    target = z["keyframes"].copy()
    for slot in LAYOUT.quat_slots:
        flip = np.nansum(Y[:, slot] * target[:, slot], axis=1) < 0
        target[np.ix_(flip, slot)] *= -1
    return float(np.abs(Y - target)[z["keyframe_mask"]].max())


def test_two_keyframes_with_only_partial_freedom(tmp_path):
    """Found by the property test: two keyframes, no variable frames, the free components of partial
    keyframes only. The spline is a line (Y'' = 0), so the acceleration preconditioner saw H = 0 and
    the first step overflowed; it must converge."""
    p = tmp_path / "k.json"
    p.write_text(json.dumps({"format": "dynsplines.keyframes/1", "scene": str(SCENE), "keyframes": [
        {"time": 0.0, "joints": {"root": [0, 0, 0, 0, 0, 0, 1], "l_hip": [0, 0, 0, 1]}},
        {"time": 1.0, "joints": {"l_hip": [None, 0, 0, 0]}}]}))
    out = tmp_path / "out.npz"
    with contextlib.redirect_stdout(io.StringIO()):
        code = main(["animate", str(p), "--no-render", "--quiet", "--save-path", str(out)])
    assert code == EXIT_OK
    z = np.load(out)
    # it ends normally: converged, or infeasible where the keyed root at the floor puts feet into it
    # (the least violation certifies what the keyframes leave out of reach)
    assert str(z["status"]) in ("converged", "infeasible") and keyframe_error(z) <= 1e-9
    assert np.isfinite(z["frames"]).all() and not np.array_equal(z["frames"], z["plain_frames"])


def test_zero_filled_partial_quaternion_keeps_its_fixed_components():
    """Found by the property test: [0, null, 0, 0] with x fixed nowhere else was filled to zero and
    then replaced by the identity [1, 0, 0, 0], breaking the keyframe's w = 0."""
    from solver.keyframes import Keyframes

    values = np.array([[0.0, np.nan, 0.0, 0.0], [np.nan, 0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]])
    kf = Keyframes([0.0, 1.0, 2.0], values, ~np.isnan(values))
    filled = kf.initial_values([[0, 1, 2, 3]])
    assert np.array_equal(filled[kf.mask], values[kf.mask])
    assert filled[0].tolist() == [0.0, 1.0, 0.0, 0.0]  # the free x takes the rotation


def test_both_outcomes_were_exercised():
    """The strategies reach valid files as well as broken ones. Self-contained (it used to read the
    counts left by the reader test and skip when run alone): it draws its own examples, derandomized,
    so the result does not depend on the test order or the example database."""
    outcomes: dict[str, int] = {}

    @settings(max_examples=min(EXAMPLES, 50), derandomize=True, database=None, deadline=None,
              suppress_health_check=[HealthCheck.too_slow])
    @given(data=files)
    def draw(data):
        with tempfile.TemporaryDirectory() as d:
            p = Path(d) / "k.json"
            p.write_bytes(data)
            outcome = check_clean(p)
        outcomes[outcome] = outcomes.get(outcome, 0) + 1

    draw()
    assert outcomes.get("ok", 0) > 0 and outcomes.get("error", 0) > 0, outcomes
