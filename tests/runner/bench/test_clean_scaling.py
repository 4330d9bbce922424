"""`bench scaling --mode clean`'s loop: a clip played forward and backward k times is k times as long after its
rest frame, continuous at every seam (no step larger than the clip's own), the rest frame kept once; bad
options are one line."""
from pathlib import Path

import numpy as np
import pytest

from runner.bench.clean_scaling import loop_bvh
from runner.cli import main
from runner.exit_codes import EXIT_INPUT

CLIP = Path(__file__).resolve().parents[3] / "models" / "cmu" / "16_23.bvh"


def motion(path: Path) -> tuple[int, np.ndarray]:
    """("Frames:" of the header, (frames, channels) the motion rows)."""
    lines = path.read_text().splitlines()
    m = lines.index("MOTION")
    rows = np.array([[float(v) for v in ln.split()] for ln in lines[m + 3:] if ln.strip()])
    return int(lines[m + 1].split()[1]), rows


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
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 3 and "--mode animate" in err[0] and "--mode clean" in err[1] and "none.bvh" in err[2]
