"""`dynsplines clean`'s arguments: --pin takes comma-separated times or a keyframe file, repeated; a bad one is one line; a
clean says where it splits its frame intervals."""
import numpy as np
import pytest

from runner.cli import build_parser


def test_pins_are_comma_separated_and_may_be_repeated():
    args = build_parser().parse_args(["clean", "x.bvh", "--pin", "0.5,1.25", "--pin", "2", "--pin-ends"])
    assert [t for group in args.pin for t in group] == [0.5, 1.25, 2.0]
    assert args.pin_ends and args.func.__module__ == "runner.commands.clean"


def test_a_bad_pin_is_named(capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["clean", "x.bvh", "--pin", "0.5,soon"])
    assert "'0.5,soon' is not a comma-separated list of times in seconds" in capsys.readouterr().err


def test_contacts_name_a_file_the_clean_takes():
    args = build_parser().parse_args(["clean", "x.bvh", "--contacts", "x.contacts.json"])
    assert str(args.contacts) == "x.contacts.json"


def test_the_change_line_names_the_imports_straightened_knee():
    """The clean's change is from the capture as retargeted: where the import straightened a knee or elbow the
    capture bends backwards, the change line says which and by how much (the file carries it too)."""
    from types import SimpleNamespace

    from runner.clean import _import_clamp

    said = _import_clamp(SimpleNamespace(clamped={"l_knee": np.zeros(4), "r_knee": np.array([0.0, 55.25, 3.0, 0.0])}))
    assert "r_knee by up to 55.2 deg" in said or "r_knee by up to 55.3 deg" in said
    assert _import_clamp(SimpleNamespace(clamped={"l_knee": np.zeros(4)})) == ""
    assert _import_clamp(SimpleNamespace(clamped=None)) == ""


def test_a_keyframe_file_pins_its_keyframes_times(tmp_path, capsys):
    """--pin KEYS.json: the times of a keyframe file's keyframes (read here with json, the reference) are the pins,
    beside times given as numbers; a file without keyframe times, or none at all, is one line naming it."""
    import json
    from pathlib import Path

    keys = Path(__file__).resolve().parents[2] / "models" / "run_and_step.keyframes.json"
    args = build_parser().parse_args(["clean", "x.bvh", "--pin", str(keys), "--pin", "3"])
    expected = [float(k["time"]) for k in json.loads(keys.read_text())["keyframes"]]
    assert len(expected) > 2 and [t for group in args.pin for t in group] == expected + [3.0]
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"keyframes": [{"joints": {}}]}))
    for path, said in ((bad, "no keyframe times to pin"), (tmp_path / "none.json", "no such keyframe file")):
        with pytest.raises(SystemExit):
            build_parser().parse_args(["clean", "x.bvh", "--pin", str(path)])
        err = capsys.readouterr().err
        assert f"{path}: {said}" in err and len(err.strip().splitlines()) == 1


def test_a_clean_says_where_its_frame_intervals_are_split(tmp_path, capsys):
    """127_33 at 15 fps (every 8th frame, 1 s): its feet move so far from one frame to the next that the clean splits
    frame intervals into quadrature panels (`solver.displacement.frame_panels`), says how many, and records them; at
    its own 120 fps (0.25 s) nothing is split and nothing is said."""
    import json
    from pathlib import Path

    from bvh_edit import edit_bvh

    from runner.cli import main

    clip = Path(__file__).resolve().parents[2] / "models" / "cmu" / "127_33.bvh"
    for name, kw in (("slow", {"seconds": 1.0, "stride": 8}), ("full", {"seconds": 0.25})):
        src = edit_bvh(clip, tmp_path / f"{name}.bvh", **kw)
        main(["clean", str(src), "--no-render", "--no-summary", "--out-dir", str(tmp_path / name)])
        said = capsys.readouterr().out
        split = json.loads((tmp_path / name / f"{name}.clean.metrics.json").read_text())["split_intervals"]
        if name == "slow":
            assert split > 0 and f"{split} of the capture's 15 frame intervals split into up to" in said
        else:
            assert split == 0 and "quadrature panels" not in said
