"""`--plot`: the foot-height figure's title describes the scene it was drawn for (a flat floor, or a
floor with boxes), not always the run-and-step scene's step."""
import mujoco
import numpy as np
import pytest

import runner.plots as plots
from runner.paths import MODELS
from solver.surfaces import StaticSurfaces

BOXES = """
<mujoco>
  <worldbody>
    <geom name="floor" type="plane" size="0 0 .1"/>
    <geom name="crate" type="box" pos="1 0 .2" size=".3 .3 .2"/>
    <geom name="ledge" type="box" pos="3 0 .1" size=".3 .3 .1"/>
  </worldbody>
</mujoco>
"""


def test_a_flat_scene_speaks_of_the_floor_only():
    surfaces = StaticSurfaces.from_model(mujoco.MjModel.from_xml_path(str(MODELS / "floor.xml")))
    title = plots.foot_height_title(surfaces)
    assert "floor" in title
    assert not any(word in title for word in ("step", "box", "edge"))


@pytest.mark.parametrize("xml, names", [(None, ["step"]), (BOXES, ["crate", "ledge"])])
def test_a_scene_with_boxes_names_them(xml, names):
    model = (mujoco.MjModel.from_xml_path(str(MODELS / "run_and_step.xml")) if xml is None
             else mujoco.MjModel.from_xml_string(xml))
    title = plots.foot_height_title(StaticSurfaces.from_model(model))
    assert all(name in title for name in names) and "floor" in title and "edge" in title


def test_the_figure_carries_the_scene_title(monkeypatch, tmp_path):
    model = mujoco.MjModel.from_xml_path(str(MODELS / "floor.xml"))
    seen = {}
    monkeypatch.setattr(plots, "_savefig", lambda fig, path: seen.setdefault("title", fig.axes[0].get_title()))
    q = np.tile(model.qpos0, (2, 1))
    q[:, 2] = 1.0
    plots.plot_foot_heights(tmp_path / "f.png", model, {"optimized": (np.array([0.0, 1.0]), q, "samples")},
                            [0.0, 1.0])
    assert seen["title"] == plots.foot_height_title(StaticSurfaces.from_model(model))
    assert "step" not in seen["title"]
