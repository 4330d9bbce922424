"""BVH files: parse a CMU clip (`read_bvh`) after a check of its text that gives line-numbered errors.

The text check (`_check_bvh_text`: the HIERARCHY grammar, the MOTION header, every data line) gives exact
line-numbered errors for user mistakes and protects against two `bvhio` 1.5.4 defects: its line reader
loops forever at end of file (a truncated file would hang it), and the line numbers in its SyntaxErrors
are wrong inside nested joints. Then `bvhio` parses the hierarchy, channels and Euler angles into local
quaternions (the pipeline: runner/capture/retarget.py).
"""
from __future__ import annotations

import codecs
import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from runner.capture.gaps import corrupt_frames, fill_gaps, rest_size
from solver.errors import InputError
from solver.quaternion import normalize

POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
ROTATION_CHANNELS = ("Xrotation", "Yrotation", "Zrotation")


@dataclass(frozen=True)
class BvhClip:
    """A parsed BVH clip (CMU units, BVH axes), before retargeting.

    Attributes:
        names: the J joint names in file order (depth-first).
        channels: the J joints' channel names, e.g. ("Zrotation", "Yrotation", "Xrotation").
        parents: (J,) parent index of each joint, -1 for the root.
        offsets: (J, 3) joint offsets from the parent [BVH units].
        local_quat: (n, J, 4) local rotation of each joint per frame (w x y z), BVH axes.
        local_pos: (n, J, 3) local translation per frame [BVH units] (the offset, or the position
            channels where a joint has them).
        frame_time: [s] time between frames.
        source: the file.
        end_sites: {joint index: (3,) End Site OFFSET [BVH units]} for the leaf joints (those without
            child joints; the BVH grammar gives a leaf an End Site).
        raw: (n, C) the MOTION section's numbers as written, C = total channel count (file order).
        gaps: the runs of frames where the file gives a joint no number ("nan"), or whose root is farther from
            the frames around them than a body moves (every joint's), filled in `local_quat` and `local_pos` from the
            frames around them (`runner.capture.gaps`).
    """

    names: tuple[str, ...]
    channels: tuple[tuple[str, ...], ...]
    parents: np.ndarray
    offsets: np.ndarray
    local_quat: np.ndarray
    local_pos: np.ndarray
    frame_time: float
    source: str
    end_sites: dict = field(default_factory=dict)
    raw: np.ndarray | None = None
    gaps: tuple = ()

    def index(self, name: str) -> int:
        return self.names.index(name)

    def rest_positions(self) -> np.ndarray:
        """(J, 3) [file units, file axes] every joint's place in the rest pose (`rest_places`)."""
        return rest_places(self.offsets, self.parents)


def rest_places(offsets: np.ndarray, parents) -> np.ndarray:
    """(J, 3) [file units, file axes] every joint's place in the rest pose (every channel zero): its (J, 3) OFFSETs
    summed from the root, `parents` (J,) before their children (-1 for the root)."""
    rest = np.zeros((len(offsets), 3))
    for j, par in enumerate(parents):
        rest[j] = offsets[j] + (rest[par] if par >= 0 else 0.0)
    return rest


# --------------------------------------------------------------------------------------------------
# parsing
# --------------------------------------------------------------------------------------------------


