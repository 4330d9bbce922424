"""runner.files: atomic output and the writable-folder check."""
import os

import numpy as np
import pytest

from runner.files import atomic_output, check_writable_dir
from solver import InputError


def _leftovers(folder, keep):
    return sorted(p.name for p in folder.iterdir() if p.name not in keep)


def test_atomic_output_replaces_on_success(tmp_path):
    out = tmp_path / "a.npy"
    out.write_bytes(b"old")
    with atomic_output(out) as tmp:
        assert tmp.parent == tmp_path and tmp.name.endswith(".npy") and tmp != out
        assert not tmp.exists()  # the writer creates it
        np.save(tmp, np.arange(3))  # numpy would append .npy to a name without it
        assert out.read_bytes() == b"old"  # not yet replaced
    np.testing.assert_array_equal(np.load(out), np.arange(3))
    assert _leftovers(tmp_path, {"a.npy"}) == []


def test_atomic_output_suffix_override(tmp_path):
    with atomic_output(tmp_path / "clip", suffix=".mp4") as tmp:
        assert tmp.suffix == ".mp4"
        tmp.write_bytes(b"x")
    assert (tmp_path / "clip").read_bytes() == b"x"


@pytest.mark.parametrize("exc", [RuntimeError("disk on fire"), KeyboardInterrupt()])
def test_failed_write_leaves_earlier_output_intact(tmp_path, exc):
    out = tmp_path / "run.mp4"
    out.write_bytes(b"earlier complete video")
    with pytest.raises(type(exc)), atomic_output(out) as tmp:
        tmp.write_bytes(b"half a vid")
        raise exc
    assert out.read_bytes() == b"earlier complete video"
    assert _leftovers(tmp_path, {"run.mp4"}) == []


def test_failed_first_write_leaves_nothing(tmp_path):
    out = tmp_path / "new.png"
    with pytest.raises(ValueError), atomic_output(out) as tmp:
        tmp.write_bytes(b"partial")
        raise ValueError("encoder failed")
    assert list(tmp_path.iterdir()) == []


def test_body_that_writes_nothing_raises(tmp_path):
    with pytest.raises(FileNotFoundError), atomic_output(tmp_path / "x.png"):
        pass


def test_check_writable_dir_creates_missing_folders(tmp_path):
    out = tmp_path / "renders" / "deeper" / "x.mp4"
    assert check_writable_dir(out) == out.parent
    assert out.parent.is_dir()
    assert list(out.parent.iterdir()) == []  # the probe file is gone


def test_check_writable_dir_file_in_the_way(tmp_path):
    (tmp_path / "renders").write_text("I am a file")
    with pytest.raises(InputError, match=r"cannot write .*x\.mp4.*renders.*choose another --out"):
        check_writable_dir(tmp_path / "renders" / "x.mp4")


def test_check_writable_dir_output_is_a_folder(tmp_path):
    with pytest.raises(InputError, match="existing folder"):
        check_writable_dir(tmp_path)


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root writes read-only folders")
def test_check_writable_dir_read_only(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        with pytest.raises(InputError, match="not writable"):
            check_writable_dir(folder / "x.mp4")
    finally:
        folder.chmod(0o755)
