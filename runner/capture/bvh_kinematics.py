"""Forward kinematics of a parsed BVH clip (runner/capture/bvh.py): world orientations and positions of its
joints, where a chain ends, and the lengths the skeleton recognition (runner/capture/skeleton.py) reads."""
from __future__ import annotations

import numpy as np

from runner.capture.bvh import BvhClip
from solver.quaternion import conj, mul, normalize

__all__ = ["between", "rotate", "forward", "file_world", "to_mujoco", "tip_positions", "bone_length", "reach"]


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate (..., 3) vectors by (..., 4) unit quaternions (w x y z)."""
    qv = np.concatenate([np.zeros(v.shape[:-1] + (1,)), v], axis=-1)
    return mul(mul(q, qv), conj(q))[..., 1:]


def between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n, 4) the shortest rotations taking the directions a (n, 3) to b (n, 3) (not opposite): w = 1 + a.b,
    v = a x b for unit a, b, normalized (the half-way quaternion)."""
    a = a / np.linalg.norm(a, axis=1, keepdims=True)
    b = b / np.linalg.norm(b, axis=1, keepdims=True)
    return normalize(np.concatenate([1.0 + np.sum(a * b, axis=1, keepdims=True), np.cross(a, b)], axis=1))


def forward(parents, local_quat: np.ndarray, local_pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """BVH forward kinematics (column vectors): world orientations (n, J, 4) and positions (n, J, 3) from
    local rotations (n, J, 4) (w x y z) and translations (n, J, 3): q_world[j] = q_world[parent] q_local[j],
    p_world[j] = p_world[parent] + R(q_world[parent]) t[j]. Parents precede their children."""
    n, J = local_quat.shape[:2]
    q, p = np.empty((n, J, 4)), np.empty((n, J, 3))
    for j in range(J):
        par = parents[j]
        if par < 0:
            q[:, j], p[:, j] = local_quat[:, j], local_pos[:, j]
        else:
            q[:, j] = mul(q[:, par], local_quat[:, j])
            p[:, j] = p[:, par] + rotate(q[:, par], local_pos[:, j])
    return q, p


def file_world(clip: BvhClip) -> tuple[np.ndarray, np.ndarray]:
    """World orientation (n, J, 4) and position (n, J, 3) [file units] of every joint, file axes, every
    frame (`forward`; a joint's translation is its OFFSET or, where it has position channels, their
    values: bvhio's reading, as Blender's importer)."""
    return forward(clip.parents, clip.local_quat, clip.local_pos)


def to_mujoco(q: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """(..., 4) rotations given in a file's axes expressed in MuJoCo's: R' = A R A^T for v' = A v."""
    out = np.array(q, float, copy=True)
    out[..., 1:] = q[..., 1:] @ axes.T
    return out


def tip_positions(clip: BvhClip, world: tuple[np.ndarray, np.ndarray], joint: int, axes=None, unit=1.0) -> np.ndarray:
    """(n, 3) where the chain from `joint` ends: the End Site of the leaf its longest path reaches (a
    leaf without one: the leaf itself), from world = (orientations, positions) in the frame of `axes`
    (None: the file's) and `unit` [m per file unit]."""
    children: list[list[int]] = [[] for _ in clip.names]
    for c, par in enumerate(clip.parents):
        if par >= 0:
            children[par].append(c)
    j = joint
    while children[j]:
        j = max(children[j], key=lambda c: bone_length(clip, c) + reach(clip, children, c))
    q, p = world
    end = np.asarray(clip.end_sites.get(j, np.zeros(3)), float)
    if axes is not None:
        end = axes @ end
    return p[:, j] + rotate(q[:, j], np.broadcast_to(end * unit, p[:, j].shape))


def bone_length(clip: BvhClip, j: int) -> float:
    """[file units] the length of the bone ending at joint j: its mean translation from its parent."""
    return float(np.linalg.norm(clip.local_pos[:, j].mean(axis=0)))


def reach(clip: BvhClip, children, j: int) -> float:
    """[file units] the longest path from joint j down to an end (its End Site included)."""
    if not children[j]:
        end = clip.end_sites.get(j)
        return float(np.linalg.norm(end)) if end is not None else 0.0
    return max(bone_length(clip, c) + reach(clip, children, c) for c in children[j])
