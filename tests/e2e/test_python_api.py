"""The README's Python API snippet, run exactly as written from a folder other than the checkout, gives the
command line's path bit for bit (after `runner.environment.apply_defaults()`, which the snippet calls first
and says why), for the same problem: the keyframe file without its motion-capture "source" (the solver
library does not import BVH clips; with one, the command line also bounds the accelerations by the
capture's filtered peaks)."""
import json
import re
from pathlib import Path

import numpy as np

from runner.cli import main

REPO = Path(__file__).resolve().parents[2]


def readme_snippet() -> str:
    text = (REPO / "README.md").read_text()
    section = text[text.index("the Python API\n"):]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def test_readme_snippet_is_one_import_and_one_call():
    code = readme_snippet()
    imports = [line for line in code.splitlines() if line.startswith(("import ", "from "))]
    assert imports == ["from runner.environment import apply_defaults", "import solver"]
    assert code.index("apply_defaults()") < code.index("import solver")  # before numpy is imported
    assert "bit for bit" in code  # the snippet says when it agrees with the command
    assert code.count("solver.solve_problem(") == 1 and "solver.LeastChangeOptions()" in code


def test_readme_snippet_gives_the_command_lines_frames(tmp_path, monkeypatch):
    import solver

    data = json.loads(solver.shipped("run_and_step.keyframes.json").read_text())
    data.pop("source", None)
    data["scene"] = str(solver.shipped("run_and_step.xml"))
    if "model" in data:
        data["model"] = str(solver.shipped(data["model"]))
    keys = tmp_path / "no_source.keyframes.json"
    keys.write_text(json.dumps(data))
    out = tmp_path / "cli.npz"
    assert main(["animate", str(keys), "--no-render", "--quiet", "--save-path", str(out)]) == 0
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)  # not the checkout: the snippet's shipped files are found from any folder
    scope: dict = {}
    exec(compile(readme_snippet(), "README.md", "exec"), scope)
    solution = scope["solution"]
    with np.load(out) as z:
        assert np.array_equal(solution.frames.times, z["frame_times"])
        assert np.array_equal(solution.frames.values, z["frames"])  # identical, not merely close
        assert scope["qpos"].shape == (len(z["frame_times"]), 51)
