"""Keyframe files (solver/keyframe_file.py): round trip, atomic write, and every malformed-input message."""
import json
from pathlib import Path

import mujoco
import numpy as np
import pytest

from solver.errors import InputError
from solver.keyframe_file import FORMAT, read_keyframes, write_keyframes
from solver.keyframes import Keyframes
from solver.layout import StateLayout

MODELS = Path(__file__).resolve().parents[2] / "models"


@pytest.fixture(scope="module")
def figure():
    """The shipped figure's model alone (no scene): contacts are checked against its feet."""
    return mujoco.MjModel.from_xml_path(str(MODELS / "humanoid39.xml"))


@pytest.fixture(scope="module")
def layout(figure):
    return StateLayout.from_model(figure)


def sample_keyframes(layout, rng):
    k = 3
    values = np.zeros((k, layout.nq))
    values[:, :3] = rng.normal(size=(k, 3))
    for slot in layout.quat_slots:
        q = rng.normal(size=(k, 4))
        values[:, slot] = q / np.linalg.norm(q, axis=1, keepdims=True)
    mask = np.ones_like(values, bool)
    mask[1] = False
    mask[1, layout.joint("root").qpos_slice] = True  # keyframe 1 fixes only the root ...
    mask[1, layout.joint("l_knee").qposadr] = True  # ... and one component of the left knee
    return Keyframes(np.array([0.0, 0.25, 0.6]), values, mask, source="test")


def write_json(tmp_path, doc, name="k.json"):
    p = tmp_path / name
    p.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return p


def minimal(**kf1):
    return {"format": FORMAT, "keyframes": [{"time": 0.0, "joints": {"root": [0, 0, 1, 1, 0, 0, 0]}},
                          {"time": 0.5, "joints": {"root": [1, 0, 1, 1, 0, 0, 0], **kf1}}]}


def test_round_trip(tmp_path, layout):
    kf = sample_keyframes(layout, np.random.default_rng(0))
    (tmp_path / "sub").mkdir()
    out = tmp_path / "sub" / "clip.keyframes.json"
    source = {"clip": "cmu/x.bvh", "command": "python -c 'x' --out y", "hand_edits": "none"}
    write_keyframes(out, kf, layout, model=MODELS / "humanoid39.xml", scene=MODELS / "run_and_step.xml",
                    source=source, terms="all")
    assert sorted(p.name for p in out.parent.iterdir()) == ["clip.keyframes.json"]  # no temporary left
    back, info = read_keyframes(out, layout)
    assert back.times == pytest.approx(kf.times)
    assert np.array_equal(back.mask, kf.mask)
    assert back.values[kf.mask] == pytest.approx(kf.values[kf.mask], abs=1e-6)
    assert np.isnan(back.values[~kf.mask]).all()
    assert back.source == str(out)
    assert info.model == (MODELS / "humanoid39.xml").resolve()
    assert info.scene == (MODELS / "run_and_step.xml").resolve()
    assert info.source == source and info.terms == "all"
    doc = json.loads(out.read_text())
    assert doc["format"] == FORMAT
    assert not Path(doc["model"]).is_absolute()  # relative to the keyframe file
    assert (out.parent / doc["model"]).resolve() == (MODELS / "humanoid39.xml").resolve()
    kf1 = doc["keyframes"][1]["joints"]
    assert sorted(kf1) == ["l_knee", "root"]  # joints with nothing fixed are omitted
    assert kf1["l_knee"][1:] == [None, None, None]  # free components are null
    # a human-readable layout: one line per joint
    assert '      "l_hip": [' in out.read_text()


def test_reads_hand_written_file(tmp_path, layout):
    (tmp_path / "humanoid39.xml").write_text("<mujoco/>")  # "model" must name a file (not read here)
    p = write_json(tmp_path, {
        "format": FORMAT, "model": "humanoid39.xml",
        "keyframes": [
            {"time": 0.0, "comment": "start", "joints": {"root": [0, 0, 1, 1, 0, 0, 0], "l_knee": [1, 0, 0, 0]}},
            {"time": 0.5, "joints": {"root": [1, 0, None, None, None, None, None]}},
        ],
    })
    kf, info = read_keyframes(p, layout)
    assert kf.count == 2 and kf.is_partial.all()
    assert kf.mask[1].sum() == 2 and kf.values[1, 0] == 1.0
    assert info.model == (tmp_path / "humanoid39.xml").resolve() and info.scene is None
    assert info.source == {} and info.terms is None


