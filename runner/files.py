"""Writing output files safely: check the folder first, write to a temporary file, then rename.

A render takes seconds and an export can fail halfway (a full disk, an OpenGL error, Ctrl-C). Writing
through `atomic_output` means the output path holds either the previous complete file or the new
complete file, never a truncated one. `check_writable_dir` runs before the slow work starts, so a bad
`--out` fails in milliseconds with a message that says what to do.
"""
from __future__ import annotations

import contextlib
import os
import uuid
from collections.abc import Iterator
from pathlib import Path

from solver.errors import InputError

__all__ = ["atomic_output", "check_writable_dir"]


def check_writable_dir(path: str | os.PathLike, option: str = "--out") -> Path:
    """Make sure the folder of output file `path` exists (creating it) and can be written.

    Writability is probed by creating and removing a file there (`os.access` says yes to root even on
    a read-only mount).

    Args:
        path: the output *file* path, e.g. "renders/run_and_step.mp4".
        option: the command-line option that named it, for the message's fix ("choose another ...").

    Returns:
        The folder, as a `Path`.

    Raises:
        InputError: the folder cannot be created, is not a folder, or cannot be written; `path` is an
            existing folder.
    """
    path = Path(path)
    folder = path.parent
    if path.is_dir():
        raise InputError(f"cannot write {path}: it is an existing folder; choose a file name for {option}")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError) as e:
        raise InputError(
            f"cannot write {path}: folder {folder} does not exist and cannot be created "
            f"(a file is in the way: {e.filename}); choose another {option}") from e
    except OSError as e:
        raise InputError(
            f"cannot write {path}: folder {folder} does not exist and cannot be created "
            f"({e.strerror}); choose another {option}") from e
    probe = folder / f".{path.name}.{uuid.uuid4().hex[:8]}.probe"
    try:
        with open(probe, "xb"):
            pass
    except OSError as e:
        raise InputError(
            f"cannot write {path}: folder {folder} is not writable ({e.strerror}); "
            f"choose another {option}") from e
    finally:
        with contextlib.suppress(OSError):
            probe.unlink()
    return folder


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside `path`; on success rename it onto `path`, on failure remove it.

    The temporary file is in the same folder (so `os.replace` is an atomic rename on one file system)
    and ends with the same extension (so imageio and numpy pick the format from the name). It is not
    created in advance: the writer creates it, with the usual permissions. If the body raises (any
    exception, also KeyboardInterrupt), the temporary file is removed, an existing `path` is left as
    it was, and the exception propagates.

    Args:
        path: the final output file.
        suffix: extension of the temporary file, e.g. ".mp4"; default: that of `path`.

    Yields:
        The temporary path (`Path`), e.g. "renders/.run_and_step.mp4.3f2a9c1e.tmp.mp4".

    Raises:
        FileNotFoundError: the body finished without writing the temporary file.
        OSError: the rename failed (the temporary file is removed).
    """
    path = Path(path)
    if suffix is None:
        suffix = path.suffix
    tmp = path.parent / f".{path.name}.{uuid.uuid4().hex[:8]}.tmp{suffix}"
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
