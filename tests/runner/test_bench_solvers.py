"""`dynsplines bench solvers`: where it finds its inputs and how it judges a metric (the solves
themselves are the benchmark's, not a test's)."""
from pathlib import Path

from runner.commands.bench_solvers import find_inputs, within
from runner.paths import MODELS
from runner.problem_file import RUN_AND_STEP_KEYFRAMES


def test_inputs_come_from_the_models_then_the_clips_folder(tmp_path):
    (tmp_path / "12_34.bvh").write_text("HIERARCHY\n")  # a clip that models/cmu does not ship
    (tmp_path / "127_33.bvh").write_text("HIERARCHY\n")  # a shipped one: the shipped copy comes first
    found, missing = find_inputs(["run-and-step", "127_33", "12_34", "99_99"], tmp_path)
    assert found == [("run-and-step", RUN_AND_STEP_KEYFRAMES), ("127_33", MODELS / "cmu" / "127_33.bvh"),
                     ("12_34", tmp_path / "12_34.bvh")]
    assert missing == ["99_99"]
    assert find_inputs([str(tmp_path / "12_34.bvh")], None)[0] == [("12_34", Path(tmp_path / "12_34.bvh"))]


def test_a_metric_passes_within_2_percent_or_the_absolute_tolerance_or_better():
    assert within(1.01, 1.0, 0.0) and not within(1.03, 1.0, 0.0)  # 2 %
    assert within(0.15, 0.0, 0.2) and not within(0.25, 0.0, 0.2)  # 0.2 mm of a zero reference
    assert within(0.5, 1.0, 0.0)  # lower is better
    assert within(0.30, 0.25, 0.0, higher_is_better=True) and not within(0.20, 0.25, 0.0, higher_is_better=True)
