"""Accuracy on request at the command line (docs/orient.md "At the command line, and on the figure"): `dynsplines orient --tol`, the figure commands'
`--tol` and `dynsplines bench orient --random N`, on tiny problems."""
import json
from pathlib import Path

import numpy as np
import pytest

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
    common = ["animate", clip, "--no-render", "--max-evals", "15", "--save-path", str(out)]
    assert main([*common, "--tol", "0.05"]) == 0
    printed = capsys.readouterr().out
    assert "refinement estimate" in printed and "of E still available (tol 0.05)" in printed  # every round
    assert "tolerance met (refinement estimate" in printed or "tolerance NOT met" in printed
    solve_opts = json.loads(str(np.load(out)["options_json"]))["solve"]
    assert solve_opts["tol"] == 0.05
    # a frame budget that runs out
    assert main([*common, "--tol", "1e-9", "--max-frames", "3"]) == 0
    printed = capsys.readouterr().out
    assert "tolerance NOT met: frame budget of 3 variable frames reached at refinement estimate" in printed
    # --rounds alone: fixed rounds, the estimate still reported
    assert main([*common, "--rounds", "0"]) == 0
    printed = capsys.readouterr().out
    assert "fixed rounds, no tolerance" in printed
    assert json.loads(str(np.load(out)["options_json"]))["solve"]["tol"] == 0.0


def test_figure_tol_needs_adaptive_subdivision(tmp_path, capsys):
    clip = small_clip(tmp_path)
    code = main(["animate", clip, "--no-render", "--quiet", "--tol", "0.01", "--subdivision", "global"])
    assert code == EXIT_INPUT
    assert "--tol 0.01 refines adaptively; it does not go with --subdivision global" in capsys.readouterr().err


def test_figure_rounds_and_tol_are_one_choice(tmp_path, capsys):
    clip = small_clip(tmp_path)
    code = main(["animate", clip, "--no-render", "--quiet", "--rounds", "1", "--tol", "0.01"])
    assert code == EXIT_INPUT
    err = capsys.readouterr().err
    assert "--rounds 1 and --tol 0.01" in err and err.count("\n") == 1  # one line naming both options


def test_orient_rounds_and_tol_are_one_choice(tmp_path, capsys):
    from runner.paths import MODELS

    code = main(["orient", str(MODELS / "orient_example.json"), "--out", str(tmp_path / "o.npz"), "--rounds", "2",
                 "--tol", "1e-4"])
    assert code == EXIT_INPUT
    err = capsys.readouterr().err
    assert "--rounds 2 and --tol 0.0001" in err and err.count("\n") == 1  # one line naming both options
    assert not (tmp_path / "o.npz").exists()


def test_solve_options_map_the_flags_to_the_refinement_mode():
    from runner.animate_options import default_args, solve_options
    from solver.animate import DEFAULT_TOL

    args = default_args("penalty")
    assert (solve_options(args, {}).refine, solve_options(args, {}).tol) == ("tol", DEFAULT_TOL)
    args.rounds = 3
    opts = solve_options(args, {})
    assert (opts.refine, opts.rounds, opts.tol) == ("rounds", 3, 0.0)
    args.rounds, args.tol = None, 1e-3
    assert (solve_options(args, {}).refine, solve_options(args, {}).tol) == ("tol", 1e-3)


def test_bench_orient_random(capsys):
    assert main(["bench", "orient", "--random", "2"]) == 0
    printed = capsys.readouterr().out
    assert "acceptance seeds 1000-1001" in printed and "discrete solver" in printed
    for label in ("default: 2 sets", "tol=1e-4: 2 sets"):
        line = next(ln for ln in printed.splitlines() if label in ln)
        for field in ("true gap", "estimated", "true/est", "frames", "time [ms]", "max|1-|q||"):
            assert field in line, (field, line)


def test_speed_random_rows():
    """`bench orient --speed-random`: one row per generated set; with a tiny budget Barr-92 does not reach
    the gap and the ratio is printed as a lower bound."""
    from runner.bench.orient import SPEED_GAP, speed_random

    lines = []
    rows = speed_random(1, budget=0.2, repeat=1, out=lines.append)
    (row,) = rows
    assert row["seed"] == 1000 and row["tol"][2] <= SPEED_GAP and row["tol"][0] > 0
    assert row["barr"][0] is None and row["r_tol"] == pytest.approx(0.2 / row["tol"][0])
    text = "\n".join(lines)
    assert "Barr-92 / orient(tol=1e-4): median" in text and "lower bounds" in text