def test_a_file_saved_with_a_byte_order_mark_reads_as_without(tmp_path, layout):
    """Notepad and .NET's UTF-8 writers put a byte-order mark first; JSON has none, and json.loads refuses it."""
    text = json.dumps(minimal(l_knee=[1, 0, 0, 0]))
    plain, marked = write_json(tmp_path, text, "plain.json"), tmp_path / "marked.json"
    marked.write_bytes(b"\xef\xbb\xbf" + text.encode("utf-8"))
    (a, _), (b, _) = read_keyframes(plain, layout), read_keyframes(marked, layout)
    assert np.array_equal(a.times, b.times) and np.array_equal(a.values, b.values, equal_nan=True) and np.array_equal(a.mask, b.mask)


@pytest.mark.parametrize("umask", [0o022, 0o077])
def test_written_file_has_the_permissions_of_a_new_file(tmp_path, layout, umask):
    """The atomic write goes through mkstemp (mode 0600); the result gets 0666 minus the umask, as a file
    opened for writing would (a keyframe file is shared with other tools and people)."""
    import os
    import stat

    old = os.umask(umask)
    try:
        write_keyframes(tmp_path / "k.json", sample_keyframes(layout, np.random.default_rng(2)), layout)
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "k.json").stat().st_mode) == 0o666 & ~umask


def test_overwrite_is_atomic_and_complete(tmp_path, layout):
    kf = sample_keyframes(layout, np.random.default_rng(1))
    out = tmp_path / "k.json"
    out.write_text("old")
    write_keyframes(out, kf, layout)
    assert read_keyframes(out, layout)[0].count == 3
    with pytest.raises(InputError, match="the folder .*nowhere does not exist"):
        write_keyframes(tmp_path / "nowhere" / "k.json", kf, layout)
    with pytest.raises(InputError, match="cannot be written as JSON"):
        write_keyframes(out, kf, layout, source={"x": object()})
    assert read_keyframes(out, layout)[0].count == 3  # the failed writes left the file alone
    assert sorted(p.name for p in tmp_path.iterdir()) == ["k.json"]


def test_file_errors(tmp_path, layout):
    with pytest.raises(InputError, match=r"nope\.json: no such keyframe file"):
        read_keyframes(tmp_path / "nope.json", layout)
    with pytest.raises(InputError, match="is a folder"):
        read_keyframes(tmp_path, layout)
    p = write_json(tmp_path, '{\n  "keyframes": [\n    {"time": 0,}\n  ]\n}\n')
    with pytest.raises(InputError, match=r"k\.json: line 3, column 16: malformed JSON \(Expecting property name"):
        read_keyframes(p, layout)
    p = write_json(tmp_path, "[1, 2]")
    with pytest.raises(InputError, match="the top level is a list; a keyframe file is a JSON object"):
        read_keyframes(p, layout)
    p = write_json(tmp_path, {"format": "other/2", "keyframes": []})
    with pytest.raises(InputError, match=r"field 'format' is 'other/2'; this program reads 'dynsplines.keyframes/1'"):
        read_keyframes(p, layout)
    p = write_json(tmp_path, {"format": FORMAT, "frames": []})
    with pytest.raises(InputError, match=r"unknown top-level field\(s\) 'frames'"):
        read_keyframes(p, layout)
    p = write_json(tmp_path, {"format": FORMAT, "model": "x.xml"})
    with pytest.raises(InputError, match=r"missing field 'keyframes'"):
        read_keyframes(p, layout)


