"""The subject's own figure: the shipped figure's topology with the proportions of a clip's skeleton.

`subject_figure_xml(clip)` edits the shipped figure (models/humanoid39.xml) with MuJoCo's `MjSpec`: the
same bodies, joints, sites, materials and `<custom>` annotations (models/README.md, "The figure's
annotations"), with

* **joint centres and segment lengths from the skeleton** (docs/mocap.md, "The subject's figure"): the
  recognised skeleton (runner/capture/skeleton.py) and the figure's bodies measured on it
  (runner/capture/body_frames.py: each body's frame on its driving joint and the mean places, in that
  frame, of the joints it carries, in metres and MuJoCo axes). A body keeps the shipped figure's frame
  convention (parallel to the world at the identity pose: upright, legs straight down, arms hanging,
  feet flat), so a limb segment points along the shipped figure's segment with the length of the
  subject's bone (thigh = hip to knee joint, shin = knee to ankle, upper arm = shoulder to elbow,
  forearm = elbow to wrist). The hips, the torso joint (at the spine joint above the hips) and the
  shoulders sit at their mean places on the pelvis and the torso (exact where the source's joints
  between them do not move); the foot is the subject's foot (ball of the foot = the toe joint, flat
  sole; a foot the skeleton gives no length points forward as it stands at rest, `BALL_AHEAD` of the foot
  length to its ball: `runner.capture.body_frames.rest_forward`);
* **the sole** `ANKLE_HEIGHT` x stature below the ankle, the heel site `HEEL_BACK` x foot length behind
  the ankle, the toe site on the sole under the ball of the foot (where the foot pivots at push-off:
  the figure's foot is rigid and the subject's toes are not), the ball site at the toe joint; then
  both moved to the soles measured on the clip, and the heel rounded to a sphere of the radius measured
  there (`runner.capture.soles`; written as ``<numeric name="figure:radius:l_heel">``);
* **stature** H from the leg: the hip joint is `HIP_HEIGHT` x H above the sole (Winter 2009, fig. 4.1,
  after Drillis & Contini 1966), so H = (thigh + shin) / (HIP_HEIGHT - ANKLE_HEIGHT);
* **masses** from the shipped figure's segment fractions (de Leva 1996, J. Biomech. 29(9):1223-1230,
  table 4, the male values of the Zatsiorsky-Seluyanov adjustment) times the body mass, default
  `DEFAULT_BMI` x H^2 (the shipped figure's 70 kg at 1.75 m); inertias from the geoms, as in the
  shipped figure;
* **geoms** scaled to the segments (lengths) and to H / 1.75 m (radii).

The figure records the skeleton it was made for (runner/capture/figure_record.py: a digest of the joint
names and OFFSETs, the recognised roles, unit and up axis, and each body's frame on its joint): the
retargeting of a clip of that skeleton onto it loses nothing (runner/capture/retarget.py) and keeps the
captured root path, and the export onto the source skeleton undoes it.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from runner.capture.body_frames import MIN_FOOT, BodyFrames, body_frames
from runner.capture.bvh import BvhClip
from runner.capture.figure_record import write_record
from runner.capture.skeleton import RecognisedSkeleton, recognise
from runner.capture.skeleton_map import SkeletonMap
from solver.contacts import RADIUS_PREFIX
from solver.errors import InputError
from solver.figure import FIGURE_FILE, Figure, shipped_figure

__all__ = ["ANKLE_HEIGHT", "HIP_HEIGHT", "HEEL_BACK", "DEFAULT_BMI", "SubjectMeasures", "subject_measures",
           "subject_figure_xml", "write_subject_figure"]

#: ankle joint centre above the sole, and hip joint centre above the sole, as fractions of stature
#: (Winter, "Biomechanics and Motor Control of Human Movement", 4th ed. 2009, fig. 4.1, after Drillis &
#: Contini 1966: 0.039 H and 0.530 H)
ANKLE_HEIGHT = 0.039
HIP_HEIGHT = 0.530
#: foot length as a fraction of stature (de Leva 1996, table 1: 258.1 mm of 1741 mm, male)
FOOT_LENGTH = 258.1 / 1741.0
#: foot breadth (across the ball of the foot) as a fraction of stature (Winter 2009, fig. 4.1: 0.055 H): the
#: soles' edge sites lie half of it either side of the sole's line at the ball
FOOT_BREADTH = 0.055
#: the heel behind the ankle joint centre, as a fraction of the foot length (the shipped figure's 6 cm
#: of its 25 cm foot)
HEEL_BACK = 0.24
#: the ball of the foot ahead of the ankle joint centre, as a fraction of the foot length, for a skeleton that gives
#: the foot no length (no toe joint, its End Site at the ankle): the shipped figure's 13 cm on its 26 cm foot
BALL_AHEAD = 0.5
#: [kg/m^2] default body mass over stature squared: the shipped figure's 70 kg at 1.75 m
SHIPPED_MASS, SHIPPED_STATURE = 70.0, 1.75
DEFAULT_BMI = SHIPPED_MASS / SHIPPED_STATURE**2
#: [m] a neck shorter than this (a skeleton without a neck joint: the head's joint at the neck's base)
#: is drawn from the shoulders' midpoint instead
_MIN_NECK = 0.01
#: shipped figure: its segment lengths [m] (thigh, shin, upper arm, forearm), for scaling geoms along them
_SHIPPED_LENGTH = {"thigh": 0.42, "shin": 0.42, "upper_arm": 0.29, "forearm": 0.24}


@dataclass(frozen=True)
class SubjectMeasures:
    """What the figure takes from a skeleton (metres, MuJoCo axes).

    Attributes:
        skeleton: the recognised skeleton. frames: the figure's bodies measured on the clip (their
            frames and the places of the joints they carry, `BodyFrames.points`).
        stature: H [m]. mass: [kg]. ankle_height: [m] ankle joint centre above the sole.
        foot_length: [m] heel to toe tip.
        pelvis_height: [m] the hips above the soles at the figure's identity pose (legs straight down;
            the mean of both legs).
    """

    skeleton: RecognisedSkeleton
    frames: BodyFrames
    stature: float
    mass: float
    ankle_height: float
    foot_length: float
    pelvis_height: float

    @property
    def points(self):
        return self.frames.points


def subject_measures(clip: BvhClip, mass: float | None = None, skeleton_map: SkeletonMap | None = None) -> SubjectMeasures:
    """The skeleton, stature, mass and foot of the subject of `clip` (module docstring).

    Args:
        clip: a parsed clip. mass: [kg] body mass, > 0 (None: `DEFAULT_BMI` x stature^2).
        skeleton_map: roles, unit or up axis that win over the recognised ones (None: none).
    Raises:
        InputError: the skeleton cannot be recognised (roles named), a bone of zero length (joint named),
            a bad mass.
    """
    skel = recognise(clip, skeleton_map)
    frames = body_frames(clip, skel, shipped_figure())
    P = frames.points
    legs = [np.linalg.norm(P[f"{s}_thigh"]["end"]) + np.linalg.norm(P[f"{s}_shin"]["end"]) for s in "lr"]
    stature = float(np.mean(legs)) / (HIP_HEIGHT - ANKLE_HEIGHT)
    if mass is None:
        mass = DEFAULT_BMI * stature**2
    if not (np.isfinite(mass) and mass > 0):
        raise InputError(f"--mass {mass}: give the body mass in kilograms, a number > 0")
    ankle = ANKLE_HEIGHT * stature
    pelvis = ankle + float(np.mean([legs[i] - P["pelvis"][f"{s}_thigh"][2] for i, s in enumerate("lr")]))
    return SubjectMeasures(skel, frames, stature, float(mass), ankle, FOOT_LENGTH * stature, pelvis)


def subject_figure_xml(clip: BvhClip, mass: float | None = None, soles: bool = True,
                       skeleton_map: SkeletonMap | None = None) -> str:
    """The MJCF text of the subject's figure of `clip` (module docstring), made with `mujoco.MjSpec`
    from the shipped figure.

    Args:
        clip: a parsed clip. mass: [kg] body mass (None: from the stature, `subject_measures`).
        soles: measure the soles on the clip (False: the published places). skeleton_map: roles, unit or
            up axis that win over the recognised ones.
    Returns:
        the MJCF text (loads on its own; a scene includes it like models/humanoid39.xml).
    Raises:
        InputError: the skeleton cannot be recognised (roles named), or a bone has zero length (file
            and joint named).
    """
    import mujoco

    m = subject_measures(clip, mass, skeleton_map)
    P, s = m.points, m.stature / SHIPPED_STATURE
    spec = mujoco.MjSpec.from_file(str(FIGURE_FILE))
    spec.modelname = f"subject_{Path(clip.source).stem}"
    spec.visual.quality.shadowsize = 4096
    for side in "lr":
        spec.body(f"{side}_thigh").pos = P["pelvis"][f"{side}_thigh"]
        spec.body(f"{side}_upper_arm").pos = P["torso"][f"{side}_upper_arm"]
        for body, parent in (("shin", "thigh"), ("foot", "shin"), ("forearm", "upper_arm")):
            spec.body(f"{side}_{body}").pos = P[f"{side}_{parent}"]["end"]
        _leg(spec, side, m, s)
        _arm(spec, side, m, s)
    spec.body("torso").pos = P["pelvis"]["torso"]
    _trunk(spec, m, s)
    spec.body("pelvis").pos = [0.0, 0.0, m.pelvis_height]  # the identity pose stands on z = 0
    for g in spec.geoms:
        g.mass = g.mass * m.mass / SHIPPED_MASS
    if soles:
        _fit_soles(spec, clip, m)
    write_record(spec, clip, m.skeleton, m.frames)
    return spec.to_xml()


def _capsule(spec, name: str, a, b, radius: float) -> None:
    g = spec.geom(name)
    g.fromto = np.r_[a, b]
    g.size = [radius, 0.0, 0.0]


def _leg(spec, side: str, m: SubjectMeasures, s: float) -> None:
    """Thigh, shin and foot geoms; the foot's sites (module docstring)."""
    for body, key, radius in ((f"{side}_thigh", "thigh", 0.068), (f"{side}_shin", "shin", 0.048)):
        k = float(np.linalg.norm(m.points[body]["end"])) / _SHIPPED_LENGTH[key]
        lo, hi = (0.03, 0.39) if key == "thigh" else (0.02, 0.38)
        _capsule(spec, body, [0, 0, -lo * k], [0, 0, -hi * k], radius * s)
    ball = np.array(m.points[f"{side}_foot"]["ball"], float)
    h = m.ankle_height
    if np.linalg.norm(ball[:2]) < MIN_FOOT:  # the skeleton gives the foot no length: the figure's ball on its frame's x
        ball = np.array([BALL_AHEAD * m.foot_length, 0.0, -0.5 * h])
    forward = np.r_[ball[:2], 0.0] / np.linalg.norm(ball[:2])
    heel = -HEEL_BACK * m.foot_length * forward + [0, 0, -h]
    toe = np.r_[ball[:2], -h]
    spec.site(f"{side}_ball").pos = ball
    _sole(spec, side, heel, toe, h / 2, FOOT_BREADTH * m.stature)


