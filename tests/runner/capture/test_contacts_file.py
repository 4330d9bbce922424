"""The contacts file a clean writes and `--contacts` reads back: the schedule round-trips, a foot becomes its
sites, a surface may be left to the scene, and a bad file is one line naming it and the entry."""
import json

import pytest

import solver
from runner.capture.contacts_file import FORMAT, read_contacts_file, write_contacts_file
from solver.contacts import Contact
from solver.errors import InputError


@pytest.fixture(scope="module")
def model():
    return solver.load_model(solver.shipped("floor.xml"))


def test_a_written_schedule_reads_back(model, tmp_path):
    # the toe's contact runs into the flight, as a site staying within 5 cm while all are 3 cm up does
    contacts = [Contact("l_heel", 0.0, 0.5, "floor"), Contact("l_toe", 0.1, 0.65, "floor"), Contact("r_toe", 0.7, 1.25, "floor")]
    path = tmp_path / "c.contacts.json"
    write_contacts_file(path, contacts, [(0.6, 0.7)], "clip.bvh")
    doc = json.loads(path.read_text())
    assert doc["format"] == FORMAT and doc["source"] == {"clip": "clip.bvh"}
    back, flights = read_contacts_file(path, model, 2.0, ())
    assert set(back) == set(contacts) and flights == ((0.6, 0.7),)


def test_an_edited_file_may_name_a_foot_and_leave_out_the_surface_and_flights(model, tmp_path):
    path = tmp_path / "edited.json"
    path.write_text(json.dumps({"contacts": [{"foot": "left", "start": 0.0, "end": 0.4},
                                             {"site": "r_toe", "start": 0.2, "end": 0.9, "surface": "floor"}]}))
    back, flights = read_contacts_file(path, model, 1.0, ((0.95, 1.0),))
    assert set(back) == {Contact("l_heel", 0.0, 0.4, ""), Contact("l_toe", 0.0, 0.4, ""),
                         Contact("r_toe", 0.2, 0.9, "floor")}
    assert flights == ((0.95, 1.0),)  # the capture's own
    path.write_text(json.dumps({"contacts": [{"site": "r_toe", "start": 0.5, "end": 0.9}]}))
    with pytest.raises(InputError, match=r"contacts\[0\] \(r_toe, 0\.5-0\.9 s\) starts in the capture's flight\[0\]"):
        read_contacts_file(path, model, 1.0, ((0.4, 0.6),))


@pytest.mark.parametrize("doc, message", [
    ({"keyframes": []}, r"no \"contacts\" list; give the <stem>\.contacts\.json a clean wrote"),
    ({"contacts": [{"site": "l_knee", "start": 0.0, "end": 0.4}]}, r"contacts\[0\]: 'site' is 'l_knee'"),
    ({"contacts": [{"site": "l_toe", "start": 0.0, "end": 0.4, "surface": "step"}]}, r"step"),
    ({"contacts": [{"site": "l_toe", "start": 3.0, "end": 3.4}]}, r"contacts\[0\] starts at 3 s, after the clip's last frame"),
    ({"contacts": [{"site": "l_toe", "start": 0.0, "end": 0.4}, {"site": "r_toe", "start": 0.5, "end": 0.7}],
      "flights": [[0.4, 0.6]]}, r"contacts\[1\] \(r_toe, 0\.5-0\.7 s\) starts in flights\[0\] \(0\.4-0\.6 s\)"),
])
def test_a_bad_file_is_named_with_its_entry(model, tmp_path, doc, message):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError, match=message) as e:
        read_contacts_file(path, model, 1.0, ())
    assert str(path) in str(e.value) and "\n" not in str(e.value)


def test_a_missing_file_is_named(model, tmp_path):
    with pytest.raises(InputError, match=r"nothere\.json: no such contacts file"):
        read_contacts_file(tmp_path / "nothere.json", model, 1.0, ())
