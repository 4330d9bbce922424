"""An independent forward kinematics of a BVH file for tests: the text read here (not by bvhio), each
joint's rotation channels turned into a matrix by scipy (intrinsic rotations in the listed order, the
BVH convention), a joint's translation its OFFSET or, where it has position channels, their values (as
Blender's importer reads them), world positions and rotations by the matrix chain, in metres and MuJoCo
axes (by default CMU's: 1 unit = 0.0254 / 0.45 m, Y up)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

#: metres per CMU unit (ASF `length 0.45`: 1 unit = 1/0.45 inch), and (x, y, z)_mujoco = (Z, X, Y)_bvh
UNIT = 0.0254 / 0.45
AXES = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
#: a Z-up file's axes: (x, y, z)_mujoco = (X, Y, Z)
Z_UP = np.eye(3)
POSITIONS = ("Xposition", "Yposition", "Zposition")


@dataclass
class BvhText:
    """names (J,), parents (J,), offsets (J, 3) [units], channels (J,) lists, ends {joint: (3,)},
    frame_time [s], values (n, C) the MOTION numbers."""

    names: list
    parents: list
    offsets: np.ndarray
    channels: list
    ends: dict
    frame_time: float
    values: np.ndarray

    def index(self, name):
        return self.names.index(name)


def parse(path) -> BvhText:
    """The HIERARCHY and MOTION of a well-formed BVH file."""
    tok = Path(path).read_text().split()
    names, parents, offsets, channels, ends, stack = [], [], [], [], {}, []
    i, end_site = 0, False
    while tok[i] != "MOTION":
        t = tok[i]
        if t in ("ROOT", "JOINT"):
            names.append(tok[i + 1])
            parents.append(stack[-1] if stack else -1)
            i += 2
        elif t == "End":
            end_site = True
            i += 2
        elif t == "{":
            stack.append(-2 if end_site else len(names) - 1)  # -2: an End Site's block
            i += 1
        elif t == "}":
            top = stack.pop()
            end_site = end_site and top != -2
            i += 1
        elif t == "OFFSET":
            v = [float(x) for x in tok[i + 1:i + 4]]
            if end_site:
                ends[stack[-2]] = np.array(v)
            else:
                offsets.append(v)
            i += 4
        elif t == "CHANNELS":
            k = int(tok[i + 1])
            channels.append(tok[i + 2:i + 2 + k])
            i += 2 + k
        else:
            i += 1
    frames = int(tok[i + 2])
    frame_time = float(tok[i + 5])
    values = np.array(tok[i + 6:], float).reshape(frames, -1)
    return BvhText(names, parents, np.array(offsets), channels, ends, frame_time, values)


def local_rotations(b: BvhText) -> np.ndarray:
    """(n, J, 3, 3) local rotation matrices, BVH axes."""
    n, J = len(b.values), len(b.names)
    out = np.empty((n, J, 3, 3))
    col = 0
    for j, chans in enumerate(b.channels):
        rot = [(c[0], col + k) for k, c in enumerate(chans) if c.endswith("rotation")]
        order = "".join(a for a, _ in rot)
        out[:, j] = Rotation.from_euler(order, b.values[:, [k for _, k in rot]], degrees=True).as_matrix() if rot \
            else np.eye(3)
        col += len(chans)
    return out


def translations(b: BvhText) -> np.ndarray:
    """(n, J, 3) each joint's translation from its parent [units]: its position channels where it has
    them, else its OFFSET."""
    n = len(b.values)
    out = np.broadcast_to(b.offsets, (n,) + b.offsets.shape).copy()
    col = 0
    for j, chans in enumerate(b.channels):
        for k, c in enumerate(chans):
            if c in POSITIONS:
                out[:, j, POSITIONS.index(c)] = b.values[:, col + k]
        col += len(chans)
    return out


def world(b: BvhText, unit: float = UNIT, axes: np.ndarray = AXES) -> tuple[np.ndarray, np.ndarray]:
    """World rotations (n, J, 3, 3) and positions (n, J, 3) [m], MuJoCo axes, every frame of the file;
    `unit` [m per file unit] and `axes` (file -> MuJoCo) the file's."""
    R = local_rotations(b)
    t = translations(b)
    n, J = R.shape[:2]
    Rw = np.empty_like(R)
    pw = np.empty((n, J, 3))
    for j in range(J):
        par = b.parents[j]
        if par < 0:
            Rw[:, j], pw[:, j] = R[:, j], t[:, j]
        else:
            Rw[:, j] = Rw[:, par] @ R[:, j]
            pw[:, j] = pw[:, par] + np.einsum("nab,nb->na", Rw[:, par], t[:, j])
    return axes @ Rw @ axes.T, pw @ axes.T * unit