def _sole(spec, side: str, heel: np.ndarray, toe: np.ndarray, r: float, breadth: float, heel_radius: float = 0.0,
          toe_radius: float = 0.0) -> None:
    """The foot's heel and toe sites at `heel`, `toe` (foot frame [m]; the centres of their spheres of the
    given radii [m]), its capsule of radius r over the sole under them, and the sole's edge sites (inner
    and outer: ``figure:sole:SIDE``) `breadth` [m] apart across the sole's line under the ball site."""
    spec.site(f"{side}_heel").pos = heel
    spec.site(f"{side}_toe").pos = toe
    heel = heel - [0, 0, heel_radius]  # the sole: the spheres' lowest points with the foot flat
    toe = toe - [0, 0, toe_radius]
    forward = np.r_[toe[:2] - heel[:2], 0.0]
    length = np.linalg.norm(forward)
    forward /= length
    _capsule(spec, f"{side}_foot", heel + r * forward + [0, 0, r], toe - 0.5 * r * forward + [0, 0, r], r)
    a = np.clip(float(np.asarray(spec.site(f"{side}_ball").pos)[:2] @ forward[:2] - heel[:2] @ forward[:2]) / length, 0.0, 1.0)
    at = heel + a * (toe - heel)  # the sole's line under the ball
    inward = np.cross([0.0, 0.0, 1.0], forward) * (-1.0 if side == "l" else 1.0)  # toward the body's midline
    spec.site(f"{side}_sole_in").pos = at + 0.5 * breadth * inward
    spec.site(f"{side}_sole_out").pos = at - 0.5 * breadth * inward