def _check_bvh_text(text: str, src: str) -> tuple[int, int, list[str]]:
    """Check the structure of a BVH text enough to give line-numbered errors and to make bvhio safe.

    Checks: HIERARCHY first, ROOT next, the joint grammar (`_check_hierarchy`: braces, OFFSET, CHANNELS
    with matching count and known names, End Site), MOTION, "Frames: N" (N >= 2), "Frame Time: T"
    (T > 0), at least N data lines, the first N (those read) each with one number per declared channel (finite,
    or "nan": a gap). After this, bvhio's reader cannot run past the end of the file.

    Args:
        text: the file's text. src: the file name for messages.
    Returns:
        (frames, channels, names): the declared frame count, the total channel count and the joints' names
        in the file's order, each the whole rest of its ROOT or JOINT line (3ds Max Biped's "Bip01 L Thigh").
    Raises:
        InputError: naming the line, the value and the fix.
    """
    lines = text.splitlines()
    rows = [(i + 1, ln.split()) for i, ln in enumerate(lines) if ln.strip()]
    if not rows:
        raise InputError(f"{src}: the file is empty; a BVH file starts with HIERARCHY and has a MOTION section")
    lineno, tok = rows[0]
    if tok != ["HIERARCHY"]:
        raise InputError(
            f"{src}: line {lineno}: expected 'HIERARCHY', found {' '.join(tok)[:60]!r}; "
            "is this a BVH file? A BVH file starts with HIERARCHY, then ROOT <name>"
        )
    if len(rows) < 2 or rows[1][1][:1] != ["ROOT"] or len(rows[1][1]) < 2:
        ln, t = rows[1] if len(rows) > 1 else (lineno, [])
        raise InputError(f"{src}: line {ln}: expected 'ROOT <name>' after HIERARCHY, found {' '.join(t)!r}")
    channels, motion_at, names = _check_hierarchy(rows, src)
    rest = rows[motion_at + 1 :]
    if len(rest) < 2:
        raise InputError(
            f"{src}: line {rows[motion_at][0]}: MOTION must be followed by 'Frames: N' and 'Frame Time: T'"
        )
    (ln_f, t_f), (ln_t, t_t) = rest[0], rest[1]
    if len(t_f) != 2 or t_f[0] != "Frames:":
        raise InputError(f"{src}: line {ln_f}: expected 'Frames: N', found {' '.join(t_f)!r}")
    try:
        frames = int(t_f[1])
    except ValueError:
        raise InputError(f"{src}: line {ln_f}: frame count {t_f[1]!r} is not an integer; write 'Frames: N'") from None
    if frames < 2:
        raise InputError(
            f"{src}: line {ln_f}: Frames: {frames}; need at least 2 frames (the first, a T-pose, is dropped)"
        )
    if len(t_t) != 3 or t_t[:2] != ["Frame", "Time:"]:
        raise InputError(f"{src}: line {ln_t}: expected 'Frame Time: T' (seconds), found {' '.join(t_t)!r}")
    try:
        frame_time = float(t_t[2])
    except ValueError:
        frame_time = float("nan")
    if not (math.isfinite(frame_time) and frame_time > 0):
        raise InputError(
            f"{src}: line {ln_t}: Frame Time {t_t[2]!r} is not a positive number of seconds; "
            "e.g. 'Frame Time: .0083333' for 120 frames per second"
        )
    data = rest[2:]
    if len(data) > frames:  # lines past the count: read as bvhio reads them, the first `frames` (an exporter's
        data = data[:frames]  # count one short, Assimp's Boxing_Toes.bvh: 3070 lines, "Frames: 3069")
    if len(data) != frames:
        where = f"line {data[-1][0]}" if data else f"line {ln_t}"
        raise InputError(
            f"{src}: {where}: the file has {len(data)} frame lines but line {ln_f} says Frames: {frames}; "
            "fix the count or restore the missing lines (file truncated?)"
        )
    _check_frame_lines(data, channels, src)
    return frames, channels, names


def _check_frame_lines(data: list[tuple[int, list[str]]], channels: int, src: str) -> None:
    """InputError unless every frame line of `data` ((line number, tokens) each) has `channels` numbers, each
    finite or "nan" (a gap, `runner.capture.gaps`)."""
    for i, (ln, t) in enumerate(data):
        if len(t) != channels:
            raise InputError(
                f"{src}: line {ln}: frame {i + 1} has {len(t)} values but the HIERARCHY declares {channels} "
                "channels; every frame line needs one number per channel"
            )
        try:
            vals = [float(v) for v in t]
        except ValueError:
            bad = next(v for v in t if not _is_float(v))
            raise InputError(f"{src}: line {ln}: frame {i + 1} has the non-number {bad!r}; use plain numbers") from None
        if any(math.isinf(v) for v in vals):  # "nan" is a gap (`runner.capture.gaps`); an infinite angle is no value
            bad = next(v for v in t if math.isinf(float(v)))
            raise InputError(f"{src}: line {ln}: frame {i + 1} has the value {bad!r}; give a finite number, or nan "
                             "where the capture has no value (a gap, filled from the frames around it)")


