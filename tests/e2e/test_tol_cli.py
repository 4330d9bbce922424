"""Accuracy on request at the command line (docs/orient.md "At the command line, and on the figure"): `dynsplines orient --tol`, the figure commands'
`--tol` and `dynsplines bench orient --random N`, on tiny problems."""
import json
import re
from pathlib import Path

import numpy as np

from runner.cli import main
from runner.exit_codes import EXIT_INPUT

REPO = Path(__file__).resolve().parents[2]
MODELS = REPO / "models"

ORIENT_KEYS = {"times": [0.0, 0.6, 1.5, 2.0],
               "quaternions": [[1, 0, 0, 0], [0.7, 0.7, 0, 0], [0.5, 0.5, 0.5, 0.5], [0, 0, 1, 0]]}


def orient_file(tmp_path):
    p = tmp_path / "k.json"
    p.write_text(json.dumps(ORIENT_KEYS))
    return str(p)


def test_orient_tol(tmp_path, capsys):
    kf, out = orient_file(tmp_path), tmp_path / "p.npz"
    assert main(["orient", kf, "--out", str(out), "--tol", "1e-4"]) == 0
    printed = capsys.readouterr().out
    assert "estimated gap" in printed and "tolerance 0.0001 met" in printed
    z = np.load(out)
    assert z["tol"] == 1e-4 and z["converged_to_tol"] == 1 and 0 < z["estimated_gap"] <= 1e-4
    assert "estimated gap" in str(z["message"])
    # the default tolerance, and fixed rounds
    assert main(["orient", kf, "--out", str(out)]) == 0
    assert "tolerance 0.001 met" in capsys.readouterr().out
    assert main(["orient", kf, "--out", str(out), "--rounds", "1"]) == 0
    assert "fixed rounds, no tolerance" in capsys.readouterr().out
    z = np.load(out)
    assert z["tol"] == 0 and z["converged_to_tol"] == -1 and z["estimated_gap"] > 0
    # a budget that runs out: said, with the estimate reached
    assert main(["orient", kf, "--out", str(out), "--tol", "1e-9", "--max-frames", "4"]) == 0
    printed = capsys.readouterr().out
    assert "tolerance 1e-09 NOT met: frame budget of 4 variable frames reached at estimated gap" in printed
    assert np.load(out)["converged_to_tol"] == 0


def test_orient_tol_errors(tmp_path, capsys):
    kf, out = orient_file(tmp_path), str(tmp_path / "p.npz")
    assert main(["orient", kf, "--out", out, "--tol", "1e-4", "--form", "paper"]) == EXIT_INPUT
    assert "only the normalized form has" in capsys.readouterr().err
    for bad in ("0", "-1", "nan", "x"):
        try:
            code = main(["orient", kf, "--out", out, "--tol", bad])
        except SystemExit as e:
            code = e.code
        assert code != 0, bad
        assert "--tol" in capsys.readouterr().err


def small_clip(tmp_path, n=3):
    """The first n keyframes of the shipped clip."""
    doc = json.loads((MODELS / "run_and_step.keyframes.json").read_text())
    doc["keyframes"] = doc["keyframes"][:n]
    doc["scene"] = str(MODELS / "run_and_step.xml")
    doc["model"] = str(MODELS / "humanoid39.xml")
    doc["source"] = {}
    p = tmp_path / "clip.json"
    p.write_text(json.dumps(doc))
    return str(p)


def test_figure_tol(tmp_path, capsys):
    clip, out = small_clip(tmp_path), tmp_path / "path.npz"
    common = ["animate", clip, "--no-render", "--tol", "0.05", "--save-path", str(out)]
    assert main(common) == 0
    assert "refinement estimate" in capsys.readouterr().out
    needs = len(np.load(out)["objective_trace"])  # (evaluations,), docs/saved-path.md
    # half of what the clip takes ends the solve, and the summary says so
    assert main([*common, "--max-evals", str(needs // 2)]) == 0
    text = capsys.readouterr().out
    assert f"stopped: evaluation budget of {needs // 2} spent" in text
    assert "refinement converged" not in text
    flat = re.sub(r"\n\s+", " ", text)  # the verdict wraps onto indented lines
    assert re.search(r"verdict: .*(refinement not converged|no refinement estimate)", flat), text
    solve_opts = json.loads(str(np.load(out)["options_json"]))["solve"]
    assert solve_opts["tol"] == 0.05 and solve_opts["max_evals"] == needs // 2


def test_orient_rounds_and_tol_are_one_choice(tmp_path, capsys):
    from runner.paths import MODELS

    code = main(["orient", str(MODELS / "orient_example.json"), "--out", str(tmp_path / "o.npz"), "--rounds", "2",
                 "--tol", "1e-4"])
    assert code == EXIT_INPUT
    err = capsys.readouterr().err
    assert "--rounds 2 and --tol 0.0001" in err and err.count("\n") == 1  # one line naming both options
    assert not (tmp_path / "o.npz").exists()


def test_solve_options_map_the_flags_to_the_least_change_options():
    from runner.animate_options import default_args, solve_options
    from solver.least_change import LeastChangeOptions

    args = default_args()
    assert solve_options(args) == LeastChangeOptions()
    args.tol, args.max_time, args.max_evals, args.rate = 1e-3, 30.0, 50, 300.0
    assert solve_options(args) == LeastChangeOptions(tol=1e-3, max_time_s=30.0, max_evals=50, rate=300.0)
