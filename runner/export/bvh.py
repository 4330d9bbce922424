"""BVH export of the figure on its own skeleton, and the inverse (a BVH clip back to figure `qpos`).

Skeleton: one BVH joint per figure body (pelvis = ROOT, then the bodies with a ball joint, depth-first in
MuJoCo's order), named after the bodies. OFFSETs are MuJoCo's `body_pos` of the loaded model (the joint
centre: every ball joint sits at its body's origin); leaf bodies (feet, forearms) end in an `End Site`
at the far end of their geoms, except the feet, whose end site is the toe contact site (the tip of the
sole, `solver.figure.Figure.feet`). The ROOT's OFFSET is 0 0 0 and its position channels carry the root
translation (world position of the pelvis frame).

Neck and head: the figure's head is rigid with its torso, so the skeleton adds two joints that never
move, ``neck`` (the base of the neck) and ``head`` (the base of the skull), under the torso, ending in
an End Site at the top of the head (`solver.figure.NeckChain`: the geom ``neck`` and the site ``head``).
Their rotation channels are always 0. So the rest armature spans the figure's standing height, from
the soles to the top of the head (1.75 m for models/humanoid39.xml).

Units and axes: metres and degrees. BVH axes are Y up, the figure facing +Z, its left at +X:
(X, Y, Z)_bvh = (y, z, x)_mujoco, the axes of the CMU clips (runner/capture/skeleton.py, inverted).
Blender's BVH importer with its defaults (Forward -Z, Up Y, scale 1) turns BVH Y into Blender Z, so the
figure opens upright, 1.75 m tall, standing on Blender's ground plane at the identity pose' root height.

Rotations: every joint has the channels ``Yrotation Zrotation Xrotation`` (R = Ry Rz Rx acting on column
vectors, the BVH convention: the first channel is the outermost rotation). The middle axis Z is the
figure's forward axis (roll, abduction), the one least often near 90 degrees for a runner (heading Y and
flexion X are often large), which keeps the Euler angles away from gimbal lock. Angles are unwrapped over
time (no 360-degree jumps) and written with 9 decimals (positions too, in metres).

The local rotation of a joint is the body's `body_quat` times its ball joint's quaternion (the root's is
the free joint's quaternion), expressed in BVH axes: R' = M R M^T with M the axis change above.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from solver.errors import InputError
from solver.figure import Figure
from solver.quaternion import align_hemispheres, conj, mul, normalize

__all__ = ["MUJOCO_TO_BVH", "EULER_ORDER", "Skeleton", "figure_skeleton", "bvh_text", "write_bvh",
           "is_figure_clip", "figure_qpos_from_bvh"]

#: (3, 3) axis change from MuJoCo (z up, facing +x, left +y) to BVH (Y up, facing +Z, left +X): v' = M v.
MUJOCO_TO_BVH = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
#: Euler order of every joint's rotation channels (intrinsic, outermost first).
EULER_ORDER = "YZX"
_DECIMALS = 9


@dataclass(frozen=True)
class Skeleton:
    """The figure's bodies (and its fixed neck and head joints) as a BVH skeleton.

    Attributes:
        bodies: (J,) MuJoCo body ids, depth-first (root first), -1 for the fixed neck and head joints.
        names: (J,) body names ("neck", "head" for the fixed joints).
        parents: (J,) index into `bodies` of each parent, -1 for the root.
        offsets: (J, 3) body_pos in the parent frame [m], MuJoCo axes (the root's: zeros).
        body_quat: (J, 4) body_quat (w x y z); the root's is the identity (the free joint replaces it).
        qpos_quat: (J, 4) qpos indices of each body's joint quaternion (the root's: its free joint's;
            zeros for the fixed joints, which `local_quat` keeps at the identity).
        root_pos: (3,) qpos indices of the root translation.
        end_sites: {index: (3,) offset [m], MuJoCo axes} for the leaf bodies.
    """

    bodies: np.ndarray
    names: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    body_quat: np.ndarray
    qpos_quat: np.ndarray
    root_pos: np.ndarray
    end_sites: dict

    @property
    def count(self) -> int:
        return len(self.bodies)

    @property
    def moving(self) -> np.ndarray:
        """(J,) bool: the joint is a body of the figure (False: a fixed neck or head joint)."""
        return self.bodies >= 0

    def local_quat(self, qpos: np.ndarray) -> np.ndarray:
        """(n, J, 4) unit local rotation of every joint (parent frame <- body frame), MuJoCo axes; the
        identity for the fixed joints."""
        qpos = np.asarray(qpos, float)
        out = np.zeros((len(qpos), self.count, 4))
        out[..., 0] = 1.0
        m = self.moving
        q = normalize(qpos[:, self.qpos_quat[m]])
        out[:, m] = normalize(mul(np.broadcast_to(self.body_quat[m], q.shape), q))
        return out


def figure_skeleton(model, head: bool = True) -> Skeleton:
    """The skeleton of the figure in `model`: the free-joint body and its descendants (module docstring).

    Args:
        model: MjModel holding the figure.
        head: add the fixed neck and head joints (BVH); False: the bodies only (glTF, whose torso node
            holds the head's mesh).
    Raises:
        InputError: no free joint, or a descendant body without exactly one ball joint at its origin,
            or a figure without its annotations (`solver.figure.Figure.from_model`).
    """
    import mujoco

    free = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
    if len(free) != 1:
        raise InputError(f"the scene has {len(free)} free joints; BVH export needs exactly one (the figure's root)")
    root = int(model.jnt_bodyid[free[0]])
    bodies, parents, qidx = [root], [-1], [model.jnt_qposadr[free[0]] + 3 + np.arange(4)]
    for b in range(root + 1, model.nbody):  # MuJoCo numbers bodies depth-first
        if int(model.body_parentid[b]) not in bodies:
            continue
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b)
        jnts = range(model.body_jntadr[b], model.body_jntadr[b] + model.body_jntnum[b])
        if len(jnts) != 1 or model.jnt_type[jnts[0]] != mujoco.mjtJoint.mjJNT_BALL:
            raise InputError(f"body {name!r} has {len(jnts)} joint(s); BVH export needs one ball joint per body")
        if np.abs(model.jnt_pos[jnts[0]]).max() > 1e-12:
            raise InputError(f"body {name!r}: its ball joint is not at the body origin (pos "
                             f"{model.jnt_pos[jnts[0]].tolist()}); BVH export needs joints at body origins")
        parents.append(bodies.index(int(model.body_parentid[b])))
        bodies.append(b)
        qidx.append(model.jnt_qposadr[jnts[0]] + np.arange(4))
    bodies = np.array(bodies, int)
    offsets = model.body_pos[bodies].copy()
    offsets[0] = 0.0
    bquat = model.body_quat[bodies].copy()
    bquat[0] = (1.0, 0.0, 0.0, 0.0)
    names = tuple(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, int(b)) for b in bodies)
    figure = Figure.from_model(model)
    end_sites = {i: _end_site(model, int(b), figure) for i, b in enumerate(bodies) if i not in parents}
    root_pos = model.jnt_qposadr[free[0]] + np.arange(3)
    sk = Skeleton(bodies, names, np.array(parents, int), offsets, bquat, np.array(qidx, int), root_pos, end_sites)
    neck = figure.neck
    if head and neck is not None and not {"neck", "head"} & set(names):
        sk = _with_neck(sk, names.index(neck.body), neck)
    return sk


def _with_neck(sk: Skeleton, torso: int, neck) -> Skeleton:
    """`sk` with the fixed joints neck (child of `torso`) and head, and the head's End Site (module docstring)."""
    J = sk.count
    return Skeleton(np.r_[sk.bodies, -1, -1], sk.names + ("neck", "head"), np.r_[sk.parents, torso, J],
                    np.vstack([sk.offsets, neck.neck, neck.skull - neck.neck]),
                    np.vstack([sk.body_quat, [[1.0, 0, 0, 0]] * 2]), np.vstack([sk.qpos_quat, np.zeros((2, 4), int)]),
                    sk.root_pos, {**sk.end_sites, J + 1: neck.top - neck.skull})


def _end_site(model, body: int, figure: Figure) -> np.ndarray:
    """A leaf body's End Site [m], body frame: a foot's toe contact site (the tip of the sole), else the
    end of the body's geoms farthest from the origin."""
    import mujoco

    for _heel, toe in figure.feet.values():
        if int(model.site_bodyid[model.site(toe).id]) == body:
            return np.array(model.site_pos[model.site(toe).id], float)
    best = np.zeros(3)
    for g in range(model.body_geomadr[body], model.body_geomadr[body] + model.body_geomnum[body]):
        size, kind = model.geom_size[g], int(model.geom_type[g])
        half = {int(mujoco.mjtGeom.mjGEOM_CAPSULE): size[1] + size[0], int(mujoco.mjtGeom.mjGEOM_SPHERE): size[0],
                int(mujoco.mjtGeom.mjGEOM_CYLINDER): size[1]}.get(kind, size[2])
        R = np.empty(9)
        mujoco.mju_quat2Mat(R, model.geom_quat[g])
        axis = R.reshape(3, 3)[:, 2]
        for p in (model.geom_pos[g] + half * axis, model.geom_pos[g] - half * axis):
            if np.linalg.norm(p) > np.linalg.norm(best):
                best = p
    return best


def _euler_degrees(q: np.ndarray) -> np.ndarray:
    """(n, 3) Euler angles [deg] (EULER_ORDER, intrinsic) of (n, 4) w x y z rotations, BVH axes."""
    from scipy.spatial.transform import Rotation

    R = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()
    R = MUJOCO_TO_BVH @ R @ MUJOCO_TO_BVH.T
    import warnings

    with warnings.catch_warnings():  # gimbal lock: scipy sets the third angle to 0, still exact
        warnings.simplefilter("ignore", UserWarning)
        ang = Rotation.from_matrix(R).as_euler(EULER_ORDER, degrees=True)
    return np.degrees(np.unwrap(np.radians(ang), axis=0))


def bvh_text(skeleton: Skeleton, qpos: np.ndarray, fps: float) -> str:
    """The BVH file for the motion `qpos` (n, nq) sampled at `fps` [Hz] (module docstring)."""
    qpos = np.asarray(qpos, float)
    fmt = f"{{:.{_DECIMALS}f}}"
    rot_channels = " ".join(f"{a}rotation" for a in EULER_ORDER)
    lines = ["HIERARCHY"]
    children = {i: [c for c in range(skeleton.count) if skeleton.parents[c] == i] for i in range(skeleton.count)}

    def vec(v):
        return " ".join(fmt.format(x) for x in (MUJOCO_TO_BVH @ v) + 0.0)

    def joint(i, depth):
        pad = "  " * depth
        if i == 0:
            lines.append(f"ROOT {skeleton.names[i]}")
            channels = f"CHANNELS 6 Xposition Yposition Zposition {rot_channels}"
        else:
            lines.append(f"{pad}JOINT {skeleton.names[i]}")
            channels = f"CHANNELS 3 {rot_channels}"
        lines.extend([f"{pad}{{", f"{pad}  OFFSET {vec(skeleton.offsets[i])}", f"{pad}  {channels}"])
        for c in children[i]:
            joint(c, depth + 1)
        if i in skeleton.end_sites:
            lines.extend([f"{pad}  End Site", f"{pad}  {{", f"{pad}    OFFSET {vec(skeleton.end_sites[i])}",
                          f"{pad}  }}"])
        lines.append(f"{pad}}}")

    joint(0, 0)
    local = skeleton.local_quat(qpos)  # (n, J, 4)
    angles = np.stack([_euler_degrees(align_hemispheres(local[:, j])) for j in range(skeleton.count)], axis=1)
    pos = qpos[:, skeleton.root_pos] @ MUJOCO_TO_BVH.T
    rows = np.concatenate([pos, angles.reshape(len(qpos), -1)], axis=1) + 0.0  # + 0.0: no "-0.000"
    lines += ["MOTION", f"Frames: {len(qpos)}", f"Frame Time: {1.0 / fps:.{_DECIMALS}f}"]
    lines += [" ".join(fmt.format(x) for x in row) for row in rows]
    return "\n".join(lines) + "\n"


def write_bvh(path: str | Path, model, qpos: np.ndarray, fps: float) -> Skeleton:
    """Write the motion `qpos` (n, nq) of the figure in `model`, sampled at `fps` [Hz], to a .bvh file
    atomically. Returns the skeleton written."""
    from runner.files import atomic_output

    skeleton = figure_skeleton(model)
    text = bvh_text(skeleton, qpos, fps)
    with atomic_output(path) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")
    return skeleton


def is_figure_clip(clip, model) -> bool:
    """True if `clip` (a BvhClip) is on the figure's own skeleton: it has a joint named after every figure
    body (what `write_bvh` writes), so `figure_qpos_from_bvh` reads it exactly, without retargeting."""
    names = set(clip.names)
    return all(n in names for n in figure_skeleton(model, head=False).names)


def figure_qpos_from_bvh(clip, model) -> np.ndarray:
    """The inverse of `write_bvh`: the figure's `qpos` for every frame of a clip on the figure's skeleton.

    Args:
        clip: `runner.bvh_import.BvhClip` (from `read_bvh`) with a joint per figure body, named so.
        model: MjModel holding the figure.
    Returns:
        (n, nq) qpos: root position [m], unit quaternions (w x y z), hemisphere-aligned over time.
    Raises:
        InputError: a figure body is missing from the clip.
    """
    sk = figure_skeleton(model, head=False)  # the fixed neck and head joints carry nothing
    missing = [n for n in sk.names if n not in clip.names]
    if missing:
        raise InputError(f"{clip.source}: no joint(s) {', '.join(missing)}; this clip is not on the figure's "
                         "skeleton (written by `dynsplines export --to FILE.bvh`)")
    idx = [clip.index(n) for n in sk.names]
    n = clip.local_quat.shape[0]
    qpos = np.zeros((n, model.nq))
    qpos[:, sk.root_pos] = clip.local_pos[:, idx[0]] @ MUJOCO_TO_BVH  # v = M^T v'
    for j, c in enumerate(idx):
        q = np.array(clip.local_quat[:, c], float)
        q[:, 1:] = q[:, 1:] @ MUJOCO_TO_BVH  # R = M^T R' M: rotate the axis back
        q = mul(np.broadcast_to(conj(sk.body_quat[j]), q.shape), normalize(q))
        qpos[:, sk.qpos_quat[j]] = align_hemispheres(normalize(q))
    return qpos
