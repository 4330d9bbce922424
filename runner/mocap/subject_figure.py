"""The subject's own figure: the shipped figure's topology with the proportions of a CMU clip's skeleton.

`subject_figure_xml(clip)` edits the shipped figure (models/humanoid39.xml) with MuJoCo's `MjSpec`: the
same bodies, joints, sites, materials and `<custom>` annotations (models/README.md, "The figure's
annotations"), with

* **joint centres and segment lengths from the HIERARCHY** (docs/mocap.md, "The subject's figure"): the
  skeleton's rest pose (every channel zero) in metres and MuJoCo axes (`rest_positions`). A body keeps
  the shipped figure's frame convention (parallel to the world at the identity pose: upright, legs
  straight down, arms hanging, feet flat), so a limb segment points along the shipped figure's segment
  with the length of the subject's bone: thigh = |OFFSET of the knee joint|, shin = |OFFSET of the
  ankle|, upper arm = |OFFSET of the elbow|, forearm = |OFFSET of the wrist|. The hips, the torso joint
  and the shoulders sit where the rest skeleton has them relative to the joint of their parent body
  (the joints the figure merges, LHipJoint, LowerBack, Spine, Spine1, LeftShoulder, compose their
  OFFSETs); the foot is the subject's foot at rest (ball of the foot = the toe joint, flat sole);
* **the sole** `ANKLE_HEIGHT` x stature below the ankle, the heel site `HEEL_BACK` x foot length behind
  the ankle, the toe site on the sole under the ball of the foot (where the foot pivots at push-off:
  the figure's foot is rigid and the subject's toes are not), the ball site at the toe joint; then
  both moved to the soles measured on the clip, and the heel rounded to a sphere of the radius measured
  there (`runner.mocap.soles`; written as ``<numeric name="figure:radius:l_heel">``);
* **stature** H from the leg: the hip joint is `HIP_HEIGHT` x H above the sole (Winter 2009, fig. 4.1,
  after Drillis & Contini 1966), so H = (thigh + shin) / (HIP_HEIGHT - ANKLE_HEIGHT);
* **masses** from the shipped figure's segment fractions (de Leva 1996, J. Biomech. 29(9):1223-1230,
  table 4, the male values of the Zatsiorsky-Seluyanov adjustment) times the body mass, default
  `DEFAULT_BMI` x H^2 (the shipped figure's 70 kg at 1.75 m); inertias from the geoms, as in the
  shipped figure;
* **geoms** scaled to the segments (lengths) and to H / 1.75 m (radii).

The figure records the skeleton it was made for (`<text name="subject:skeleton" data="..."/>`, a
digest of the joint names and OFFSETs, `skeleton_digest`): the retargeting of a clip of that skeleton
onto it loses nothing (runner/mocap/retarget.py) and keeps the captured root path.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from runner.mocap.bvh import BvhClip
from solver.contacts import RADIUS_PREFIX
from solver.errors import InputError
from solver.figure import FIGURE_FILE, Figure

__all__ = ["ANKLE_HEIGHT", "HIP_HEIGHT", "HEEL_BACK", "DEFAULT_BMI", "SKELETON_TEXT", "SubjectMeasures",
           "rest_positions", "skeleton_digest", "subject_measures", "subject_figure_xml", "write_subject_figure",
           "figure_skeleton_digest"]

#: ankle joint centre above the sole, and hip joint centre above the sole, as fractions of stature
#: (Winter, "Biomechanics and Motor Control of Human Movement", 4th ed. 2009, fig. 4.1, after Drillis &
#: Contini 1966: 0.039 H and 0.530 H)
ANKLE_HEIGHT = 0.039
HIP_HEIGHT = 0.530
#: foot length as a fraction of stature (de Leva 1996, table 1: 258.1 mm of 1741 mm, male)
FOOT_LENGTH = 258.1 / 1741.0
#: the heel behind the ankle joint centre, as a fraction of the foot length (the shipped figure's 6 cm
#: of its 25 cm foot)
HEEL_BACK = 0.24
#: [kg/m^2] default body mass over stature squared: the shipped figure's 70 kg at 1.75 m
SHIPPED_MASS, SHIPPED_STATURE = 70.0, 1.75
DEFAULT_BMI = SHIPPED_MASS / SHIPPED_STATURE**2
#: the `<custom>` text naming the skeleton a subject figure was made for
SKELETON_TEXT = "subject:skeleton"
_FROM_BVH = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # runner.mocap.retarget.BVH_TO_MUJOCO
_UNIT = 0.0254 / 0.45  # runner.mocap.retarget.UNIT_TO_METRES

#: figure body -> the CMU joint at its joint centre
BODY_JOINT = {"pelvis": "Hips", "l_thigh": "LeftUpLeg", "l_shin": "LeftLeg", "l_foot": "LeftFoot",
              "r_thigh": "RightUpLeg", "r_shin": "RightLeg", "r_foot": "RightFoot", "torso": "LowerBack",
              "l_upper_arm": "LeftArm", "l_forearm": "LeftForeArm", "r_upper_arm": "RightArm",
              "r_forearm": "RightForeArm"}
#: limb bodies: (the CMU joint where the segment ends, the shipped figure's segment direction)
LIMBS = {"l_thigh": "LeftLeg", "l_shin": "LeftFoot", "r_thigh": "RightLeg", "r_shin": "RightFoot",
         "l_upper_arm": "LeftForeArm", "l_forearm": "LeftHand", "r_upper_arm": "RightForeArm",
         "r_forearm": "RightHand"}
_DOWN = np.array([0.0, 0.0, -1.0])
#: the joints whose OFFSET is a length the figure needs (a zero one is refused): the leg and arm bones,
#: the foot, and the hip and shoulder offsets from the body centre
NEEDED = ("LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase", "RightUpLeg", "RightLeg", "RightFoot",
          "RightToeBase", "LeftArm", "LeftForeArm", "LeftHand", "RightArm", "RightForeArm", "RightHand",
          "Spine", "Neck1", "Head")
#: shipped figure: its segment lengths [m] (thigh, shin, upper arm, forearm), for scaling geoms along them
_SHIPPED_LENGTH = {"thigh": 0.42, "shin": 0.42, "upper_arm": 0.29, "forearm": 0.24}


@dataclass(frozen=True)
class SubjectMeasures:
    """What the figure takes from a skeleton (metres, MuJoCo axes, rest pose: every channel zero).

    Attributes:
        rest: {CMU joint: (3,) position relative to the Hips}; End Sites as "<joint>/end".
        stature: H [m]. mass: [kg]. ankle_height: [m] ankle joint centre above the sole.
        foot_length: [m] heel to toe tip.
        pelvis_height: [m] the Hips above the soles at the figure's identity pose (legs straight down;
            the mean of both legs).
    """

    rest: dict
    stature: float
    mass: float
    ankle_height: float
    foot_length: float
    pelvis_height: float


def rest_positions(clip: BvhClip) -> dict:
    """{joint name: (3,) rest position [m], MuJoCo axes, relative to the root}, End Sites as "NAME/end".

    Forward kinematics of the OFFSETs with every rotation channel zero (the BVH rest pose), in metres
    (1 unit = 0.0254 / 0.45 m) and MuJoCo axes ((x, y, z) = (Z, X, Y) of BVH).
    """
    off = clip.offsets @ _FROM_BVH.T * _UNIT
    pos: list[np.ndarray] = []
    for j, par in enumerate(clip.parents):
        pos.append(off[j] + pos[par] if par >= 0 else np.zeros(3))
    out = {name: pos[j] for j, name in enumerate(clip.names)}
    for j, end in clip.end_sites.items():
        out[f"{clip.names[j]}/end"] = pos[j] + _FROM_BVH @ np.asarray(end, float) * _UNIT
    return out


def skeleton_digest(clip: BvhClip) -> str:
    """A digest of the skeleton's joint names, parents and OFFSETs (rounded to 1e-5 units): equal for
    two clips of one subject's skeleton, different for another's."""
    h = hashlib.sha1()
    for name, par, off in zip(clip.names, clip.parents, np.round(clip.offsets, 5) + 0.0, strict=True):
        h.update(f"{name}:{par}:{off[0]:.5f},{off[1]:.5f},{off[2]:.5f};".encode())
    return h.hexdigest()[:16]


def figure_skeleton_digest(model) -> str | None:
    """The skeleton digest a subject figure records (`SKELETON_TEXT`), or None (another figure)."""
    import mujoco

    i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_TEXT, SKELETON_TEXT)
    if i < 0:
        return None
    adr, size = int(model.text_adr[i]), int(model.text_size[i])
    return bytes(model.text_data[adr:adr + size]).split(b"\0")[0].decode().strip()


def _check_lengths(clip: BvhClip) -> None:
    """InputError naming the file and the joint if an OFFSET the figure needs has zero length."""
    from runner.mocap.retarget import check_skeleton

    check_skeleton(clip)
    missing = [j for j in NEEDED if j not in clip.names]
    if missing:
        raise InputError(f"{clip.source}: the skeleton has no joint(s) {', '.join(missing)}; the subject's figure "
                         "needs the CMU skeleton (the cgspeed BVH conversion of mocap.cs.cmu.edu); use --figure default")
    for j in NEEDED:
        if np.linalg.norm(clip.offsets[clip.index(j)]) * _UNIT < 1e-3:
            raise InputError(f"{clip.source}: joint {j} has a zero-length OFFSET "
                             f"({' '.join(f'{v:g}' for v in clip.offsets[clip.index(j)])}), so the bone that ends "
                             "there has no length; fix the HIERARCHY or use --figure default")


def subject_measures(clip: BvhClip, mass: float | None = None) -> SubjectMeasures:
    """The stature, mass and foot of the subject of `clip` (module docstring).

    Args:
        clip: a parsed CMU clip. mass: [kg] body mass, > 0 (None: `DEFAULT_BMI` x stature^2).
    Raises:
        InputError: not the CMU skeleton, a needed OFFSET of zero length, a bad mass.
    """
    _check_lengths(clip)
    rest = rest_positions(clip)
    legs = [np.linalg.norm(rest[f"{s}Leg"] - rest[f"{s}UpLeg"]) + np.linalg.norm(rest[f"{s}Foot"] - rest[f"{s}Leg"])
            for s in ("Left", "Right")]
    stature = float(np.mean(legs)) / (HIP_HEIGHT - ANKLE_HEIGHT)
    if mass is None:
        mass = DEFAULT_BMI * stature**2
    if not (np.isfinite(mass) and mass > 0):
        raise InputError(f"--mass {mass}: give the body mass in kilograms, a number > 0")
    ankle = ANKLE_HEIGHT * stature
    pelvis = ankle + float(np.mean([legs[i] - rest[f"{s}UpLeg"][2] for i, s in enumerate(("Left", "Right"))]))
    return SubjectMeasures(rest, stature, float(mass), ankle, FOOT_LENGTH * stature, pelvis)


def _swing(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(3, 3) the smallest rotation taking direction a to direction b (Rodrigues)."""
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    v, c = np.cross(a, b), float(a @ b)
    if c < -1.0 + 1e-12:
        raise InputError("a bone of the skeleton points straight up at rest; the subject's figure needs the CMU "
                         "rest pose (legs down, arms out)")
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + c)


