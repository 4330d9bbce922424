"""The small scene the render tests draw: a floor, a light and a one-legged body on a free joint."""
from __future__ import annotations


def one_leg_scene(light: str = "", leg: bool = True, toe_site: bool = False, floor_size: str = "0 0 .1",
                  visual: str = "") -> str:
    """MJCF of a pelvis capsule (0.5 m) on a free joint at 1 m, with (leg=True) a 0.9 m leg capsule on a
    ball joint `hip` (and a `toe` site 5 cm below its end when toe_site), over a plane `floor` of
    MJCF size `floor_size` under one light (extra attributes `light`, e.g. 'directional="true"');
    `visual` is inserted before the worldbody (e.g. an offscreen size)."""
    toe = '\n        <site name="toe" pos=".1 0 -.95"/>' if toe_site else ""
    body = f"""
      <body name="leg">
        <joint name="hip" type="ball"/>
        <geom type="capsule" fromto="0 0 0 0 0 -.9" size=".07" rgba=".6 .6 .6 1"/>{toe}
      </body>""" if leg else ""
    return f"""
<mujoco>{visual}
  <worldbody>
    <light pos="0 0 4" dir="0 0 -1" {light}/>
    <geom name="floor" type="plane" size="{floor_size}" rgba=".3 .4 .5 1"/>
    <body name="pelvis" pos="0 0 1">
      <freejoint name="root"/>
      <geom type="capsule" fromto="0 0 0 0 0 .5" size=".1" rgba=".8 .6 .4 1"/>{body}
    </body>
  </worldbody>
</mujoco>
"""