def test_keyframe_field_errors(tmp_path, layout):
    doc = minimal()
    del doc["keyframes"][1]["time"]
    with pytest.raises(InputError, match=r"k\.json: keyframe 1: missing field 'time'"):
        read_keyframes(write_json(tmp_path, doc), layout)
    doc = minimal()
    doc["keyframes"][1]["time"] = "0.5"
    with pytest.raises(InputError, match=r"keyframe 1: 'time' is '0.5'; give a finite number of seconds"):
        read_keyframes(write_json(tmp_path, doc), layout)
    doc = minimal()
    del doc["keyframes"][0]["joints"]
    with pytest.raises(InputError, match=r"keyframe 0 \(t=0.0 s\): missing field 'joints'"):
        read_keyframes(write_json(tmp_path, doc), layout)
    doc = minimal()
    doc["keyframes"][0]["tme"] = 1
    with pytest.raises(InputError, match=r"keyframe 0: unknown field\(s\) 'tme'"):
        read_keyframes(write_json(tmp_path, doc), layout)


def test_joint_errors(tmp_path, layout):
    p = write_json(tmp_path, minimal(l_knees=[1, 0, 0, 0]))
    with pytest.raises(InputError, match=r"keyframe 1 \(t=0.5 s\), joints: unknown joint 'l_knees'; the figure's "
                                         r"joints are: root, l_hip, l_knee, .*r_elbow"):
        read_keyframes(p, layout)
    p = write_json(tmp_path, minimal(l_knee=[1, 0, 0]))
    with pytest.raises(InputError, match=r"joint 'l_knee': \[1, 0, 0\] has 3 components; a ball joint takes a list "
                                         r"of 4 \(qw qx qy qz\)"):
        read_keyframes(p, layout)
    p = write_json(tmp_path, minimal(root=[0, 0, 1, 1]))
    with pytest.raises(InputError, match=r"joint 'root'.* has 4 components; a free joint takes a list of 7 "
                                         r"\(x y z qw qx qy qz\)"):
        read_keyframes(p, layout)
    p = write_json(tmp_path, minimal(l_knee=0.5))
    with pytest.raises(InputError, match=r"joint 'l_knee': 0.5 is not a list; a ball joint takes a list of 4"):
        read_keyframes(p, layout)


@pytest.mark.parametrize("text, shown", [("NaN", "nan"), ("Infinity", "inf"), ("-Infinity", "-inf"),
                                         ('"0.3"', "'0.3'"), ("true", "True"), ("[1]", r"\[1\]")])
def test_bad_values(tmp_path, layout, text, shown):
    raw = json.dumps(minimal(l_elbow=[1, 0, 0, 0])).replace('"l_elbow": [1, 0, 0, 0]', f'"l_elbow": [1, 0, {text}, 0]')
    p = write_json(tmp_path, raw)
    with pytest.raises(InputError, match=rf"keyframe 1 \(t=0.5 s\), joint 'l_elbow', component 2 \(qy\): {shown} is "
                                         "not a finite number; give a number, or null"):
        read_keyframes(p, layout)


def test_checks_of_solver_keyframes_name_the_file(tmp_path, layout):
    doc = minimal()
    doc["keyframes"][1]["time"] = 0.0
    with pytest.raises(InputError, match=r"k\.json: keyframe 1 \(t=0.0 s\) duplicates keyframe 0"):
        read_keyframes(write_json(tmp_path, doc), layout)
    doc = minimal()
    doc["keyframes"] = doc["keyframes"][:1]
    with pytest.raises(InputError, match=r"k\.json: need at least two keyframes"):
        read_keyframes(write_json(tmp_path, doc), layout)
    doc = minimal()
    doc["keyframes"][1]["joints"] = {}
    with pytest.raises(InputError, match=r"k\.json: keyframe 1 \(t=0.5 s\) fixes no component"):
        read_keyframes(write_json(tmp_path, doc), layout)