def _rest_rotations(rest: dict) -> dict:
    """{body: (3, 3)} rotation from the figure body's frame at the identity pose to the body's pose in the
    skeleton's rest pose: a limb's segment direction (straight down) to the bone's rest direction;
    the identity for the pelvis, torso and feet (their rest poses are the figure's)."""
    rot = {b: np.eye(3) for b in BODY_JOINT}
    for body, end in LIMBS.items():
        rot[body] = _swing(_DOWN, rest[end] - rest[BODY_JOINT[body]])
    return rot


def _local(rest: dict, rot: dict, body: str, point: np.ndarray) -> np.ndarray:
    """A rest-pose point [m] in the frame of `body` at the figure's identity pose."""
    return rot[body].T @ (np.asarray(point, float) - rest[BODY_JOINT[body]])


def subject_figure_xml(clip: BvhClip, mass: float | None = None, soles: bool = True) -> str:
    """The MJCF text of the subject's figure of `clip` (module docstring), made with `mujoco.MjSpec`
    from the shipped figure.

    Args:
        clip: a parsed CMU clip. mass: [kg] body mass (None: from the stature, `subject_measures`).
    Returns:
        the MJCF text (loads on its own; a scene includes it like models/humanoid39.xml).
    Raises:
        InputError: the skeleton is not the CMU one, or a needed OFFSET has zero length (file and
            joint named).
    """
    import mujoco

    m = subject_measures(clip, mass)
    rest, rot, s = m.rest, _rest_rotations(m.rest), m.stature / SHIPPED_STATURE
    spec = mujoco.MjSpec.from_file(str(FIGURE_FILE))
    spec.modelname = f"subject_{Path(clip.source).stem}"
    spec.visual.quality.shadowsize = 4096
    for name, parent in (("l_thigh", "pelvis"), ("r_thigh", "pelvis"), ("l_shin", "l_thigh"), ("r_shin", "r_thigh"),
                         ("l_foot", "l_shin"), ("r_foot", "r_shin"), ("torso", "pelvis"),
                         ("l_upper_arm", "torso"), ("r_upper_arm", "torso"), ("l_forearm", "l_upper_arm"),
                         ("r_forearm", "r_upper_arm")):
        spec.body(name).pos = _local(rest, rot, parent, rest[BODY_JOINT[name]])
    for side, cmu in (("l", "Left"), ("r", "Right")):
        _leg(spec, side, cmu, m, rot, s)
        _arm(spec, side, cmu, m, rot, s)
    _trunk(spec, m, rot, s)
    spec.body("pelvis").pos = [0.0, 0.0, m.pelvis_height]  # the identity pose stands on z = 0
    for g in spec.geoms:
        g.mass = g.mass * m.mass / SHIPPED_MASS
    if soles:
        _fit_soles(spec, clip, m)
    spec.add_text(name=SKELETON_TEXT, data=skeleton_digest(clip))
    return spec.to_xml()


