"""The term registry: a term in a module of its own (toy_term.py) plus one registration line is usable
from `solver.animate(..., terms=...)` and from the command line's `--terms`."""
import importlib.util
import json
from pathlib import Path

import mujoco
import numpy as np
import pytest

import solver
from solver.errors import InputError
from solver.problem import DEFAULT_TERMS, parse_terms, term_names
from solver.terms.registry import register_term, registered_terms, unregister_term

from conftest import TOY_SCENE

MODELS = Path(__file__).resolve().parents[3] / "models"
_spec = importlib.util.spec_from_file_location("toy_term", Path(__file__).with_name("toy_term.py"))
toy_term_module = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(toy_term_module)  # the toy term's own module (tests/ folders are not packages)
RootHeight = toy_term_module.RootHeight
TARGET = 0.6  # [m] the toy term's root height


@pytest.fixture()
def toy_term():
    register_term("toy", lambda build: RootHeight(TARGET), default_weight=1.0)  # the one registration line
    yield
    unregister_term("toy")


def _keyframes(layout, nq):
    """Three keyframes of the standing figure 1 m up; the middle one leaves the root height free."""
    V = np.zeros((3, nq))
    V[:, 2] = 1.0
    V[:, layout.quat_slots[:, 0]] = 1.0
    mask = np.ones_like(V, bool)
    mask[1, 2] = False
    V[1, 2] = np.nan
    return solver.Keyframes(np.array([0.0, 0.5, 1.0]), V, mask)


def test_a_registered_term_is_listed_and_parsed_but_not_on_by_default(toy_term):
    assert term_names()[-1] == "toy" and term_names()[:-1] == [s.name for s in registered_terms()][:-1]
    assert tuple(parse_terms(None)) == DEFAULT_TERMS
    assert parse_terms("toy,smooth") == {"toy": 1.0, "smooth": 0.05}
    assert "toy" in parse_terms("all")


def test_a_registered_term_acts_in_solver_animate(toy_term):
    """With the toy term the free root height between the keyframes goes down toward 0.6 m (by more
    than 0.1 m); without it the smoothest path keeps it at 1 m (to 1e-6 m)."""
    model = mujoco.MjModel.from_xml_string(TOY_SCENE)
    kf = _keyframes(solver.StateLayout.from_model(model), model.nq)
    plain = solver.animate(model, kf, terms="smooth")
    toy = solver.animate(model, kf, terms="toy,smooth")
    t = np.array([0.5])
    assert abs(plain.frames.path(t)[0, 2] - 1.0) < 1e-6
    assert toy.frames.path(t)[0, 2] < 0.9
    assert toy.weights["toy"] == 1.0 and toy.integrals_final["toy"] < toy.integrals_initial["toy"]


def test_a_registered_term_acts_from_the_command_line(toy_term, tmp_path, capsys):
    """`dynsplines animate ... --terms toy,smooth` (in process): the saved path's root height at the
    middle keyframe is below 0.9 m; with --terms smooth it stays at 1 m; --help lists the term."""
    from runner.cli import main

    doc = {"format": "dynsplines.keyframes/1", "keyframes": [{"time": 0.0, "joints": {"root": [0, 0, 1.0, 1, 0, 0, 0]}},
                         {"time": 0.5, "joints": {"root": [0, 0, None, 1, 0, 0, 0]}},
                         {"time": 1.0, "joints": {"root": [0, 0, 1.0, 1, 0, 0, 0]}}]}
    path = tmp_path / "k.json"
    path.write_text(json.dumps(doc))
    mid = {}
    for terms in ("smooth", "toy,smooth"):
        out = tmp_path / f"{terms}.npz"
        code = main(["animate", str(path), "--scene", str(MODELS / "floor.xml"), "--no-render", "--quiet",
                     "--terms", terms, "--save-path", str(out)])
        assert code == 0, capsys.readouterr().err
        z = np.load(out)
        mid[terms] = float(z["frames"][np.argmin(np.abs(z["frame_times"] - 0.5)), 2])
    assert abs(mid["smooth"] - 1.0) < 1e-6 and mid["toy,smooth"] < 0.9
    assert "integral toy" in capsys.readouterr().out
    assert main(["animate", "--help"]) == 0
    help_terms = capsys.readouterr().out.split("  --terms", 1)[1].split("\n  --", 1)[0]
    assert "cone,toy" in "".join(help_terms.split())  # --terms' help lists the registered names


def test_bad_registrations_are_input_errors(toy_term):
    with pytest.raises(InputError, match="already registered"):
        register_term("toy", lambda b: RootHeight(0.0))
    with pytest.raises(InputError, match="without commas or spaces"):
        register_term("a,b", lambda b: RootHeight(0.0))
    with pytest.raises(InputError, match="must be finite and >= 0"):
        register_term("toy2", lambda b: RootHeight(0.0), default_weight=-1.0)
    register_term("toy", lambda b: solver.terms.UnitQuaternion(b.layout.quat_slots), replace=True)
    model = mujoco.MjModel.from_xml_string(TOY_SCENE)
    with pytest.raises(InputError, match="must return a Term whose name is 'toy'"):
        solver.figure_objective(model, {"toy": 1.0}, 0.0, 1.0)