def test_contacts_round_trip_and_feet_expand(tmp_path, layout, figure):
    from solver.contacts import Contact

    kf = sample_keyframes(layout, np.random.default_rng(1))
    contacts = [Contact("l_toe", 0.0, 0.2, "floor"), Contact("r_heel", 0.3, 0.45)]
    out = tmp_path / "c.keyframes.json"
    write_keyframes(out, kf, layout, contacts=contacts)
    text = out.read_text()
    assert '    {"site": "l_toe", "start": 0.0, "end": 0.2, "surface": "floor"}' in text  # one per line
    _, info = read_keyframes(out, figure)
    assert tuple(info.contacts) == tuple(contacts)
    doc = json.loads(text)
    doc["contacts"].append({"foot": "right", "start": 0.5, "end": 0.6, "surface": "box0"})
    _, info = read_keyframes(write_json(tmp_path, doc), figure)
    assert info.contacts[2:] == (Contact("r_heel", 0.5, 0.6, "box0"), Contact("r_toe", 0.5, 0.6, "box0"))
    _, info = read_keyframes(write_json(tmp_path, minimal(), "none.json"), layout)
    assert not info.contacts and len(info.contacts) == 0
    # times are rounded outward: a contact keeps every frame it held (frame times k * 0.0083333)
    odd = [Contact("r_toe", 3 * 0.0083333, 28 * 0.0083333)]
    write_keyframes(out, kf, layout, contacts=odd)
    back = read_keyframes(out, figure)[1].contacts[0]
    assert back.start <= odd[0].start and back.end >= odd[0].end and back.end - odd[0].end < 1e-6


def test_contacts_name_the_given_figures_feet(tmp_path, layout, figure):
    """With the model, the contacts are checked against that figure's feet (its MJCF annotations): a
    figure whose left toe site is called l_tip accepts it and expands 'left' to it, the shipped figure
    refuses it; with a layout alone no figure is assumed: a 'foot' entry asks for the model."""
    from solver.contacts import Contact

    text = (MODELS / "humanoid39.xml").read_text().replace('"l_toe"', '"l_tip"').replace("l_heel l_toe", "l_heel l_tip")
    model = mujoco.MjModel.from_xml_string(text)
    doc = minimal()
    doc["contacts"] = [{"site": "l_tip", "start": 0, "end": 1}, {"foot": "left", "start": 2, "end": 3}]
    path = write_json(tmp_path, doc)
    _, info = read_keyframes(path, model)
    assert tuple(info.contacts) == (Contact("l_tip", 0, 1), Contact("l_heel", 2, 3), Contact("l_tip", 2, 3))
    with pytest.raises(InputError, match="'site' is 'l_tip'; the figure's contact sites are l_heel, l_toe"):
        read_keyframes(path, figure)
    with pytest.raises(InputError, match=r"contacts\[1\]: 'foot' is 'left', but the contacts were read without the figure"):
        read_keyframes(path, layout)
    doc["contacts"] = doc["contacts"][:1]  # a site alone is read as written, for build_problem to check
    assert tuple(read_keyframes(write_json(tmp_path, doc), layout)[1].contacts) == (Contact("l_tip", 0, 1),)


@pytest.mark.parametrize("contacts, shown", [
    ({"site": "l_toe"}, "list"),
    ([5], "contacts[0] is 5"),
    ([{"site": "nose", "start": 0, "end": 1}], "contacts[0]: 'site' is 'nose'; the figure's contact sites are l_heel"),
    ([{"site": 3, "start": 0, "end": 1}], "contacts[0]: 'site' is 3; give a contact site's name (l_heel"),
    ([{"foot": "l", "start": 0, "end": 1}], "contacts[0]: 'foot' is 'l'; give 'left' or 'right'"),
    ([{"site": "l_toe", "foot": "left", "start": 0, "end": 1}], "exactly one of 'site'"),
    ([{"site": "l_toe", "end": 1}], "contacts[0]: missing field 'start'"),
    ([{"site": "l_toe", "start": "0", "end": 1}], "contacts[0]: 'start' is '0'; give a finite number"),
    ([{"site": "l_toe", "start": 1, "end": 0.5}], "contacts[0]: 'end' 0.5 is not after 'start' 1; swap them"),
    ([{"site": "l_toe", "start": 0, "end": 1, "surface": 3}], "'surface' is 3"),
    ([{"site": "l_toe", "start": 0, "end": 1, "force": 3}], "unknown field(s) 'force'"),
])
def test_contact_errors_name_file_field_value_and_fix(tmp_path, figure, contacts, shown):
    p = write_json(tmp_path, {**minimal(), "contacts": contacts})
    with pytest.raises(InputError) as e:
        read_keyframes(p, figure)
    assert str(e.value).startswith(str(p)) and shown in str(e.value)