def _capsule(spec, name: str, a, b, radius: float) -> None:
    g = spec.geom(name)
    g.fromto = np.r_[a, b]
    g.size = [radius, 0.0, 0.0]


def _leg(spec, side: str, cmu: str, m: SubjectMeasures, rot: dict, s: float) -> None:
    """Thigh, shin and foot geoms; the foot's sites (module docstring)."""
    rest = m.rest
    for body, length, key, radius in ((f"{side}_thigh", f"{cmu}Leg", "thigh", 0.068),
                                      (f"{side}_shin", f"{cmu}Foot", "shin", 0.048)):
        L = float(np.linalg.norm(rest[length] - rest[BODY_JOINT[body]]))
        k = L / _SHIPPED_LENGTH[key]
        lo, hi = (0.03, 0.39) if key == "thigh" else (0.02, 0.38)
        _capsule(spec, body, [0, 0, -lo * k], [0, 0, -hi * k], radius * s)
    foot = f"{side}_foot"
    ball = _local(rest, rot, foot, rest[f"{cmu}ToeBase"])
    forward = np.r_[ball[:2], 0.0] / np.linalg.norm(ball[:2])
    h = m.ankle_height
    heel = -HEEL_BACK * m.foot_length * forward + [0, 0, -h]
    toe = np.r_[ball[:2], -h]
    spec.site(f"{side}_ball").pos = ball
    _sole(spec, side, heel, toe, h / 2)