def _fit_soles(spec, clip: BvhClip, m: SubjectMeasures) -> None:
    """Move the heel and toe sites (and the foot capsules) to the subject's soles measured on the clip
    (`runner.capture.soles.fit_soles`); the published places stay if the feet never rest long enough."""
    from runner.capture.retarget import clamp_hyperextension, retarget
    from runner.capture.soles import fit_soles
    from solver.layout import StateLayout

    model = spec.compile()
    figure = Figure.from_model(model)
    qpos = retarget(clip, m.skeleton, m.frames, figure, StateLayout.from_model(model))[m.skeleton.rest_frames:]
    qpos, _ = clamp_hyperextension(qpos, figure)
    tips = {foot: np.array(m.points[f"{heel[0]}_foot"]["tip"], float) for foot, (heel, _) in figure.feet.items()}
    try:
        fit = fit_soles(model, qpos, clip.frame_time, tips)
    except InputError:  # the feet never rest: nothing to measure
        return
    for heel, toe in figure.feet.values():
        _sole(spec, heel[0], fit.sites[heel], fit.sites[toe], m.ankle_height / 2, FOOT_BREADTH * m.stature,
              fit.radii[heel], fit.radii[toe])
        for site in (heel, toe):
            if fit.radii[site] > 0:
                spec.add_numeric(name=RADIUS_PREFIX + site, data=[float(fit.radii[site])])


