"""Joint values a person can write: Euler angles or an axis and an angle, in degrees, as a keyframe file
may give them instead of quaternions (docs/keyframe-format.md "Angles in degrees").

A ball joint's value is then an object, one of

    {"euler": [a1, a2, a3], "order": "zxy"}    R = R_z(a1) R_x(a2) R_y(a3): the first axis outermost
    {"axis": [x, y, z], "angle": a}            a rotation by a about the axis (any length > 0)

and the free root's is {"pos": [x, y, z]} plus, optionally, one of those (no rotation: its orientation
is free; a null position component is free). Angles in degrees; `order` is three axis letters (x, y, z,
any case, e.g. "xyz", "ZYX", "xzx"), with R = R_o1(a1) R_o2(a2) R_o3(a3) taking the joint's frame to its
parent's: rotations about the axes of the turning frame in the order written (intrinsic), the BVH channel
convention. Elementary rotations: R_x(a) = [[1, 0, 0], [0, cos a, -sin a], [0, sin a, cos a]] and its
cyclic permutations; the quaternion of R_u(a) is (cos a/2, sin a/2 u), and the product of quaternions
is that of the rotations (Shoemake, "Animating rotation with quaternion curves", SIGGRAPH 1985).
"""
from __future__ import annotations

import math

import numpy as np

from solver.errors import InputError

__all__ = ["joint_components"]

_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
_ROTATION_KEYS = ({"euler", "order"}, {"axis", "angle"})


def _axis_angle(axis, angle_deg: float) -> np.ndarray:
    """(4,) w x y z of the rotation by angle_deg [deg] about the unit vector `axis`."""
    half = math.radians(angle_deg) / 2.0
    return np.array([math.cos(half), *(math.sin(half) * np.asarray(axis, float))])


def _mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a b of two quaternions (w x y z)."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def _numbers(value, n: int, where: str, field: str, example: str) -> list[float]:
    if not (isinstance(value, list) and len(value) == n and all(_finite(v) for v in value)):
        raise InputError(f"{where}: {field} is {value!r}; give {n} numbers, e.g. {example}")
    return [float(v) for v in value]


def _finite(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _rotation(obj: dict, where: str) -> np.ndarray:
    """(4,) the quaternion of an {"euler", "order"} or {"axis", "angle"} object (module docstring)."""
    if "euler" in obj:
        angles = _numbers(obj["euler"], 3, where, "'euler'", "[0, 25, 0] (degrees)")
        order = obj.get("order")
        if not (isinstance(order, str) and len(order) == 3 and all(c in _AXES for c in order.lower())):
            raise InputError(f"{where}: 'order' is {order!r}; give the three axes of 'euler' in order, e.g. "
                             "\"xyz\" (R = Rx Ry Rz, the first outermost)")
        q = np.array([1.0, 0.0, 0.0, 0.0])
        for c, a in zip(order.lower(), angles, strict=True):
            q = _mul(q, _axis_angle(_AXES[c], a))
        return q
    axis = np.array(_numbers(obj.get("axis"), 3, where, "'axis'", "[0, 1, 0]"))
    angle = obj.get("angle")
    if not _finite(angle):
        raise InputError(f"{where}: 'angle' is {angle!r}; give the rotation about 'axis' in degrees, e.g. 25")
    norm = float(np.linalg.norm(axis))
    if norm < 1e-9:
        raise InputError(f"{where}: 'axis' is {obj['axis']!r}; give a direction (not zero), e.g. [0, 1, 0]")
    return _axis_angle(axis / norm, angle)


def joint_components(kind: str, obj: dict, where: str) -> list:
    """The qpos components (None: free) a joint's value object gives (module docstring).

    Args:
        kind: the joint's kind, "free" (7 components: x y z, w x y z) or "ball" (4: w x y z).
        obj: the value as the file gives it (a JSON object). where: the file, keyframe and joint, for messages.
    Returns:
        list of 7 or 4 floats or None.
    Raises:
        InputError: another kind of joint, an unknown or missing field, both or no rotation forms, a
            value that is not numbers, an order that is not three axes, a zero axis.
    """
    allowed = {"pos"} if kind == "free" else set()
    forms = [keys for keys in _ROTATION_KEYS if keys & set(obj)]
    extra = sorted(set(obj) - allowed - set().union(*_ROTATION_KEYS))
    if kind not in ("free", "ball") or extra or len(forms) > 1 or (kind == "ball" and not forms):
        fields = "'pos' and " if kind == "free" else ""
        raise InputError(f"{where}: {obj!r}; a {kind} joint in degrees is an object with {fields}either 'euler' and "
                         "'order' or 'axis' and 'angle', e.g. {\"euler\": [0, 25, 0], \"order\": \"xyz\"} or "
                         "{\"axis\": [0, 1, 0], \"angle\": 25} (docs/keyframe-format.md)")
    quat = list(_rotation(obj, where)) if forms else [None] * 4
    if kind == "ball":
        return quat
    pos = obj.get("pos", [None] * 3)
    if not (isinstance(pos, list) and len(pos) == 3 and all(v is None or _finite(v) for v in pos)):
        raise InputError(f"{where}: 'pos' is {pos!r}; give the root's x y z in metres (null: free), e.g. [0, 0, 1.0]")
    return [None if v is None else float(v) for v in pos] + quat
