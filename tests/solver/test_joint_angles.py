"""Joint values in degrees in a keyframe file (solver/joint_angles.py): Euler angles of any order and an
axis with an angle give the quaternion scipy's Rotation gives (an independent implementation: uppercase
sequences are intrinsic there, as the file's order is), a knee bent 25 degrees about its hinge has that
flexion (2 atan2(v . axis, w), models/README.md), the root takes a position and a rotation, and every
malformed value is one line naming the file, keyframe, joint and the fix."""
import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from solver.errors import InputError
from solver.keyframe_file import FORMAT, read_keyframes
from solver.layout import StateLayout

MODELS = Path(__file__).resolve().parents[2] / "models"


@pytest.fixture(scope="module")
def layout():
    import mujoco

    return StateLayout.from_model(mujoco.MjModel.from_xml_path(str(MODELS / "humanoid39.xml")))


def read(tmp_path, layout, **joints):
    """The keyframes of a file whose keyframe 1 has `joints` (keyframe 0 and 2 fix the root)."""
    root = [0, 0, 1.0, 1, 0, 0, 0]
    doc = {"format": FORMAT, "keyframes": [{"time": 0.0, "joints": {"root": root}},
                                           {"time": 0.5, "joints": joints},
                                           {"time": 1.0, "joints": {"root": root}}]}
    path = tmp_path / "k.json"
    path.write_text(json.dumps(doc))
    return read_keyframes(path, layout)[0]


def same_rotation(q, ref_xyzw):
    """q (w x y z) and scipy's (x y z w) are the same rotation (either sign)."""
    ref = np.array([ref_xyzw[3], *ref_xyzw[:3]])
    return min(np.abs(q - ref).max(), np.abs(q + ref).max()) < 1e-12


@pytest.mark.parametrize("order", ["xyz", "ZYX", "zxy", "yzx", "xzx"])
def test_euler_angles_of_any_order(tmp_path, layout, order):
    angles = [30.0, -50.0, 110.0]
    k = read(tmp_path, layout, l_hip={"euler": angles, "order": order})
    q = k.values[1, layout.joint("l_hip").qpos_slice]
    assert same_rotation(q, Rotation.from_euler(order.upper(), angles, degrees=True).as_quat())


def test_axis_and_angle(tmp_path, layout):
    k = read(tmp_path, layout, torso={"axis": [1, 2, -2], "angle": 40})
    q = k.values[1, layout.joint("torso").qpos_slice]
    assert same_rotation(q, Rotation.from_rotvec(np.radians(40) * np.array([1, 2, -2]) / 3).as_quat())


def test_a_knee_bent_25_degrees(tmp_path, layout):
    k = read(tmp_path, layout, l_knee={"axis": [0, 1, 0], "angle": 25})  # the knee's flexion axis: +y
    w, x, y, z = k.values[1, layout.joint("l_knee").qpos_slice]
    assert abs(np.degrees(2 * np.arctan2(y, w)) - 25.0) < 1e-12 and x == z == 0


def test_the_root_takes_a_position_and_a_rotation(tmp_path, layout):
    k = read(tmp_path, layout, root={"pos": [0.5, None, 1.02], "euler": [0, 0, 90], "order": "xyz"})
    s = layout.joint("root").qpos_slice
    assert k.mask[1, s].tolist() == [True, False, True, True, True, True, True]
    assert np.allclose(k.values[1, s][[0, 2]], [0.5, 1.02])
    assert np.allclose(k.values[1, s][3:], [np.sqrt(0.5), 0, 0, np.sqrt(0.5)], atol=1e-15)
    k = read(tmp_path, layout, root={"pos": [0.5, 0.0, 1.02]})  # no rotation: the orientation is free
    assert k.mask[1, s].tolist() == [True] * 3 + [False] * 4


@pytest.mark.parametrize("value, match", [
    ({"euler": [0, 25, 0]}, r"'order' is None; give the three axes of 'euler' in order"),
    ({"euler": [0, 25, 0], "order": "xyw"}, r"'order' is 'xyw'"),
    ({"euler": [0, 25], "order": "xyz"}, r"'euler' is \[0, 25\]; give 3 numbers"),
    ({"axis": [0, 0, 0], "angle": 25}, r"'axis' is \[0, 0, 0\]; give a direction"),
    ({"axis": [0, 1, 0]}, r"'angle' is None; give the rotation about 'axis' in degrees"),
    ({"axis": [0, 1, 0], "angle": 25, "euler": [0, 0, 0], "order": "xyz"}, r"either 'euler' and 'order' or 'axis'"),
    ({"pos": [0, 0, 1]}, r"a ball joint in degrees is an object with either"),
    ({"angle": 25, "degrees": True}, r"a ball joint in degrees"),
])
def test_a_bad_value_is_one_line(tmp_path, layout, value, match):
    with pytest.raises(InputError, match=r"k\.json: keyframe 1 \(t=0\.5 s\), joint 'l_knee': .*" + match) as e:
        read(tmp_path, layout, l_knee=value)
    assert "\n" not in str(e.value)
