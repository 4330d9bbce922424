"""Gaps in a capture ("nan" in a frame line): filled from the joint's frames on either side (the slerp between
its orientations, a straight line between its positions), named; an infinite value or a joint with no number
at all is one line naming the file."""
import json
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from runner.capture.bvh import read_bvh, rest_places
from runner.capture.gaps import EVERY_JOINT, ROOT_SPEED_MAX, corrupt_frames, fill_gaps, gaps_line, rest_size
from solver.errors import InputError
from tests.runner.capture.test_bvh_import import TINY_JOINTS, tiny_bvh, tiny_frame

CLIP = Path(__file__).resolve().parents[3] / "models" / "cmu" / "127_33.bvh"


def _about_z(deg):
    """(k, 4) unit quaternions (w x y z) about z by each of `deg` degrees."""
    a = np.radians(np.asarray(deg, float)) / 2
    return np.stack([np.cos(a), 0 * a, 0 * a, np.sin(a)], axis=1)


def test_a_gap_is_the_slerp_and_the_line_between_its_neighbours():
    """A joint turning about z by 0, 20, ?, ?, 80 degrees fills at 40 and 60 (the slerp's constant rate); its
    position along x 0, 1, ?, ?, 4 at 2 and 3; gaps at the ends hold the nearest frame; the other joint is kept."""
    n, nan = 6, np.nan
    quat = np.stack([_about_z([0, 20, 0, 0, 80, 90]), _about_z([5, 5, 5, 5, 5, 5])], axis=1)  # (6, 2, 4)
    pos = np.zeros((n, 2, 3))
    pos[:, 0, 0] = [0, 1, nan, nan, 4, 5]
    quat[2:4, 0] = nan
    quat[0, 1, 1] = nan  # the second joint: its first frame only
    quat[5, 1] = nan  # and its last
    q, p, gaps = fill_gaps(quat, pos, ("a", "b"), 0.1, "x.bvh")
    assert np.isfinite(q).all() and np.isfinite(p).all()
    angle = np.degrees(2 * np.arctan2(q[:, 0, 3], q[:, 0, 0]))
    assert angle == pytest.approx([0, 20, 40, 60, 80, 90], abs=1e-9)
    assert p[:, 0, 0] == pytest.approx([0, 1, 2, 3, 4, 5], abs=1e-12)
    assert q[0, 1] == pytest.approx(quat[1, 1], abs=1e-12) and q[5, 1] == pytest.approx(quat[4, 1], abs=1e-12)
    assert [(g.joint, g.first, g.last) for g in gaps] == [("a", 3, 4), ("b", 1, 1), ("b", 6, 6)]
    line = gaps_line(gaps)
    assert "a frames 3-4 (0.200 s)" in line and "b 2 frames in 2 gaps, the longest frame 1 (0.100 s)" in line
    assert gaps_line(()) is None


def test_a_joint_without_a_number_in_any_frame_is_named():
    quat = np.full((3, 1, 4), np.nan)
    with pytest.raises(InputError, match=r"^x\.bvh: joint spine has no number in any frame"):
        fill_gaps(quat, np.zeros((3, 1, 3)), ("spine",), 0.1, "x.bvh")


def test_a_file_with_nan_reads_with_its_gap_filled(tmp_path):
    """The tiny clip, its left knee bending 0, 30, ?, 90 degrees (BVH X) in frames 2-5 with "nan" in frame 4's
    X channel: frame 4 is the slerp of frames 3 and 5, by scipy's Slerp of the Euler angles as written."""
    frames = [tiny_frame()] + [tiny_frame(LeftLeg=(0, 0, a)) for a in (0, 30, 60, 90)]
    col = 6 + 3 * TINY_JOINTS.index("LeftLeg") + 2  # the hips' 6 channels, then Z Y X per joint
    tokens = frames[3].split()
    tokens[col] = "nan"
    frames[3] = " ".join(tokens)
    path = tmp_path / "gap.bvh"
    path.write_text(tiny_bvh(frames))
    clip = read_bvh(path)
    knee = clip.names.index("LeftLeg")
    ends = Rotation.from_euler("ZYX", [[0, 0, 30], [0, 0, 90]], degrees=True)
    xyzw = Slerp([0.0, 1.0], ends)([0.5]).as_quat()[0]
    expected = np.r_[xyzw[3], xyzw[:3]]
    assert abs(abs(float(clip.local_quat[3, knee] @ expected)) - 1.0) < 1e-9
    assert [(g.joint, g.first, g.last) for g in clip.gaps] == [("LeftLeg", 4, 4)]
    assert np.isfinite(clip.local_quat).all() and np.isfinite(clip.local_pos).all()


def test_the_rest_size_is_the_largest_extent_of_the_joints_and_end_sites():
    """A chain 1 + 1 down with a foot 0.5 forward and an arm 0.3 to the side: 2.0 (the vertical extent)."""
    offsets = np.array([[0, 0, 0], [0, -1, 0], [0, -1, 0], [0.3, 0, 0]], float)
    places = rest_places(offsets, [-1, 0, 1, 0])
    assert places[2] == pytest.approx([0, -2, 0]) and places[3] == pytest.approx([0.3, 0, 0])
    assert rest_size(places, {2: np.array([0, 0, 0.5]), 3: np.zeros(3)}) == pytest.approx(2.0)