def _sole(spec, side: str, heel: np.ndarray, toe: np.ndarray, r: float, heel_radius: float = 0.0,
          toe_radius: float = 0.0) -> None:
    """The foot's heel and toe sites at `heel`, `toe` (foot frame [m]; the centres of their spheres of the
    given radii [m]) and its capsule of radius r over the sole under them."""
    spec.site(f"{side}_heel").pos = heel
    spec.site(f"{side}_toe").pos = toe
    heel = heel - [0, 0, heel_radius]  # the sole: the spheres' lowest points with the foot flat
    toe = toe - [0, 0, toe_radius]
    forward = np.r_[toe[:2] - heel[:2], 0.0]
    forward /= np.linalg.norm(forward)
    _capsule(spec, f"{side}_foot", heel + r * forward + [0, 0, r], toe - 0.5 * r * forward + [0, 0, r], r)


def _fit_soles(spec, clip: BvhClip, m: SubjectMeasures) -> None:
    """Move the heel and toe sites (and the foot capsules) to the subject's soles measured on the clip
    (`runner.mocap.soles.fit_soles`); the published places stay if the feet never rest long enough."""
    from runner.mocap.retarget import clamp_hyperextension, retarget
    from runner.mocap.soles import fit_soles
    from solver.layout import StateLayout

    model = spec.compile()
    figure = Figure.from_model(model)
    qpos, _ = clamp_hyperextension(retarget(clip, figure, StateLayout.from_model(model))[1:], figure)
    tips = {}
    for foot, (heel, _) in figure.feet.items():
        cmu = "Left" if heel.startswith("l") else "Right"
        end = m.rest.get(f"{cmu}ToeBase/end", m.rest[f"{cmu}ToeBase"])
        tips[foot] = end - m.rest[f"{cmu}Foot"]  # the foot's frame is parallel to the rest pose's
    try:
        fit = fit_soles(model, qpos, clip.frame_time, tips)
    except InputError:  # the feet never rest: nothing to measure
        return
    for heel, toe in figure.feet.values():
        _sole(spec, heel[0], fit.sites[heel], fit.sites[toe], m.ankle_height / 2, fit.radii[heel], fit.radii[toe])
        for site in (heel, toe):
            if fit.radii[site] > 0:
                spec.add_numeric(name=RADIUS_PREFIX + site, data=[float(fit.radii[site])])