def _arm(spec, side: str, m: SubjectMeasures, s: float) -> None:
    """Upper arm, forearm and hand geoms; the wrist site."""
    for body, key, lo, hi, radius in ((f"{side}_upper_arm", "upper_arm", 0.02, 0.27, 0.043),
                                      (f"{side}_forearm", "forearm", 0.02, 0.23, 0.036)):
        k = float(np.linalg.norm(m.points[body]["end"])) / _SHIPPED_LENGTH[key]
        _capsule(spec, body, [0, 0, -lo * k], [0, 0, -hi * k], radius * s)
    wrist = np.array(m.points[f"{side}_forearm"]["end"], float)
    spec.site(f"{side}_wrist").pos = wrist
    hand = spec.geom(f"{side}_hand")
    hand.pos = wrist + [0, 0, -0.08 * s]
    hand.size = np.array([0.045, 0.025, 0.07]) * s


def _trunk(spec, m: SubjectMeasures, s: float) -> None:
    """Pelvis, belly, chest, neck and head geoms; the head site (top of the head)."""
    pelvis, torso = m.points["pelvis"], m.points["torso"]
    hip_y = 0.5 * abs(pelvis["l_thigh"][1] - pelvis["r_thigh"][1])
    hip_z = 0.5 * (pelvis["l_thigh"][2] + pelvis["r_thigh"][2])
    _capsule(spec, "pelvis", [0, -0.83 * hip_y, 0.45 * hip_z], [0, 0.83 * hip_y, 0.45 * hip_z], 0.095 * s)
    shoulder = 0.5 * (torso["l_upper_arm"] + torso["r_upper_arm"])
    skull = np.array(torso["skull"], float)
    neck = np.array(torso["neck"], float)
    if np.linalg.norm(skull - neck) < _MIN_NECK:
        neck = np.r_[skull[:2], shoulder[2]]
    # belly and chest at the shipped figure's heights, as fractions of the shoulder height above the torso joint
    for name, z, half, radius in (("belly", 0.04 / 0.34, 0.06, 0.10), ("chest", 0.24 / 0.34, 0.07, 0.11)):
        c = np.r_[0.0, 0.0, z * shoulder[2]]
        _capsule(spec, name, c - [0, half * s, 0], c + [0, half * s, 0], radius * s)
    _capsule(spec, "neck", neck, skull, 0.045 * s)
    # the head from the base of the skull to the top of the head: stature above the sole at the identity pose
    top_z = m.stature - m.pelvis_height - pelvis["torso"][2]  # above the torso joint
    top = np.r_[skull[:2], max(top_z, skull[2] + 0.1 * s)]
    spec.site("head").pos = top
    head = spec.geom("head")
    head.pos = 0.5 * (skull + top)
    head.size = [0.10 * s, 0.085 * s, 0.5 * (top[2] - skull[2])]


def write_subject_figure(clip: BvhClip, out: str | Path, mass: float | None = None,
                         skeleton_map: SkeletonMap | None = None) -> Path:
    """Write the subject's figure of `clip` (`subject_figure_xml`) to `out` atomically; returns `out`.

    Raises:
        InputError: as `subject_figure_xml`; the folder is missing or the file cannot be written.
    """
    from runner.files import atomic_output

    out = Path(out)
    if not out.parent.is_dir():
        raise InputError(f"{out}: the folder {out.parent} does not exist; create it first")
    text = subject_figure_xml(clip, mass, skeleton_map=skeleton_map)
    try:
        with atomic_output(out, suffix=".xml") as tmp:
            Path(tmp).write_text(text, encoding="utf-8")
    except OSError as e:
        raise InputError(f"cannot write {out}: {e.strerror or e}; choose another output folder") from None
    return out
