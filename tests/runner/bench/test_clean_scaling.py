"""`bench scaling --mode clean`'s lengths. A prefix is the capture's first frames as written: its header, the
rest frame and the first rows read back by the BVH reader exactly as the whole file's, `Frames:` right, and the
lengths in the factors' exact ratios. The loop: a clip played forward and backward k times is k times as long
after its rest frame, continuous at every seam (no step larger than the clip's own), the rest frame kept once.
Bad options are one line."""
from pathlib import Path

import numpy as np
import pytest

from runner.bench.clean_scaling import loop_bvh, prefix_bvh, prefix_frames
from runner.capture.bvh import read_bvh
from runner.cli import main
from runner.exit_codes import EXIT_INPUT

CLIP = Path(__file__).resolve().parents[3] / "models" / "cmu" / "16_23.bvh"


def motion(path: Path) -> tuple[int, np.ndarray]:
    """("Frames:" of the header, (frames, channels) the motion rows)."""
    lines = path.read_text().splitlines()
    m = lines.index("MOTION")
    rows = np.array([[float(v) for v in ln.split()] for ln in lines[m + 3:] if ln.strip()])
    return int(lines[m + 1].split()[1]), rows


@pytest.mark.parametrize("frames", [2, 37, 299])
def test_a_prefix_is_the_first_frames_of_the_capture_as_written(tmp_path, frames):
    whole = read_bvh(CLIP)
    written = prefix_bvh(CLIP, tmp_path / "p.bvh", frames)
    count, rows = motion(tmp_path / "p.bvh")
    assert written == count == len(rows) == 1 + frames
    head = CLIP.read_text().split("MOTION")[0]
    assert (tmp_path / "p.bvh").read_text().split("MOTION")[0] == head
    part = read_bvh(tmp_path / "p.bvh")
    assert part.names == whole.names and part.frame_time == whole.frame_time
    np.testing.assert_array_equal(part.raw, whole.raw[:1 + frames])  # the rest frame, then the first frames
    np.testing.assert_array_equal(part.offsets, whole.offsets)


def test_prefix_lengths_are_in_the_factors_ratios_and_fit_the_clip(tmp_path):
    _, src = motion(CLIP)
    n = len(src) - 1  # 299 after the rest frame
    assert prefix_frames(CLIP, (1, 2, 4, 8)) == {1: 37, 2: 74, 4: 148, 8: 296}  # 37 = floor(299 / 8)
    assert prefix_frames(CLIP, (1, 3)) == {1: n // 3, 3: 3 * (n // 3)}
    with pytest.raises(ValueError, match="150x needs at least 300"):
        prefix_frames(CLIP, (1, 150))
    with pytest.raises(ValueError, match="a prefix of 300 frames; the clip has 299"):
        prefix_bvh(CLIP, tmp_path / "p.bvh", 300)


@pytest.mark.parametrize("copies", [1, 2, 3])
def test_the_loop_is_copies_times_as_long_and_continuous(tmp_path, copies):
    _, src = motion(CLIP)
    n = len(src) - 1  # after the rest frame
    written = loop_bvh(CLIP, tmp_path / "x.bvh", copies)
    count, got = motion(tmp_path / "x.bvh")
    assert written == count == len(got) == 1 + copies * (n - 1) + 1
    np.testing.assert_array_equal(got[0], src[0])  # the rest frame, once
    np.testing.assert_array_equal(got[1:n + 1], src[1:])
    if copies > 1:
        np.testing.assert_array_equal(got[n:2 * n], src[1:][::-1])  # the second copy: backward from the seam
    step = np.abs(np.diff(src[1:], axis=0)).max()
    assert np.abs(np.diff(got[1:], axis=0)).max() <= step


def test_a_loop_needs_two_frames(tmp_path):
    lines = CLIP.read_text().splitlines()
    m = lines.index("MOTION")
    short = tmp_path / "short.bvh"
    short.write_text("\n".join([*lines[:m + 1], "Frames: 2", lines[m + 2], *lines[m + 3:m + 5]]) + "\n")
    with pytest.raises(ValueError, match="a loop needs at least 2"):
        loop_bvh(short, tmp_path / "x.bvh", 2)


def test_bad_options_are_one_line(tmp_path, capsys):
    assert main(["bench", "scaling", "--mode", "clean", "--dense"]) == EXIT_INPUT
    assert main(["bench", "scaling", "--clip", str(CLIP)]) == EXIT_INPUT
    assert main(["bench", "scaling", "--mode", "clean", "--clip", str(tmp_path / "none.bvh")]) == EXIT_INPUT
    assert main(["bench", "scaling", "--loop"]) == EXIT_INPUT
    assert main(["bench", "scaling", "--mode", "clean", "--factors", "1,1000"]) == EXIT_INPUT
    assert main(["bench", "scaling", "--mode", "clean", "--factors", "1,x"]) == EXIT_INPUT
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 6 and "--mode animate" in err[0] and "--mode clean" in err[1] and "none.bvh" in err[2]
    assert "--loop goes with --mode clean" in err[3] and "1000x needs" in err[4] and "whole numbers" in err[5]


def test_the_per_evaluation_table_builds_one_preconditioner_two_ways(capsys):
    """`--per-eval`: D's preconditioner on the clean's grid of the capture's first half and of all of it, dense and
    banded; the two S S^T g agree to round-off (the same matrix), and the lengths are in the factors' ratio."""
    assert main(["bench", "scaling", "--mode", "clean", "--per-eval", "--clip", str(CLIP), "--factors", "1,2"]) == 0
    rows = [ln.split() for ln in capsys.readouterr().out.splitlines() if "|" in ln and ln.split()[0] in ("1x", "2x")]
    assert [r[0] for r in rows] == ["1x", "2x"] and abs(int(rows[1][1]) - 2 * int(rows[0][1])) <= 1
    assert all(float(r[-1]) < 1e-8 for r in rows)  # the relative difference of S S^T g, dense against banded
    assert main(["bench", "scaling", "--mode", "clean", "--per-eval", "--clip", str(CLIP), "--factors", "1,200"]) == EXIT_INPUT
    assert "fewer than the 4 a clean needs" in capsys.readouterr().err
