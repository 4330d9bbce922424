"""Clips of postures built by hand (tests/runner/capture/test_postures.py, test_way_back.py, tests/e2e/test_clean.py):
a seated subject, whose level thighs give a knee's flexion no forward swing of the shin to be told by; a
kneeling one, whose feet lie on their tops lower than they stand flat; one who stands up from a chair with
the ankles still; one whose arms are held rounded in front of the body. One skeleton: Y up, Z forward, cm, rest pose standing with
the arms down."""
from pathlib import Path

import numpy as np

#: [1] the share of the kneeling clip's frames standing before it kneels down
STAND = 0.4
#: [deg] the seated clip's knee flexion is KNEE +- SWING, its hips flexed 90 +- SWING / 2, its elbows ELBOW +- SWING
KNEE, ELBOW, SWING = 90.0, 45.0, 10.0

_LEG = """  JOINT {s}UpLeg
  {{
    OFFSET {x} -5 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT {s}Leg
    {{
      OFFSET 0 -42 2
      CHANNELS 3 Zrotation Xrotation Yrotation
      JOINT {s}Foot
      {{
        OFFSET 0 -42 -2
        CHANNELS 3 Zrotation Xrotation Yrotation
        JOINT {s}ToeBase
        {{
          OFFSET 0 -6 12
          CHANNELS 3 Zrotation Xrotation Yrotation
          End Site
          {{
            OFFSET 0 0 5
          }}
        }}
      }}
    }}
  }}
"""
_ARM = """      JOINT {s}Shoulder
      {{
        OFFSET {x1} 12 0
        CHANNELS 3 Zrotation Xrotation Yrotation
        JOINT {s}Arm
        {{
          OFFSET {x2} 0 0
          CHANNELS 3 Zrotation Xrotation Yrotation
          JOINT {s}ForeArm
          {{
            OFFSET 0 -28 0
            CHANNELS 3 Zrotation Xrotation Yrotation
            JOINT {s}Hand
            {{
              OFFSET 0 -25 0
              CHANNELS 3 Zrotation Xrotation Yrotation
              End Site
              {{
                OFFSET 0 -10 0
              }}
            }}
          }}
        }}
      }}
"""


def seated_clip(path: Path, frames: int = 72, fps: float = 24.0, arms_up: bool = False, displaced: float = 0.0) -> Path:
    """Write a seated subject's clip (Y up, Z forward, cm; rest pose standing, arms down): every frame the
    hips at 48 cm, each thigh turned -90 deg about X (level, forward), each knee +KNEE about X (the shin
    down again: flexion), the ankles keeping the feet flat, each elbow -ELBOW about X (flexion: the forearm
    forward of a hanging arm, behind the head of a raised one), all swinging by SWING over the clip so the
    hinges can be measured; the upper arms 20 deg forward of hanging, or with `arms_up` raised overhead (160
    deg forward) the whole clip. With `displaced` [deg] the feet have position channels, as a Perception Neuron
    export "with displacement": each knee's rotation is off by d = displaced x sin(3 x 2 pi f / frames) about X,
    the foot's translation turned back by -d and its rotation by -d, so every joint's world position and
    rotation below the knee is the clip's without them (its known answer), and only the knee's rotation
    no longer points the shin."""
    rows = []
    for f in range(frames):
        s = np.sin(2.0 * np.pi * f / frames)
        hip, knee, elbow = -90.0 + 0.5 * SWING * s, KNEE + SWING * s, -ELBOW + SWING * s
        d = displaced * np.sin(6.0 * np.pi * f / frames)
        if displaced:
            c, n = np.cos(np.radians(-d)), np.sin(np.radians(-d))
            foot = [0.0, -42.0 * c + 2.0 * n, -42.0 * n - 2.0 * c]  # Rx(-d) (0, -42, -2): the foot's OFFSET turned back
            leg = [0, hip, 0, 0, knee + d, 0] + foot + [0, -(hip + knee) - d, 0, 0, 0, 0]
        else:
            leg = [0, hip, 0, 0, knee, 0, 0, -(hip + knee), 0, 0, 0, 0]
        arm = [0, 0, 0, 0, -160.0 if arms_up else -20.0, 0, 0, elbow, 0, 0, 0, 0]
        rows.append([0.5 * s, 48.0, 0.0, 0, 0, 0] + leg + leg + [0] * 12 + arm + arm)
    return _write(path, rows, fps, foot_positions=bool(displaced))