class _Grammar:
    """Recursive descent over the HIERARCHY's rows (see `_check_hierarchy`); counts the channels."""

    def __init__(self, rows: list[tuple[int, list[str]]], src: str):
        self.rows, self.src, self.total, self.names = rows, src, 0, [" ".join(rows[1][1][1:])]

    def row(self, i: int) -> tuple[int, list[str]]:
        if i >= len(self.rows):
            raise InputError(
                f"{self.src}: the file ends inside the HIERARCHY (truncated?); close every joint with '}}' and "
                "add the MOTION section"
            )
        return self.rows[i]

    def fail(self, i: int, expected: str):
        ln, t = self.row(i)
        found = " ".join(t)[:60]
        raise InputError(f"{self.src}: line {ln}: expected {expected}, found {found!r}; fix the HIERARCHY there")

    def offset(self, i: int) -> None:
        ln, t = self.row(i)
        if t[0] != "OFFSET":
            self.fail(i, "'OFFSET x y z'")
        if len(t) != 4 or not all(_is_float(v) for v in t[1:]):
            raise InputError(f"{self.src}: line {ln}: {' '.join(t)!r}: OFFSET takes three numbers, "
                             "e.g. 'OFFSET 0 -7.5 0'")

    def channels(self, i: int) -> int:
        ln, t = self.row(i)
        if t[0] != "CHANNELS":
            self.fail(i, "'CHANNELS n ...' after the OFFSET")
        try:
            count = int(t[1])
        except (IndexError, ValueError):
            raise InputError(
                f"{self.src}: line {ln}: CHANNELS needs a count, got {' '.join(t)!r}; "
                "write e.g. 'CHANNELS 3 Zrotation Yrotation Xrotation'"
            ) from None
        names = t[2:]
        if count != len(names):
            raise InputError(
                f"{self.src}: line {ln}: CHANNELS says {count} channels but lists {len(names)} "
                f"({' '.join(names)}); make the count match the names"
            )
        for name in names:
            if name not in POSITION_CHANNELS + ROTATION_CHANNELS:
                raise InputError(
                    f"{self.src}: line {ln}: unknown channel {name!r}; channels are "
                    f"{', '.join(POSITION_CHANNELS + ROTATION_CHANNELS)}"
                )
        return count

    def end_site(self, i: int) -> int:
        if self.row(i + 1)[1] != ["{"]:
            self.fail(i + 1, "'{' opening the End Site")
        self.offset(i + 2)
        if self.row(i + 3)[1] != ["}"]:
            self.fail(i + 3, "'}' closing the End Site")
        return i + 4

    def joint(self, i: int) -> int:
        """The joint whose '{' is rows[i]; returns the index after its '}'."""
        if self.row(i)[1] != ["{"]:
            self.fail(i, "'{' opening the joint")
        self.offset(i + 1)
        self.total += self.channels(i + 2)
        i += 3
        while True:
            _, t = self.row(i)
            if t[0] == "JOINT" and len(t) >= 2:  # the name is the rest of the line (Biped's "Bip01 L Thigh")
                self.names.append(" ".join(t[1:]))
                i = self.joint(i + 1)
            elif t[0] == "End" and len(t) >= 2 and t[1].startswith("Site"):  # a name after it names nothing
                # (MotionBuilder's "End Site Head_end"; "End Site5", numbered by an exporter of ASF/AMC names)
                i = self.end_site(i)
            elif t == ["}"]:
                return i + 1
            else:
                self.fail(i, "'JOINT <name>', 'End Site' or '}'")


def _check_hierarchy(rows: list[tuple[int, list[str]]], src: str) -> tuple[int, int, list[str]]:
    """Check the HIERARCHY grammar (recursive descent over the non-empty lines' tokens).

    joint := ('ROOT' | 'JOINT') name... '{' 'OFFSET' x y z 'CHANNELS' n names... (joint | end)* '}'
    end   := 'End' 'Site' [name] '{' 'OFFSET' x y z '}'

    Args:
        rows: (line number, tokens) of the non-empty lines; rows[0] is HIERARCHY.
        src: the file name for messages.
    Returns:
        (total channel count, index in rows of the MOTION line, the joints' names in the file's order).
    Raises:
        InputError: naming the line, what was found and what was expected.
    """
    grammar = _Grammar(rows, src)
    k = grammar.joint(2)  # rows[1] is "ROOT name", checked by the caller
    if k >= len(rows):
        raise InputError(
            f"{src}: no MOTION line after the HIERARCHY (file truncated?); a BVH file needs "
            "'MOTION', 'Frames: N', 'Frame Time: T' and N lines of numbers"
        )
    if rows[k][1][:1] != ["MOTION"]:
        grammar.fail(k, "'MOTION' after the ROOT joint's closing '}'")
    if rows[k][1] != ["MOTION"]:
        grammar.fail(k, "'MOTION' alone on its line")
    return grammar.total, k, grammar.names


