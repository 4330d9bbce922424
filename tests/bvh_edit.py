"""Hand edits of a BVH clip for tests: another frame rate, another Euler order, renamed joints, scaled
bones, fewer frames: the clips a user of another capture would bring."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation


def edit_bvh(src, dst, *, seconds: float | None = None, stride: int = 1, order: str | None = None,
             rename: dict | None = None, scale: float = 1.0, hop: tuple | None = None, toeless: tuple = ()) -> Path:
    """Write an edited copy of the BVH clip `src` to `dst`.

    Args:
        seconds: keep the T-pose frame and about this many seconds after it (None: all).
        stride: keep every stride-th frame after the T-pose frame (frame time x stride).
        order: rewrite every joint's rotation channels in this order (e.g. "XYZ", "YXZ"), converting
            the angles so the rotations stay the same.
        rename: {old joint name: new name}. scale: multiply every OFFSET and root position (another
            subject's bone lengths).
        hop: (start [s], duration [s], height [m]): add 4 height s (1 - s), s = (t - start) / duration,
            to the root's height (BVH Y) for 0 < s < 1, t the time after the T-pose frame: the figure
            lifted off the ground, both feet with it (a synthetic hop).
        toeless: joints (e.g. the toes) replaced, with everything below them, by an End Site at their parent's
            joint (OFFSET 0 0 0), their channels dropped: a skeleton that gives the foot no length.
    """
    lines = Path(src).read_text().splitlines()
    m = next(i for i, ln in enumerate(lines) if ln.strip() == "MOTION")
    frame_time = float(lines[m + 2].split()[-1])
    head = lines[:m]
    data = np.array([[float(v) for v in ln.split()] for ln in lines[m + 3:] if ln.strip()])
    if toeless:
        head, data = _toeless(head, data, toeless)
    chans = []  # (joint, [channel names]) in file order
    joint = None
    out_head = []
    for ln in head:
        tok = ln.split()
        if tok[:1] in (["ROOT"], ["JOINT"]):
            joint = tok[1]
            if rename and joint in rename:
                ln = ln.replace(joint, rename[joint])
        elif tok[:1] == ["OFFSET"] and scale != 1.0:
            ln = ln[: ln.index("OFFSET")] + "OFFSET " + " ".join(f"{float(v) * scale:.6f}" for v in tok[1:])
        elif tok[:1] == ["CHANNELS"]:
            names = tok[2:]
            chans.append((joint, names))
            if order is not None:
                pos = [c for c in names if c.endswith("position")]
                ln = ln[: ln.index("CHANNELS")] + "CHANNELS " + " ".join(
                    [str(len(names))] + pos + [f"{a}rotation" for a in order])
        out_head.append(ln)
    cols = []
    col = 0
    new = data.copy()
    for _, names in chans:
        idx = list(range(col, col + len(names)))
        pos = [i for i, c in zip(idx, names, strict=True) if c.endswith("position")]
        rot = [i for i, c in zip(idx, names, strict=True) if c.endswith("rotation")]
        if scale != 1.0:
            new[:, pos] = data[:, pos] * scale
        if hop is not None and "Yposition" in names and not cols:  # the root's height
            from bvh_fk import UNIT

            start, duration, height = hop
            s = (np.arange(len(data)) - 1) * frame_time - start
            s = np.where((s > 0) & (s < duration), s / duration, 0.0)
            new[:, col + names.index("Yposition")] += 4.0 * height * s * (1.0 - s) / UNIT
        if order is not None and rot:
            seq = "".join(names[i - col][0] for i in rot)
            r = Rotation.from_euler(seq.upper(), data[:, rot], degrees=True)  # intrinsic: R = R1 R2 R3
            new[:, rot] = r.as_euler(order.upper(), degrees=True)
        cols += idx
        col += len(names)
    frames = np.concatenate([new[:1], new[1:][::stride]])
    if seconds is not None:
        frames = frames[: 1 + round(seconds / (frame_time * stride)) + 1]
    text = out_head + ["MOTION", f"Frames: {len(frames)}", f"Frame Time: {frame_time * stride:.7f}"]
    text += [" ".join(f"{v:.6f}" for v in row) for row in frames]
    Path(dst).write_text("\n".join(text) + "\n")
    return Path(dst)


def _toeless(head: list, data: np.ndarray, joints) -> tuple[list, np.ndarray]:
    """The HIERARCHY lines with each of `joints` (and its subtree) an End Site at OFFSET 0 0 0, and the MOTION
    columns without their channels."""
    out, keep, col, i = [], [], 0, 0
    while i < len(head):
        tok = head[i].split()
        if tok[:1] == ["JOINT"] and tok[1] in joints:
            indent = head[i][: len(head[i]) - len(head[i].lstrip())]
            depth, j = 0, i + 1
            while True:  # to the closing brace of the joint's block, dropping the channels inside it
                t = head[j].split()
                depth += t == ["{"]
                depth -= t == ["}"]
                if t[:1] == ["CHANNELS"]:
                    col += int(t[1])
                j += 1
                if depth == 0:
                    break
            out += [f"{indent}End Site", f"{indent}{{", f"{indent}\tOFFSET 0.00000 0.00000 0.00000", f"{indent}}}"]
            i = j
            continue
        if tok[:1] == ["CHANNELS"]:
            keep += range(col, col + int(tok[1]))
            col += int(tok[1])
        out.append(head[i])
        i += 1
    return out, data[:, keep]
