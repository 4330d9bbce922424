"""The shipped models from any folder: `solver.shipped(name)`, and the hint of the file readers when a
relative path such as the checkout's "models/run_and_step.xml" is not found from the current folder."""
import json
from pathlib import Path

import pytest

import solver
from solver.errors import InputError

MODELS = Path(__file__).resolve().parents[2] / "models"  # the checkout's models/, which solver/models links


@pytest.fixture
def elsewhere(tmp_path, monkeypatch):
    """A current folder that is not the checkout."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_shipped_files_are_the_checkouts_models_from_any_folder(elsewhere):
    for name in ("run_and_step.xml", "run_and_step.keyframes.json", "cmu/127_33.bvh", "humanoid39.xml"):
        path = solver.shipped(name)
        assert path.is_absolute() and path.read_bytes() == (MODELS / name).read_bytes()
        assert solver.shipped(f"models/{name}") == path  # the checkout's spelling too
    model = solver.load_model(solver.shipped("run_and_step.xml"))
    keyframes, info = solver.read_keyframes(solver.shipped("run_and_step.keyframes.json"), model)
    doc = json.loads((MODELS / "run_and_step.keyframes.json").read_text())
    assert len(keyframes.times) == len(doc["keyframes"]) and model.nq == 51


def test_an_unknown_shipped_name_lists_the_shipped_files(elsewhere):
    with pytest.raises(InputError, match=r"shipped\('run_and_stp.xml'\): no such shipped file .*run_and_step\.xml"):
        solver.shipped("run_and_stp.xml")
    with pytest.raises(InputError, match="not an absolute path"):
        solver.shipped(str(MODELS / "floor.xml"))


def test_a_checkout_path_from_elsewhere_says_where_the_shipped_file_is(elsewhere):
    """The README's old spelling from another folder: the one-line error names the folder it looked in,
    the shipped file's real path and `solver.shipped`."""
    with pytest.raises(InputError) as e:
        solver.load_model("models/run_and_step.xml")
    msg = str(e.value)
    assert "models/run_and_step.xml does not exist" in msg and str(elsewhere) in msg
    assert str(solver.shipped("run_and_step.xml")) in msg and "solver.shipped('run_and_step.xml')" in msg
    assert "\n" not in msg
    model = solver.load_model(solver.shipped("run_and_step.xml"))
    with pytest.raises(InputError) as e:
        solver.read_keyframes("models/run_and_step.keyframes.json", model)
    msg = str(e.value)
    assert "no such keyframe file" in msg and "solver.shipped('run_and_step.keyframes.json')" in msg


def test_no_hint_for_a_file_that_is_not_shipped(elsewhere):
    with pytest.raises(InputError) as e:
        solver.load_model("models/mine.xml")
    assert "shipped" not in str(e.value)
    with pytest.raises(InputError, match=r"mine\.json: no such keyframe file \(current folder: "):
        solver.read_keyframes("mine.json", solver.load_model(solver.shipped("run_and_step.xml")))