def test_a_root_far_from_its_neighbours_is_corrupt_and_a_sprint_is_not():
    """A 1.75-unit body at 60 fps: a walk at 1.4 units/s with frames 0 and 50-52 put 1,460 units away (a decoder's
    garbage, the first frame among them) is corrupt at exactly those; a sprint at the fastest human speed
    (12.4 m/s for a 1.75 m body), reversing at once (the largest departure from a window's median), is not."""
    dt, size, n = 1 / 60, 1.75, 120
    t = np.arange(n) * dt
    walk = np.stack([1.4 * t, np.full(n, 0.95), np.zeros(n)], axis=1)
    walk[[0, 50, 51, 52]] = [1460.0, -1460.0, 1460.0]
    assert np.flatnonzero(corrupt_frames(walk, size, dt)).tolist() == [0, 50, 51, 52]
    v = 12.4 / 1.75 * size
    assert v <= ROOT_SPEED_MAX * size
    sprint = np.stack([v * np.minimum(t, 1.0) - v * np.maximum(t - 1.0, 0.0), np.full(n, 0.95), np.zeros(n)], axis=1)
    assert not corrupt_frames(sprint, size, dt).any()


def test_a_corrupt_frame_is_filled_for_every_joint_and_named_once(tmp_path):
    """The tiny clip (root at 1, 17, 10; 10 fps) with file frames 8-9 of its 16 put 10,000 units away and their knee
    angles garbage: read, those frames are their neighbours' root and the slerp of their knees, named once."""
    frames = [tiny_frame()] + [tiny_frame(LeftLeg=(0, 0, 5 * i)) for i in range(15)]
    for i in (7, 8):
        frames[i] = tiny_frame(hips_pos=(1e4, -1e4, 1e4), LeftLeg=(170, -80, 33))
    path = tmp_path / "corrupt.bvh"
    path.write_text(tiny_bvh(frames))
    clip = read_bvh(path)
    assert [(g.joint, g.first, g.last) for g in clip.gaps] == [(EVERY_JOINT, 8, 9)]
    assert clip.local_pos[7, 0] == pytest.approx([1.0, 17.0, 10.0]) and clip.local_pos[8, 0] == pytest.approx([1.0, 17.0, 10.0])
    knee = clip.names.index("LeftLeg")
    ends = Rotation.from_euler("ZYX", [[0, 0, 25], [0, 0, 40]], degrees=True)  # file frames 7 and 10
    for frame, u in ((7, 1 / 3), (8, 2 / 3)):
        xyzw = Slerp([0.0, 1.0], ends)([u]).as_quat()[0]
        assert abs(abs(float(clip.local_quat[frame, knee] @ np.r_[xyzw[3], xyzw[:3]])) - 1.0) < 1e-9
    assert "every joint frames 8-9 (0.200 s)" in gaps_line(clip.gaps)
    frames[0] = tiny_frame(hips_pos=(1e4, -1e4, 1e4))  # a rest pose put before the motion, elsewhere: as written
    path.write_text(tiny_bvh(frames))
    clip = read_bvh(path)
    assert [(g.joint, g.first, g.last) for g in clip.gaps] == [(EVERY_JOINT, 8, 9)]
    assert clip.local_pos[0, 0] == pytest.approx([1e4, -1e4, 1e4])


def test_an_infinite_value_is_one_line_naming_the_line(tmp_path):
    frames = [tiny_frame(), tiny_frame(), tiny_frame()]
    frames[2] = frames[2].replace("17", "inf", 1)
    path = tmp_path / "inf.bvh"
    path.write_text(tiny_bvh(frames))
    with pytest.raises(InputError, match=r"inf\.bvh: line \d+: frame 3 has the value 'inf'; give a finite number, or nan"):
        read_bvh(path)


@pytest.mark.slow
def test_a_clean_of_a_clip_with_a_gap_fills_names_and_writes_it(tmp_path, capsys):
    """127_33's first 0.25 s with "nan" in its first child joint's three angles at one frame: `clean` runs, prints
    the gap, records it in the metrics report, and the BVH it writes on the source skeleton has numbers only."""
    from bvh_edit import edit_bvh

    from runner.cli import main

    src = edit_bvh(CLIP, tmp_path / "gap.bvh", seconds=0.25)
    lines = src.read_text().splitlines()
    first = next(i for i, ln in enumerate(lines) if ln.startswith("Frame Time")) + 1
    joint = re.search(r"JOINT (\S+)", src.read_text()).group(1)
    tokens = lines[first + 10].split()
    tokens[6:9] = ["nan"] * 3
    lines[first + 10] = " ".join(tokens)
    src.write_text("\n".join(lines) + "\n")
    assert main(["clean", str(src), "--no-render", "--out-dir", str(tmp_path / "out")]) == 0
    said = capsys.readouterr().out
    assert "gaps filled (frames where the file gives a joint no number, 'nan'" in said and f"{joint} frame 11 (" in said
    report = json.loads((tmp_path / "out" / "gap.clean.metrics.json").read_text())
    assert report["reference_gaps"] == [f"{joint} frame 11 (0.008 s)"]
    written = (tmp_path / "out" / "gap.clean.bvh").read_text().split("MOTION")[1].lower()
    assert "nan" not in written and "inf" not in written