def test_a_file_without_format_is_refused_naming_the_field_and_the_value_to_write(tmp_path, layout):
    doc = minimal()
    del doc["format"]
    p = write_json(tmp_path, doc)
    with pytest.raises(InputError) as e:
        read_keyframes(p, layout)
    assert str(e.value) == (f"{p}: missing field 'format'; add \"format\": \"{FORMAT}\" to the top-level object "
                            "(the file format this program reads)")


def test_an_unknown_surface_names_the_file_and_the_contacts_index(tmp_path):
    """With the scene given to the reader, at once; with only the figure's layout, when the contact
    problem is built on its scene: either way one line naming the file and the entry."""
    from runner.paths import MODELS
    from solver.problem import ProblemSpec, build_problem

    scene = mujoco.MjModel.from_xml_path(str(MODELS / "run_and_step.xml"))
    contacts = [{"site": "l_toe", "start": 0.0, "end": 0.2, "surface": "floor"},
                {"site": "r_toe", "start": 0.3, "end": 0.5, "surface": "stpe"}]
    p = write_json(tmp_path, {**minimal(), "contacts": contacts})
    with pytest.raises(InputError) as e:
        read_keyframes(p, scene)
    assert str(e.value).startswith(f"{p}: contacts[1]: 'surface' is 'stpe', which the scene does not have; its "
                                   "surfaces are floor, step")
    kf, info = read_keyframes(p, StateLayout.from_model(scene))  # no scene: read, checked later
    with pytest.raises(InputError, match=rf"^{p}: contacts\[1\]: 'surface' is 'stpe', which the scene"):
        build_problem(scene, ProblemSpec(kf, info.contacts))


def test_every_shipped_keyframe_file_loads(figure):
    from runner.paths import MODELS

    files = sorted(MODELS.glob("*.keyframes.json")) + sorted(Path(__file__).parents[1].rglob("*.keyframes.json"))
    assert files
    for f in files:
        keyframes, info = read_keyframes(f, figure)
        assert keyframes.count >= 2 and json.loads(f.read_text())["format"] == FORMAT


def test_flights_round_trip_rounded_outward_and_absent_is_none(tmp_path, layout):
    kf = sample_keyframes(layout, np.random.default_rng(1))
    out = tmp_path / "f.json"
    write_keyframes(out, kf, layout, flights=[(0.2541666666, 0.2708333333), (0.75, 0.7625)])
    _, info = read_keyframes(out, layout)
    # 6 decimals, start rounded down and end up: the interval read back still holds the one written
    assert info.flights == ((0.254166, 0.270834), (0.75, 0.7625))
    write_keyframes(out, kf, layout, flights=[])
    assert read_keyframes(out, layout)[1].flights == ()  # stated: the motion never flies
    assert read_keyframes(write_json(tmp_path, minimal()), layout)[1].flights is None  # not stated


@pytest.mark.parametrize("flights, shown", [
    ({"a": 1}, "field 'flights' is a dict"),
    ([[0.3, 0.2]], r"flights\[0\] is \[0.3, 0.2\]"),
    ([[0.1, 0.2], [0.3]], r"flights\[1\] is \[0.3\]"),
    ([["0.1", 0.2]], r"flights\[0\]"),
])
def test_flight_errors_name_file_entry_and_value(tmp_path, layout, flights, shown):
    p = write_json(tmp_path, {**minimal(), "flights": flights})
    with pytest.raises(InputError, match=f"k.json: {shown}"):
        read_keyframes(p, layout)