def _arm(spec, side: str, cmu: str, m: SubjectMeasures, rot: dict, s: float) -> None:
    """Upper arm, forearm and hand geoms; the wrist site."""
    rest = m.rest
    for body, end, key, lo, hi, radius in ((f"{side}_upper_arm", f"{cmu}ForeArm", "upper_arm", 0.02, 0.27, 0.043),
                                           (f"{side}_forearm", f"{cmu}Hand", "forearm", 0.02, 0.23, 0.036)):
        L = float(np.linalg.norm(rest[end] - rest[BODY_JOINT[body]]))
        k = L / _SHIPPED_LENGTH[key]
        _capsule(spec, body, [0, 0, -lo * k], [0, 0, -hi * k], radius * s)
    fore = f"{side}_forearm"
    wrist = _local(rest, rot, fore, rest[f"{cmu}Hand"])
    spec.site(f"{side}_wrist").pos = wrist
    hand = spec.geom(f"{side}_hand")
    hand.pos = wrist + [0, 0, -0.08 * s]
    hand.size = np.array([0.045, 0.025, 0.07]) * s


def _trunk(spec, m: SubjectMeasures, rot: dict, s: float) -> None:
    """Pelvis, belly, chest, neck and head geoms; the head site (top of the head)."""
    rest = m.rest
    hip_y = 0.5 * abs(rest["LeftUpLeg"][1] - rest["RightUpLeg"][1])
    hip_z = 0.5 * (rest["LeftUpLeg"][2] + rest["RightUpLeg"][2])
    _capsule(spec, "pelvis", [0, -0.83 * hip_y, 0.45 * hip_z], [0, 0.83 * hip_y, 0.45 * hip_z], 0.095 * s)
    shoulder = 0.5 * (_local(rest, rot, "torso", rest["LeftArm"]) + _local(rest, rot, "torso", rest["RightArm"]))
    neck = _local(rest, rot, "torso", rest["Neck"])
    skull = _local(rest, rot, "torso", rest["Head"])
    # belly and chest at the shipped figure's heights, as fractions of the shoulder height above the torso joint
    for name, z, half, radius in (("belly", 0.04 / 0.34, 0.06, 0.10), ("chest", 0.24 / 0.34, 0.07, 0.11)):
        c = np.r_[0.0, 0.0, z * shoulder[2]]
        _capsule(spec, name, c - [0, half * s, 0], c + [0, half * s, 0], radius * s)
    _capsule(spec, "neck", neck, skull, 0.045 * s)
    # the head from the base of the skull to the top of the head: stature above the sole at the identity pose
    top_z = m.stature - m.pelvis_height  # above the torso joint (at the Hips)
    top = np.r_[skull[:2], max(top_z, skull[2] + 0.1 * s)]
    spec.site("head").pos = top
    head = spec.geom("head")
    head.pos = 0.5 * (skull + top)
    head.size = [0.10 * s, 0.085 * s, 0.5 * (top[2] - skull[2])]


def write_subject_figure(clip: BvhClip, out: str | Path, mass: float | None = None) -> Path:
    """Write the subject's figure of `clip` (`subject_figure_xml`) to `out` atomically; returns `out`.

    Raises:
        InputError: as `subject_figure_xml`; the folder is missing or the file cannot be written.
    """
    from runner.files import atomic_output

    out = Path(out)
    if not out.parent.is_dir():
        raise InputError(f"{out}: the folder {out.parent} does not exist; create it first")
    text = subject_figure_xml(clip, mass)
    try:
        with atomic_output(out, suffix=".xml") as tmp:
            Path(tmp).write_text(text, encoding="utf-8")
    except OSError as e:
        raise InputError(f"cannot write {out}: {e.strerror or e}; choose another output folder") from None
    return out
