"""A figure whose contact sites have other names is another MJCF and nothing else: contact detection, the
problem, the solve and the motion metrics read the sites and feet from the figure's own annotations
(`figure:foot:SIDE`), never from the shipped figure's names. Checked against the shipped figure itself: the
same motion and keyframes on the renamed copy give the same contacts, path and figures, name for name."""
import numpy as np
import pytest

import solver
from runner.capture.contact_detection import reference_contacts
from runner.motion_metrics import motion_metrics
from runner.paths import MODELS
from solver.contacts import Contact

RENAMED = {"l_heel": "LeftHeel", "l_toe": "LeftToeBase", "r_heel": "RightHeel", "r_toe": "RightToeBase"}
FPS = 100.0


def _renamed_scene(tmp_path):
    """models/floor.xml on a copy of the shipped figure whose four contact sites are renamed (`RENAMED`)."""
    text = (MODELS / "humanoid39.xml").read_text()
    for old, new in RENAMED.items():
        text = text.replace(f'name="{old}"', f'name="{new}"')
    for side, (heel, toe) in (("left", ("l_heel", "l_toe")), ("right", ("r_heel", "r_toe"))):
        text = text.replace(f'name="figure:foot:{side}" data="{heel} {toe}"',
                            f'name="figure:foot:{side}" data="{RENAMED[heel]} {RENAMED[toe]}"')
    (tmp_path / "renamed.xml").write_text(text)
    scene = (MODELS / "floor.xml").read_text().replace('<include file="humanoid39.xml"/>',
                                                      '<include file="renamed.xml"/>')
    (tmp_path / "scene.xml").write_text(scene)
    return solver.load_model(tmp_path / "scene.xml")


def _sway(model):
    """(n, nq) 0.8 s of the figure standing at its rest pose (feet on the floor) while its root rises 2 cm
    and comes back down: the feet leave the floor in the middle."""
    t = np.arange(0.0, 0.8 + 1e-9, 1 / FPS)
    q = np.tile(model.qpos0, (len(t), 1))
    q[:, 2] += 0.02 * np.sin(np.pi * t / 0.8) ** 2
    return t, q


def test_renamed_contact_sites_give_the_shipped_figures_results(tmp_path):
    shipped = solver.load_model(MODELS / "floor.xml")
    renamed = _renamed_scene(tmp_path)
    assert solver.Figure.from_model(renamed).contact_sites == tuple(RENAMED.values())
    t, q = _sway(shipped)
    found = {name: reference_contacts(model, q, 1 / FPS) for name, model in (("shipped", shipped), ("renamed", renamed))}
    assert found["shipped"], "the standing feet are in contact"
    assert [Contact(RENAMED[c.site], c.start, c.end, c.surface) for c in found["shipped"]] == found["renamed"]
    keys = [0, 40, 80]
    keyframes = solver.Keyframes(t[keys], q[keys], np.ones((3, shipped.nq), bool), source="sway")
    results = {}
    for name, model in (("shipped", shipped), ("renamed", renamed)):
        problem = solver.build_problem(model, solver.ProblemSpec(keyframes, contacts=tuple(found[name])))
        assert problem.contacts.sites == solver.Figure.from_model(model).contact_sites
        sol = solver.solve_problem(problem, solver.LeastChangeOptions())
        assert sol.E_final > 0  # the contact constraints on the figure's own sites moved the path
        path = sol.frames.path(t)
        np.testing.assert_allclose(sol.frames.path(t[keys]), q[keys], atol=1e-9)  # keyframes met exactly
        results[name] = path, motion_metrics(model, path, FPS, q, found[name])
    np.testing.assert_allclose(results["renamed"][0], results["shipped"][0], atol=1e-9)
    a, b = results["shipped"][1], results["renamed"][1]
    assert b["sites"] == list(RENAMED.values()) and a["sites"] == list(RENAMED)
    for key in ("float_contact_mm", "skate_contact_mm", "flight_time_s"):
        assert b["path"][key] == pytest.approx(a["path"][key], abs=1e-9), key