def kneeling_clip(path: Path, frames: int = 96, fps: float = 24.0) -> Path:
    """Write a subject who stands (the first STAND of the frames: legs straight, hips at 95 cm, the toes' base on
    the floor), kneels down (a tenth) and kneels (the rest: thighs upright, each knee +90 deg about X so the shin
    lies back along the floor, each ankle +90 so the foot lies on its top behind it, the ankle 5 cm up, lower than
    a standing foot's 6), the elbows swinging from ELBOW - SWING to ELBOW + SWING throughout."""
    rows = []
    down = int(STAND * frames)
    for f in range(frames):
        k = min(max((f - down) / (0.1 * frames), 0.0), 1.0)  # 0 standing .. 1 kneeling
        leg = [0, 0, 0, 0, 90.0 * k, 0, 0, 90.0 * k, 0, 0, 0, 0]
        elbow = -ELBOW + SWING * np.sin(2.0 * np.pi * f / frames)
        arm = [0, 0, 0, 0, -20.0, 0, 0, elbow, 0, 0, 0, 0]
        rows.append([0.0, 95.0 - 45.0 * k, 0.0, 0, 0, 0] + leg + leg + [0] * 12 + arm + arm)
    return _write(path, rows, fps)


def sit_to_stand_clip(path: Path, fps: float = 30.0, seconds: float = 3.0) -> Path:
    """Write a subject who sits (the first third: hips at 53 cm, thighs level, shins upright, the feet flat on
    the floor), stands up (the second third, the thigh's angle from vertical easing from 90 deg to 0) and stands
    (the last): the feet stay where they are, the hips rise over them and move 42 cm forward, and the ankles
    never turn (the shins stay upright), the elbows swinging from ELBOW - SWING to ELBOW + SWING."""
    rows = []
    n = int(round(seconds * fps))
    for f in range(n):
        k = min(max((f / fps - seconds / 3) / (seconds / 3), 0.0), 1.0)
        th = np.radians(90.0 * (0.5 + 0.5 * np.cos(np.pi * k)))  # the thigh's angle from vertical
        leg = [0, -np.degrees(th), 0, 0, np.degrees(th), 0, 0, 0, 0, 0, 0, 0]
        elbow = -ELBOW + SWING * np.sin(2.0 * np.pi * f / n)
        arm = [0, 0, 0, 0, -20.0, 0, 0, elbow, 0, 0, 0, 0]
        rows.append([0.0, 53.0 + 42.0 * np.cos(th), 30.0 - 42.0 * np.sin(th), 0, 0, 0] + leg + leg + [0] * 12 + arm + arm)
    return _write(path, rows, fps)


def rounded_arms_clip(path: Path, frames: int = 72, fps: float = 24.0) -> Path:
    """Write a standing subject whose arms are held rounded in front of the body, as a dancer's first position:
    each upper arm raised 70 deg forward of hanging and turned 110 deg inwards about its own length, so that the
    elbows, bent ELBOW +- SWING (flexion), carry the forearms across the chest and a little back towards it,
    not forward."""
    rows = []
    for f in range(frames):
        elbow = -ELBOW + SWING * np.sin(2.0 * np.pi * f / frames)
        arms = [[0, 0, 0, 0, -70.0, turn, 0, elbow, 0, 0, 0, 0] for turn in (-110.0, 110.0)]
        rows.append([0.0, 95.0, 0.0, 0, 0, 0] + [0] * 24 + [0] * 12 + arms[0] + arms[1])
    return _write(path, rows, fps)


def _write(path: Path, rows: list, fps: float, foot_positions: bool = False) -> Path:
    """The clip of `rows` (each frame's channel values in HIERARCHY order) at `fps` written to `path`; with
    `foot_positions` the feet's CHANNELS are 6, their position first."""
    spine = ("  JOINT Spine\n  {\n    OFFSET 0 10 0\n    CHANNELS 3 Zrotation Xrotation Yrotation\n"
             "    JOINT Spine1\n    {\n      OFFSET 0 18 0\n      CHANNELS 3 Zrotation Xrotation Yrotation\n"
             "      JOINT Neck\n      {\n        OFFSET 0 22 0\n        CHANNELS 3 Zrotation Xrotation Yrotation\n"
             "        JOINT Head\n        {\n          OFFSET 0 10 0\n          CHANNELS 3 Zrotation Xrotation Yrotation\n"
             "          End Site\n          {\n            OFFSET 0 16 0\n          }\n        }\n      }\n"
             + _ARM.format(s="Left", x1=4, x2=14) + _ARM.format(s="Right", x1=-4, x2=-14) + "    }\n  }\n")
    legs = _LEG.format(s="Left", x=9) + _LEG.format(s="Right", x=-9)
    if foot_positions:
        legs = legs.replace("OFFSET 0 -42 -2\n        CHANNELS 3", "OFFSET 0 -42 -2\n        CHANNELS 6 Xposition Yposition Zposition")
    text = ("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation "
            "Yrotation\n" + legs + spine + "}\n")
    body = "\n".join(" ".join(f"{v:.6f}" for v in r) for r in rows)
    path.write_text(text + f"MOTION\nFrames: {len(rows)}\nFrame Time: {1.0 / fps:.10f}\n{body}\n")
    return path
