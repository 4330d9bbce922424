"""What `animate` / `run-and-step` write and say: --export, --quiet (progress only), the default video,
progress lines off a terminal. The optimization is cut short (--rounds 0 --max-evals 3) and the renderer
is replaced where a video would be made, to keep these fast."""
import pytest

from runner.cli import main
from runner.exit_codes import EXIT_INPUT
from runner.mocap.bvh import read_bvh
from runner.problem_file import RUN_AND_STEP_KEYFRAMES

FAST = ["--rounds", "0", "--max-evals", "3", "--subdivision", "none"]


def animate(capsys, *argv):
    code = main(["animate", str(RUN_AND_STEP_KEYFRAMES), *FAST, *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def test_export_writes_each_file_after_the_path(tmp_path, capsys):
    code, out, err = animate(capsys, "--no-render", "--export", tmp_path / "a.bvh", "--export", tmp_path / "a.glb")
    assert code == 0, err
    assert (tmp_path / "a.glb").read_bytes()[:4] == b"glTF"
    clip = read_bvh(tmp_path / "a.bvh")
    assert len(clip.names) == 12 and clip.frame_time == pytest.approx(1 / 120, rel=1e-4)
    assert f"wrote {tmp_path / 'a.bvh'} (BVH, optimized:" in out and f"wrote {tmp_path / 'a.glb'} (glTF" in out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.bvh", "a.glb"]  # no temporary path left


@pytest.mark.parametrize("name, fragment", [("a.fbx", "--export"), ("a", "no extension")])
def test_bad_export_name_fails_before_optimizing(tmp_path, capsys, name, fragment):
    code, out, err = animate(capsys, "--no-render", "--export", tmp_path / name)
    assert code == EXIT_INPUT and fragment in err and name in err
    assert "round" not in out and "stopped" not in out
