"""`dynsplines export`: formats by extension, --which, one-line errors, atomic output."""
import argparse

import pytest

from runner.capture.bvh import read_bvh
from runner.commands import export
from runner.export import export_saved_path
from solver.errors import InputError


def parse(argv):
    p = argparse.ArgumentParser(prog="dynsplines")
    export.register(p.add_subparsers())
    return p.parse_args(["export", *map(str, argv)])


def test_bvh_and_glb_are_written(tmp_path, saved_npz, capsys):
    for name in ("a.bvh", "a.glb"):
        args = parse([saved_npz, "--to", tmp_path / name, "--which", "plain", "--fps", "24"])
        assert export.run(args) == 0
    assert "24 fps" in capsys.readouterr().out
    assert (tmp_path / "a.glb").read_bytes()[:4] == b"glTF"
    clip = read_bvh(tmp_path / "a.bvh")
    assert clip.frame_time == pytest.approx(1 / 24) and len(clip.local_quat) == 25  # 1 s at 24 fps


def test_default_fps_is_the_reference_rate(tmp_path, saved_npz):
    res = export_saved_path(saved_npz, tmp_path / "r.bvh", "reference")
    assert res.fps == pytest.approx(120.0) and res.frames == 121 and res.joints == 14  # 12 bodies, the fixed neck and head


@pytest.mark.parametrize("to, match", [("x.fbx", r"--to .*x\.fbx: extension '\.fbx'.*\.bvh, \.glb"),
                                       ("x", "no extension")])
def test_unknown_extension_is_one_clear_line(tmp_path, saved_npz, to, match):
    with pytest.raises(InputError, match=match) as e:
        export_saved_path(saved_npz, tmp_path / to)
    assert "\n" not in str(e.value)


def test_bad_inputs_name_the_file_and_the_fix(tmp_path, saved_npz):
    with pytest.raises(InputError, match="missing.npz: cannot read the saved path: no such file"):
        export_saved_path(tmp_path / "missing.npz", tmp_path / "x.glb")
    not_npz = tmp_path / "scene.npz"
    not_npz.write_text("<mujoco/>")
    with pytest.raises(InputError, match="not an .npz file"):
        export_saved_path(not_npz, tmp_path / "x.glb")
    with pytest.raises(InputError, match="--which 'sideways'"):
        export_saved_path(saved_npz, tmp_path / "x.glb", which="sideways")


def test_failed_export_leaves_an_earlier_file_unchanged(tmp_path, saved_npz, monkeypatch):
    out = tmp_path / "keep.glb"
    out.write_bytes(b"earlier")

    def boom(self, data):  # half a file, then Ctrl-C
        with open(self, "wb") as fh:
            fh.write(data[:10])
        raise KeyboardInterrupt

    monkeypatch.setattr("pathlib.Path.write_bytes", boom)
    with pytest.raises(KeyboardInterrupt):
        export_saved_path(saved_npz, out)
    monkeypatch.undo()
    assert out.read_bytes() == b"earlier"
    assert [p.name for p in tmp_path.iterdir()] == ["keep.glb"]
