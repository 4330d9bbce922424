"""Inline MJCF trees for the kinematics and inverse-dynamics tests, and a tangent-space step."""
import re

import mujoco
import numpy as np

from solver.figure import FIGURE_FILE

# Every feature the analytic engine models: a static body carrying a ball joint, body quats, joint
# anchors off the body origin, a welded body, damping and armature, several sites on one body.
ODD = """
<mujoco>
  <option gravity="0 0 -9.81"/>
  <worldbody>
    <geom name="floor" type="plane" size="5 5 .1"/>
    <body name="mount" pos="0 0 3" quat="0.96 0 0 0.28">
      <geom type="sphere" size=".05"/>
      <body name="pendulum" pos="0.1 0 0" quat="0.9 0.1 0.2 0">
        <joint name="swing" type="ball" pos="0 0 0.05" damping="0.3" armature="0.02"/>
        <geom type="capsule" fromto="0 0 0 0 0 -0.3" size="0.03"/>
      </body>
    </body>
    <body name="pelvis" pos="0 0 1">
      <freejoint name="root"/>
      <geom type="box" size=".1 .15 .1" pos=".02 0 .01"/>
      <body name="l_thigh" pos="0 .1 -.1" quat="0.95 0 0.3 0">
        <joint name="l_hip" type="ball" pos="0 0 0.02" damping="0.5" armature="0.05"/>
        <geom type="capsule" fromto="0 0 0 0.02 0 -.4" size=".05"/>
        <body name="l_shoe" pos="0 0 -.45" quat="0.9 0.3 0 0.1">
          <geom type="box" size=".1 .04 .02" pos=".05 0 0"/>
          <site name="l_heel" pos="-.05 0 -.02"/>
          <site name="l_toe" pos=".15 0 -.02"/>
        </body>
      </body>
      <body name="r_thigh" pos="0 -.1 -.1">
        <joint name="r_hip" type="ball"/>
        <geom type="capsule" fromto="0 0 0 0 0 -.45" size=".05"/>
        <site name="r_heel" pos="-.05 0 -.47"/>
        <site name="r_toe" pos=".15 0 -.47"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""

HINGE = """
<mujoco>
  <worldbody>
    <body name="arm" pos="0 0 1">
      <joint name="elbow" type="hinge" axis="0 1 0"/>
      <geom type="capsule" fromto="0 0 0 .3 0 0" size=".03"/>
    </body>
  </worldbody>
</mujoco>
"""


def tangent_step(model, Y, dv):
    """qpos moved along the qvel-space direction dv (n, nv) by mj_integratePos (quaternions normalized)."""
    out = []
    for y, v in zip(Y, dv):
        q = y.copy()
        mujoco.mj_integratePos(model, q, v, 1.0)
        out.append(q)
    return np.array(out)


def scaled_figure_xml(scale: float) -> str:
    """models/humanoid39.xml with every length (pos, fromto, size) times `scale`: another figure, the
    same annotations."""

    def times(m):
        return f'{m.group(1)}="{" ".join(repr(float(x) * scale) for x in m.group(2).split())}"'

    return re.sub(r'(?<=\s)(pos|fromto|size)="([^"]+)"', times, FIGURE_FILE.read_text())
