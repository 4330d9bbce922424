"""Which components of the state vector are what: the `qpos` layout of a figure.

The spline's state Y(t) is MuJoCo's `qpos` (docs/design.md, "State = MuJoCo qpos"): for the 39-DOF figure
the root position (3), root quaternion (4, w x y z), then one quaternion per ball joint, 51 numbers.
Objective terms need to know which columns are quaternions; keyframe files name joints.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solver.errors import InputError


@dataclass(frozen=True)
class Joint:
    """One named joint's slice of `qpos`.

    Attributes:
        name: joint name (MJCF `name`).
        kind: "free", "ball", "slide" or "hinge".
        qposadr: first index in `qpos`.
        nq: number of `qpos` components (free 7, ball 4, slide/hinge 1).
        dofadr: first index in `qvel`.
        nv: number of `qvel` components (free 6, ball 3, slide/hinge 1).
    """

    name: str
    kind: str
    qposadr: int
    nq: int
    dofadr: int
    nv: int

    @property
    def qpos_slice(self) -> slice:
        return slice(self.qposadr, self.qposadr + self.nq)

    @property
    def quat_index(self) -> np.ndarray | None:
        """(4,) qpos indices of this joint's quaternion, or None for hinge/slide joints."""
        if self.kind == "free":
            return np.arange(self.qposadr + 3, self.qposadr + 7)
        if self.kind == "ball":
            return np.arange(self.qposadr, self.qposadr + 4)
        return None


#: MuJoCo's joint types (mjtJoint codes): (name, qpos size, qvel size) [coordinates]
_KINDS = {0: ("free", 7, 6), 1: ("ball", 4, 3), 2: ("slide", 1, 1), 3: ("hinge", 1, 1)}


@dataclass(frozen=True)
class StateLayout:
    """The layout of the state vector Y (= `qpos`).

    Attributes:
        nq: length of the state vector.
        joints: the named joints, in `qpos` order.
        quat_slots: (s, 4) int array, qpos indices of each quaternion (free root first).
    """

    nq: int
    joints: tuple[Joint, ...]
    quat_slots: np.ndarray

    @classmethod
    def from_model(cls, model) -> StateLayout:
        """Read the layout of a MuJoCo `MjModel` (joint names, types, addresses)."""
        import mujoco

        joints = []
        for j in range(model.njnt):
            kind, nq, nv = _KINDS[int(model.jnt_type[j])]
            name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) or f"joint{j}"
            joints.append(Joint(name, kind, int(model.jnt_qposadr[j]), nq, int(model.jnt_dofadr[j]), nv))
        slots = [jt.quat_index for jt in joints if jt.quat_index is not None]
        quat = np.array(slots, dtype=int).reshape(-1, 4)
        return cls(int(model.nq), tuple(joints), quat)

    @classmethod
    def single_quaternion(cls) -> StateLayout:
        """The layout of one orientation, Y(t) in R^4 (paper sec. 3)."""
        return cls(4, (Joint("orientation", "ball", 0, 4, 0, 3),), np.arange(4).reshape(1, 4))

    @property
    def names(self) -> list[str]:
        return [j.name for j in self.joints]

    def joint(self, name: str) -> Joint:
        """The joint called `name`. Raises InputError listing the valid names."""
        found = find_joint(self.joints, name)
        if found is None:
            raise InputError(f"unknown joint {name!r}; the figure's joints are: {', '.join(self.names)}")
        return found

    @property
    def articulated_dofs(self) -> np.ndarray:
        """(k,) qvel indices of the articulated joints' rotations: ball and hinge joints, not the free
        root and not slides (`solver.change.MeasureOfChange` prices their poses alike)."""
        return np.array([d for j in self.joints if j.kind in ("ball", "hinge")
                         for d in range(j.dofadr, j.dofadr + j.nv)], int)

    @property
    def linear_index(self) -> np.ndarray:
        """qpos indices that are not quaternion components (root position, hinges, slides)."""
        mask = np.ones(self.nq, bool)
        mask[self.quat_slots.ravel()] = False
        return np.flatnonzero(mask)


def site_ids(model, names) -> np.ndarray:
    """Site ids of a MuJoCo model for site names.

    Args:
        model: MjModel. names: site names.
    Returns:
        (k,) int ids.
    Raises:
        InputError: a name the model does not have; lists the model's sites (is the figure included
            in the scene?).
    """
    import mujoco

    ids = []
    for name in names:
        i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)
        if i < 0:
            have = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_SITE, k) for k in range(model.nsite)]
            raise InputError(
                f"the model has no site {name!r} (needed: {', '.join(names)}); its sites are: "
                f"{', '.join(map(str, have)) or 'none'}. Is the figure included in the scene?"
            )
        ids.append(i)
    return np.array(ids, int)


def index_run(idx) -> np.ndarray | slice:
    """`idx` (k,) as a slice if its entries are a run of consecutive indices (indexing then gives views,
    not gathered copies, and assigning through it is plain slicing), else as an int array."""
    idx = np.asarray(idx, int).ravel()
    if len(idx) and np.array_equal(idx, np.arange(idx[0], idx[0] + len(idx))):
        return slice(int(idx[0]), int(idx[0]) + len(idx))
    return idx


def find_joint(joints, name: str) -> Joint | None:
    """The joint called `name` among `joints` (a figure's `Joint`s), or None."""
    return next((j for j in joints if j.name == name), None)