def _is_float(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def read_bvh(path: str | Path) -> BvhClip:
    """Read a BVH file: hierarchy, offsets and per-frame local rotations (parsed by `bvhio`).

    Args:
        path: a .bvh file.
    Returns:
        BvhClip with all frames of the file (the T-pose frame included), in BVH units and axes.
    Raises:
        InputError: the file is missing or unreadable, or malformed (the message names the line).
    """
    import warnings

    with warnings.catch_warnings():  # bvhio imports PyGLM as "glm", which PyGLM marks as deprecated
        warnings.simplefilter("ignore", PendingDeprecationWarning)
        import bvhio

    src = str(path)
    p = Path(path)
    if not p.is_file():
        hint = "it is a folder" if p.is_dir() else f"no such file (current folder: {Path.cwd()})"
        raise InputError(f"{src}: cannot read the BVH clip: {hint}; give the path of a .bvh file")
    try:
        raw = p.read_bytes()
        text = raw.decode("utf-8-sig")  # a byte-order mark (.NET's UTF-8 writers put one first) is not text
    except UnicodeDecodeError as e:
        raise InputError(f"{src}: not a text file (byte {e.start} is not UTF-8); give a .bvh motion file") from None
    except OSError as e:
        raise InputError(f"{src}: cannot read the BVH clip: {e.strerror}; check the file's permissions") from None
    full_names = _check_bvh_text(text, src)[2]
    try:
        container = _parse(bvhio, p, text if raw.startswith(codecs.BOM_UTF8) else None)
    except SyntaxError as e:  # not expected after _check_bvh_text; bvhio's own message, no line number
        raise InputError(
            f"{src}: malformed BVH file: {e.args[0] if e.args else e}; check the HIERARCHY and MOTION sections"
        ) from None
    except Exception as e:  # any other failure of the third-party parser on this user file
        raise InputError(f"{src}: malformed BVH file ({type(e).__name__}: {e}); check HIERARCHY and MOTION") from None

    names, channels, parents, offsets, joints = [], [], [], [], []

    def walk(joint, parent):
        names.append(joint.Name)
        channels.append(tuple(joint.Channels))
        parents.append(parent)
        offsets.append(list(joint.Offset))
        joints.append(joint)
        me = len(names) - 1
        for child in joint.Children:
            walk(child, me)

    walk(container.Root, -1)
    if len(full_names) == len(names):  # bvhio keeps a name's first word ("Bip01" of "Bip01 L Thigh"); same order
        names = list(full_names)
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputError(f"{src}: joint name(s) {', '.join(dup)} appear more than once; joint names must be unique")
    end_sites = {j: np.array(list(joint.EndSite), float) for j, joint in enumerate(joints) if not joint.Children}
    n = len(joints[0].Keyframes)
    quat = np.empty((n, len(joints), 4))
    pos = np.empty((n, len(joints), 3))
    for j, joint in enumerate(joints):
        quat[:, j] = [list(k.Rotation) for k in joint.Keyframes]  # glm.quat iterates w, x, y, z
        pos[:, j] = [list(k.Position) for k in joint.Keyframes]
    dt = float(container.FrameTime)
    corrupt = corrupt_frames(pos[:, 0], rest_size(rest_places(np.array(offsets, float), parents), end_sites), dt)
    corrupt[0] = False  # a first frame elsewhere can be a rest pose put before the motion (skeleton.py's rest frames)
    quat, pos, gaps = fill_gaps(quat, pos, names, dt, src, corrupt)
    return BvhClip(
        tuple(names),
        tuple(channels),
        np.array(parents, int),
        np.array(offsets, float),
        normalize(quat),
        pos,
        float(container.FrameTime),
        src,
        end_sites,
        _motion_numbers(text),
        gaps,
    )


def _parse(bvhio, p: Path, text: str | None):
    """bvhio's parse of the file `p`, or, given its `text`, of a copy of that text (bvhio reads a byte-order
    mark as part of the first line, and refuses the file)."""
    if text is None:
        return bvhio.readAsBvh(str(p))
    with tempfile.TemporaryDirectory() as folder:
        copy = Path(folder) / p.name
        copy.write_text(text, encoding="utf-8")
        return bvhio.readAsBvh(str(copy))


def _motion_numbers(text: str) -> np.ndarray:
    """(n, C) the numbers of the MOTION section's frame lines (already checked by `_check_bvh_text`)."""
    lines = text.splitlines()
    m = next(i for i, ln in enumerate(lines) if ln.split()[:1] == ["MOTION"])
    rows = [ln.split() for ln in lines[m + 1:] if ln.strip()]
    return np.array(rows[2:2 + int(rows[0][1])], float)  # after "Frames: N" and "Frame Time:", the N frames read
