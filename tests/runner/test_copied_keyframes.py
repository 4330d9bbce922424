"""A keyframe file copied to another folder: its paths are read relative to the file, and what is not
there is said, with the fix - the scene as a one-line error (as the figure, "model", already is), the
clip (whose capture gives the comparison and the no-jolt and effort bounds) as a warning."""
import shutil

from runner.cli import main
from runner.exit_codes import EXIT_INPUT
from runner.paths import MODELS

FAST = ["--no-render", "--max-evals", "5", "--quiet", "--no-summary"]


def test_a_copied_file_without_its_scene_is_one_line(tmp_path, capsys):
    shutil.copy(MODELS / "run_and_step.keyframes.json", tmp_path)
    assert main(["animate", str(tmp_path / "run_and_step.keyframes.json"), *FAST]) == EXIT_INPUT
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "field 'scene' 'run_and_step.xml' is read relative to the keyframe file's folder" in err, err
    assert str(tmp_path) in err and "or give --scene SCENE.xml" in err, err


def test_a_copied_file_without_its_clip_warns(tmp_path, capsys):
    for name in ("run_and_step.keyframes.json", "run_and_step.xml", "humanoid39.xml"):
        shutil.copy(MODELS / name, tmp_path)
    assert main(["animate", str(tmp_path / "run_and_step.keyframes.json"), "--save-path", str(tmp_path / "p.npz"),
                 *FAST]) == 0
    err = capsys.readouterr().err
    assert f"source.clip 'cmu/127_33.bvh' is read relative to the keyframe file, and {tmp_path}" in err, err
    assert "no no-jolt or effort bounds" in err and "copy the clip there or correct source.clip" in err, err
