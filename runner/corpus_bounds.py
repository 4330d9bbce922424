"""The acceptance bounds of `dynsplines bench corpus`: one record per bound, the figures they read, and
why a pair misses one (docs/corpus.md).

A (clip, keying) pair is solved as `dynsplines mocap` solves it (`runner.pipeline.process_clip`); its
metrics report (`<stem>.metrics.json`) and keyframe file give the flat *figures* of `pair_figures`
(`FIGURES`: each a path into the report, or a function of it), and every `Bound` compares one figure
with a limit made from another (the capture's, the plain spline's) or a constant:

    rule "le":     held when value <= factor * reference + margin   (reference 0 when None)
    rule "lt":     held when value <  factor * reference + margin
    rule "within": held when |value - reference| <= max(margin, factor * |reference|)

A bound whose figures are missing (a metric this build does not compute) is "n/a", never held or
missed. Two records are figures shown beside the bounds (`Bound.counted` False: the float on the
schedule's contacts, the flight while the capture stands): checked the same way, never failing a pair.

The skate against the plain spline's is held on the skate above what the keyframes force
(`skate_excess`): the part no path through the keyframes avoids is not the optimizer's. The no-jolt
bounds (`pelvis_acc`, `joint_acc`, `torque_rms`) read the jolt figures of the motion metrics
(`runner.jolts`: finite differences at the capture's frames, torques by `mj_inverse`), the capture's
low-pass filtered at 6 Hz (Winter) before it is differentiated.
The capture's own figure for the same quantity (`Bound.capture`) tells a scene that does not
fit the capture (the capture misses a surface bound itself) and a bound out of reach (the capture misses
another bound); see `causes`.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

#: the schedule agrees with the capture's stance when the recall and the precision of its stance frames are
#: both at least this (`runner.capture.stance.stance_agreement`); below it a flight missed the way the schedule's
#: gaps err is put down to the detection
STANCE_AGREES = 0.95
#: [cm] the root's position error must grow by more than this for "the optimizer moved the root": the
#: contact-site error's scale (the tuning clips' plain splines: 0.3-3 cm of root error, 0.8-12 cm at the sites)
ROOT_MOVED_CM = 1.0
#: the cause categories of a missed bound (`causes`), with what in the data tells each
CAUSES = {
    "scene fit": "the retargeted capture itself misses the bound against the fitted scene (its feet are not "
                 "on the surfaces fitted to them)",
    "contact detection": "the flight time is missed the way the schedule errs: its gaps (frames where no site "
                         "is scheduled in contact) are longer than the capture's flight (every site 3 cm clear) "
                         "by more than the flight bound and the path flies too long, or shorter and too short, "
                         "and the schedule disagrees with the capture's stance (recall or precision of its stance "
                         f"frames under {STANCE_AGREES:.0%})",
    "gaps the capture does not fly": "the flight time is missed as above, but the schedule agrees with the "
                                     "capture's stance: in its gaps the capture's feet are below the 3 cm flight "
                                     "height without resting (a landing foot gliding in, a heel sliding onto a "
                                     "step); the flight band lifts the sites only where the capture flies, and the "
                                     "extra flight comes from the swing bands and the spline between keyframes",
    "keyframes contradict the schedule": "a keyframe decides a contact constraint: it holds a site off its "
                                         "contact schedule, and the limit is set to what it forces "
                                         "(`Solution.relaxations`)",
    "keyframes force the skate": "the keyframes alone force more skate than the limit: in each contact a site "
                                 "passes through its keyed positions, so it slides at least the distance between "
                                 "consecutive ones (`runner.motion_metrics.forced_skate_mm`); no path through the "
                                 "keyframes holds the bound",
    "bound out of reach": "the constraint that bounds the figure is out of reach of every path the solve of "
                          "the violation itself found (its limit raised by the least violation, "
                          "`Solution.certificate`), or the capture itself misses the bound",
    "the solve stopped short": "the solve ended (its subproblems, evaluations or time spent) with the bound's "
                               "constraint still beyond its tolerance (`Solution.integrals_final` above 1)",
    "the optimizer moved the root": "a joint-angle or contact-site error missed while the root's position error "
                                    f"grew by more than {ROOT_MOVED_CM:g} cm and by a larger factor than the "
                                    "joint-angle error (a root shift moves every site with it)",
    "joints traded for the feet": "the joint-angle error missed while the contact-site error is below the plain "
                                  "spline's: the contact constraints bought the feet with the joints",
    "the plain spline met the constraints": "a bound against the plain spline (joint-angle or contact-site error, "
                                            "skate above the forced) missed where the plain spline already met "
                                            "every constraint within its tolerance: the least change only "
                                            "moved it toward the limits, by less than their tolerances, and "
                                            "it tracks neither the capture nor slides that small",
}
NOT_TOLD = "not told by the data"
#: the bounds made from the plain spline's own figure that no constraint bounds at that scale (the cause
#: "the plain spline met the constraints")
PLAIN_RELATIVE = ("joint_error", "site_error", "skate_excess")
#: where the plain spline already meets every constraint within its tolerance ("plain_worst_constraint" <= 1), a
#: `PLAIN_RELATIVE` bound allows at least this much above the plain spline's own figure, in the bound's units: a
#: figure of a capture's resolution (issue 60's examples: 0.1 mm, 0.01 cm; a BVH's 0.1 degree). The least change
#: of such a pair is the plain spline itself (D = 0, `solver.least_change`), so "below the plain spline's" or
#: "half of it" asks the solve for what its problem does not: no path is told to beat the plain spline there
PLAIN_FLOORS = {"joint_error": 0.1, "site_error": 0.01, "skate_excess": 0.1}
#: the cause of a skate bound below what the keyframes force (`forced_out_of_reach`)
FORCED = "keyframes force the skate"
#: the cause of a bound whose constraint the solve certified out of reach (its limit raised, `Solution.certificate`)
OUT_OF_REACH = "bound out of reach"


@dataclass(frozen=True)
class Bound:
    """One acceptance bound of the corpus (module docstring).

    Attributes:
        name: short id, the column of the tables. label: what it says, with units.
        value: the figure measured (a `FIGURES` key). reference: the figure the limit is made from, or None
            (the limit is `margin`). rule: "le", "lt" or "within" (module docstring). factor, margin: the
            rule's numbers, in the figure's units (margin) or dimensionless (factor).
        capture: the capture's own figure of the same quantity (for `causes`), or None.
        terms: the constraints that bound the figure (one the solve left out of reach, `Solution.unmet`:
            "bound out of reach").
        kind: "surface" (feet against the scene), "contact" (the schedule decides it) or "motion".
        source: the sentence of the acceptance list (or of the issue's "What to build") it implements.
        counted: False for a figure shown beside the bounds but not one of the acceptance list's (the
            schedule's own float, the flight while the capture stands): reported held / missed, left out of
            "every bound held" and of the failing pairs.
        resolution: a figure the limit is at least (the resolution the value is measured at: a flight time
            counted in frames resolves one frame, "frame_s"), or None.
    """

    name: str
    label: str
    value: str
    reference: str | None
    rule: str
    factor: float
    margin: float
    capture: str | None
    terms: tuple[str, ...]
    kind: str
    source: str
    counted: bool = True
    resolution: str | None = None

    def limit(self, figures: dict) -> float | None:
        """The limit for the pair's `figures` [the value's units; for "within": on |value - reference|],
        at least the plain spline's own figure plus `PLAIN_FLOORS` where the plain spline met every constraint;
        None when a figure it needs is missing."""
        ref = 0.0 if self.reference is None else figures.get(self.reference)
        if ref is None or not math.isfinite(ref):
            return None
        if self.rule == "within":
            return max(self.margin, self.factor * abs(ref), figures.get(self.resolution, 0.0) if self.resolution else 0.0)
        lim = self.factor * ref + self.margin
        if self.name in PLAIN_FLOORS and figures.get("plain_worst_constraint", math.inf) <= 1.0:
            lim = max(lim, ref + PLAIN_FLOORS[self.name])  # the plain spline met every constraint: its own + resolution
        return lim

    def measured(self, figures: dict, value_key: str | None = None) -> float | None:
        """The figure compared with the limit (for "within": |value - reference|), None when missing.
        `value_key` replaces `value` (the capture's own figure, for `causes`)."""
        v = figures.get(value_key or self.value)
        if v is None or not math.isfinite(v):
            return None
        if self.rule == "within":
            ref = figures.get(self.reference)
            return None if ref is None else abs(v - ref)
        return v

    def held(self, figures: dict, value_key: str | None = None) -> bool | None:
        """True / False, or None ("n/a") when a figure is missing."""
        v, lim = self.measured(figures, value_key), self.limit(figures)
        if v is None or lim is None:
            return None
        return v < lim if self.rule == "lt" else v <= lim


#: the issue's sentence the two figures beside the float bound implement (`Bound.counted` False)
_STANCE_AND_SCHEDULE = ("float and flight measured on the capture's stance frames as well as on the schedule's, "
                        "so a gap in the schedule cannot hide a floating foot (shown, not counted).")
#: the issue's sentences of the no-jolt bounds (their figures: `runner.jolts`)
_NO_JOLTS = "no jolts, against the larger of the plain spline's and the capture's (filtered at 6 Hz, Winter):"
#: the acceptance list, one record per bound (docs/corpus.md "Bounds"), and the figures shown beside it
BOUNDS: tuple[Bound, ...] = (
    Bound("penetration", "max penetration [mm]", "penetration_mm", None, "le", 0.0, 1.0, "capture_penetration_mm",
          ("penetration",), "surface", "Per pair: max penetration <= 1 mm."),
    Bound("keyframes", "keyframe error", "keyframe_error", None, "le", 0.0, 1e-9, None, (), "motion",
          "keyframes met to 1e-9."),
    Bound("float", "float in the capture's stance [mm]", "float_mm", None, "le", 0.0, 5.0, "capture_float_mm",
          ("planted",), "surface", "float during the capture's stance <= 5 mm."),
    Bound("float_schedule", "float on the schedule's contacts [mm]", "float_schedule_mm", None, "le", 0.0, 5.0,
          "capture_float_schedule_mm", ("planted",), "surface", _STANCE_AND_SCHEDULE, counted=False),
    Bound("flight_in_stance", "flight while the capture stands [s]", "flight_in_stance_s",
          "capture_flight_in_stance_s", "le", 1.0, 0.030, None, ("planted",), "contact", _STANCE_AND_SCHEDULE,
          counted=False),
    Bound("skate_capture", "skate vs capture [mm/frame]", "skate_mm", "capture_skate_mm", "le", 1.0, 0.5, None,
          ("slide",), "contact", "skate <= the capture's + 0.5 mm/frame"),
    Bound("skate_excess", "skate above what the keyframes force, vs plain [mm/frame]", "skate_excess_mm",
          "plain_skate_excess_mm", "le", 0.5, 0.0, "capture_skate_excess_mm", ("slide",), "contact",
          "and the skate above what the keyframes force <= half the plain spline's above it;"),
    Bound("flight", "flight time vs capture [s]", "flight_s", "capture_flight_s", "within", 0.10, 0.030, None,
          ("flight", "ground"), "contact", "flight time within 30 ms or 10 % of the capture's, whichever is larger "
          "(and one frame: both are counted in frames, so under 33 fps 30 ms asked for the same count);",
          resolution="frame_s"),
    Bound("flight_30ms", "flight time vs capture, without the frame [s]", "flight_s", "capture_flight_s", "within",
          0.10, 0.030, None, ("flight", "ground"), "contact",
          "the flight bound as the list words it, without its one-frame floor (shown, not counted).", counted=False),
    Bound("joint_error", "joint-angle error [deg]", "joint_error_deg", "plain_joint_error_deg", "le", 1.10, 0.0, None,
          (), "motion", "joint-angle error <= the plain spline's + 10 %;"),
    Bound("site_error", "contact-site error [cm]", "site_error_cm", "plain_site_error_cm", "lt", 1.0, 0.0, None,
          ("planted", "slide", "tracking"), "motion", "contact-site error below the plain spline's;"),
    Bound("off_hinge", "knee/elbow off the hinge, beyond the capture's [deg]", "off_hinge_deg", "capture_off_hinge_deg", "le", 1.0, 3.0,
          None, ("hinge",), "motion", "knee and elbow rotation off the hinge <= the capture's + 3 degrees;"),
    Bound("hyperextension", "hyperextension [deg]", "hyperextension_deg", "plain_hyperextension_deg", "le", 1.0, 0.5,
          None, ("hyperextension",), "motion", "hyperextension <= the plain spline's + 0.5 degree."),
    Bound("pelvis_acc", "peak pelvis acceleration [m/s^2]", "pelvis_acc_m_s2", "pelvis_acc_reference_m_s2", "le",
          1.5, 0.0, None, ("acceleration",), "motion",
          f"{_NO_JOLTS} peak pelvis linear acceleration <= 1.5x;"),
    Bound("joint_acc", "peak angular acceleration over the reference's, worst ball joint", "joint_acc_ratio", None,
          "le", 0.0, 1.5, None, ("acceleration",), "motion",
          f"{_NO_JOLTS} each ball joint's peak angular acceleration <= 1.5x;"),
    Bound("torque_rms", "RMS joint torque [N m]", "torque_rms_Nm", "torque_rms_reference_Nm", "le", 1.25, 0.0, None,
          (), "motion", f"{_NO_JOLTS} RMS joint torque <= 1.25x."),
)


BOUND_BY_NAME = {b.name: b for b in BOUNDS}


def _dig(doc, keys):
    """The value at `keys` in the nested dict `doc`, or None where a key is missing."""
    for k in keys:
        if not isinstance(doc, dict) or k not in doc:
            return None
        doc = doc[k]
    return doc


def _at(*keys) -> Callable[[dict], float | None]:
    """A figure at `keys` in the metrics report (None when absent)."""
    def get(doc):
        v = _dig(doc, keys)
        return None if v is None else float(v)
    return get


def _mean_of_means(*keys) -> Callable[[dict], float | None]:
    """The mean over joints (or sites) of each one's mean, at `keys` (the summary's "mean" column)."""
    def get(doc):
        v = _dig(doc, keys)
        return float(np.mean([j["mean"] for j in v.values()])) if v else None
    return get


_M = ("metrics", "motion")


def _off_hinge_excess(doc: dict) -> float | None:
    """[deg] the largest, over knees and elbows, of the optimized path's rotation off the hinge minus the
    capture's at the same joint (None when the report has no anatomy figures)."""
    opt = _dig(doc, (*_M, "optimized", "path", "off_hinge_deg"))
    cap = _dig(doc, (*_M, "plain", "reference", "off_hinge_deg"))
    return float(max(opt[j] - cap[j] for j in opt)) if opt and cap else None


def _above_forced(doc: dict, which: str, part: str = "path") -> float | None:
    """[mm/frame] the skate in contact of `which`'s `part` ("path"; the capture: "plain", "reference")
    minus the skate the keyframes force (None when either is missing)."""
    v = _dig(doc, (*_M, which, part, "skate_contact_mm"))
    forced = _dig(doc, (*_M, "keyframes", "forced_skate_contact_mm"))
    return None if v is None or forced is None else float(v) - float(forced)


def _larger(*keys) -> Callable[[dict], float | None]:
    """The larger of the figures at each of `keys` (tuples of keys into the report); None when one is
    missing: a limit made from "the larger of the plain spline's and the capture's" needs both."""
    def get(doc):
        vals = [_dig(doc, k) for k in keys]
        return None if any(v is None for v in vals) else float(max(vals))
    return get


_PLAIN, _OPT, _CAPTURE = (*_M, "plain", "path"), (*_M, "optimized", "path"), (*_M, "plain", "reference")
#: the jolt figures' keys in a motion-metrics block (`runner.jolts.jolt_figures`)
_PELVIS, _JOINTS, _TORQUE = ("peak_pelvis_acceleration_m_s2", "peak_angular_acceleration_rad_s2",
                             "rms_joint_torque_Nm")


def _worst_joint(doc: dict) -> list | None:
    """[joint, its ratio, the optimized path's peak, the plain spline's, the capture's [rad/s^2], when the
    optimized path peaks [s]] of the ball joint whose peak angular acceleration is largest against the larger
    of the plain spline's and the capture's (`runner.jolts.worst_joint_ratio`); None when a block lacks them."""
    from runner.jolts import worst_joint_ratio

    opt, plain, cap = (_dig(doc, (*b, _JOINTS)) for b in (_OPT, _PLAIN, _CAPTURE))
    worst = worst_joint_ratio(opt, plain, cap) if opt and plain and cap else None
    if worst is None:
        return None
    j = worst[0]
    when = _dig(doc, (*_OPT, "peak_angular_acceleration_t_s", j))
    return [j, worst[1], opt[j], plain[j], cap[j], None if when is None else float(when)]


#: the figures of a pair: {name: function of the metrics report}; the motion metrics are over the
#: reference's frames (`runner.run.reference_motion_metrics`); float over the capture's stance (and the
#: schedule's contacts beside it), skate over the schedule's contacts.
FIGURES: dict[str, Callable[[dict], float | None]] = {
    # the solve's longest round (one subproblem, wall time on the machine that ran it) and the clip's length
    "longest_round_s": _at("longest_round_s"),
    "clip_s": lambda doc: doc["frames"] / doc["fps"] if doc.get("frames") and doc.get("fps") else None,
    "frame_s": lambda doc: 1.0 / doc["fps"] if doc.get("fps") else None,  # the motion metrics' frame [s]
    "penetration_mm": _at("metrics", "optimized", "max_penetration_mm"),
    "stance_recall": _at("stance_agreement", "recall"),
    "stance_precision": _at("stance_agreement", "precision"),
    "capture_penetration_mm": _at(*_M, "plain", "reference", "penetration_mm", "max"),
    "keyframe_error": _at("metrics", "optimized", "keyframe_error"),
    # float on the capture's own stance frames (`runner.capture.stance.capture_stance`): a foot the schedule
    # leaves out of contact is still judged where the capture stood on it; beside it the schedule's
    "float_mm": _at(*_M, "optimized", "path", "float_stance_mm"),
    "plain_float_mm": _at(*_M, "plain", "path", "float_stance_mm"),
    "capture_float_mm": _at(*_M, "plain", "reference", "float_stance_mm"),
    "float_schedule_mm": _at(*_M, "optimized", "path", "float_contact_mm"),
    "capture_float_schedule_mm": _at(*_M, "plain", "reference", "float_contact_mm"),
    # time airborne (every site 3 cm clear) while the capture has a foot in stance
    "flight_in_stance_s": _at(*_M, "optimized", "path", "flight_in_stance_s"),
    "capture_flight_in_stance_s": _at(*_M, "plain", "reference", "flight_in_stance_s"),
    "skate_mm": _at(*_M, "optimized", "path", "skate_contact_mm"),
    "plain_skate_mm": _at(*_M, "plain", "path", "skate_contact_mm"),
    "capture_skate_mm": _at(*_M, "plain", "reference", "skate_contact_mm"),
    # the skate every path through the keyframes has (a lower bound, `runner.motion_metrics.forced_skate_mm`),
    # and each path's skate above it
    "forced_skate_mm": _at(*_M, "keyframes", "forced_skate_contact_mm"),
    "skate_excess_mm": lambda doc: _above_forced(doc, "optimized"),
    "plain_skate_excess_mm": lambda doc: _above_forced(doc, "plain"),
    "capture_skate_excess_mm": lambda doc: _above_forced(doc, "plain", "reference"),
    "flight_s": _at(*_M, "optimized", "path", "flight_time_s"),
    "plain_flight_s": _at(*_M, "plain", "path", "flight_time_s"),
    "capture_flight_s": _at(*_M, "plain", "reference", "flight_time_s"),
    "joint_error_deg": _mean_of_means(*_M, "optimized", "error", "joint_orientation_deg"),
    "plain_joint_error_deg": _mean_of_means(*_M, "plain", "error", "joint_orientation_deg"),
    "root_error_cm": _at(*_M, "optimized", "error", "root_position_cm", "mean"),
    "plain_root_error_cm": _at(*_M, "plain", "error", "root_position_cm", "mean"),
    "site_error_cm": _mean_of_means(*_M, "optimized", "error", "site_position_cm"),
    "plain_site_error_cm": _mean_of_means(*_M, "plain", "error", "site_position_cm"),
    # knee/elbow rotation off the hinge: each joint's excess over the capture's own at that joint
    # (`runner.motion_metrics.anatomy_figures`), so the bound is "<= the capture's + 3 deg" joint by joint
    "off_hinge_deg": lambda doc: _off_hinge_excess(doc),
    "capture_off_hinge_deg": lambda doc: None if _off_hinge_excess(doc) is None else 0.0,
    "hyperextension_deg": _at("metrics", "optimized", "max_hyperextension_deg"),
    "plain_hyperextension_deg": _at("metrics", "plain", "max_hyperextension_deg"),
    # no jolts (`runner.jolts`): each path's figures at the capture's frames, the capture's filtered at 6 Hz;
    # the limits are made from the larger of the plain spline's and the capture's
    "pelvis_acc_m_s2": _at(*_OPT, _PELVIS),
    "pelvis_acc_t_s": _at(*_OPT, "peak_pelvis_acceleration_t_s"),
    "plain_pelvis_acc_m_s2": _at(*_PLAIN, _PELVIS),
    "capture_pelvis_acc_m_s2": _at(*_CAPTURE, _PELVIS),
    "pelvis_acc_reference_m_s2": _larger((*_PLAIN, _PELVIS), (*_CAPTURE, _PELVIS)),
    # per ball joint: the optimized path's peak over the larger of the two at that joint, the worst joint's
    "joint_acc_ratio": lambda doc: None if (w := _worst_joint(doc)) is None else w[1],
    "torque_rms_Nm": _at(*_OPT, _TORQUE),
    "plain_torque_rms_Nm": _at(*_PLAIN, _TORQUE),
    "capture_torque_rms_Nm": _at(*_CAPTURE, _TORQUE),
    "torque_rms_reference_Nm": _larger((*_PLAIN, _TORQUE), (*_CAPTURE, _TORQUE)),
}


def schedule_flight_s(contacts, sites, t0: float, frames: int, fps: float) -> float:
    """[s] the time in which the schedule has no site in contact, counted on the reference's frames
    t0 + i / fps, i < frames (as the motion metrics count the capture's flight).

    Args:
        contacts: `solver.contacts.Contact`s (times [s] on the clip's clock). sites: the contact sites.
        t0: [s] the first keyframe's time. frames: the motion metrics' frame count. fps: [Hz].
    """
    from solver.contacts import contact_mask

    times = t0 + np.arange(int(frames)) / float(fps)
    mask = contact_mask(contacts, sites, times)
    return float((~mask.any(axis=1)).sum() / fps)


def pair_figures(report: dict, schedule_flight: float | None = None) -> dict:
    """The flat figures of one pair (`FIGURES`, missing ones left out) from its metrics report (the
    `<stem>.metrics.json` that `process_clip` writes), with the schedule's flight time [s]
    (`schedule_flight_s`), the keyframe conflicts, the stalled terms when known, "joint_rise" ([joint,
    deg]: the joint whose mean angle error grew most from the plain spline) and "joint_acc_worst" (the
    ball joint of "joint_acc_ratio" with its peaks, `_worst_joint`), both for the failing-pairs list."""
    out = {}
    for name, get in FIGURES.items():
        v = get(report)
        if v is not None and math.isfinite(v):
            out[name] = v
    if schedule_flight is not None:
        out["schedule_flight_s"] = float(schedule_flight)
    rise = _largest_joint_rise(report)
    if rise is not None:
        out["joint_rise"] = rise
    worst = _worst_joint(report)
    if worst is not None:
        out["joint_acc_worst"] = worst
    out["keyframe_conflicts"] = int(report.get("keyframe_conflicts") or 0)
    if "relaxed" in report:  # {constraint: count}; reports written before it name none
        out["relaxed"] = sorted(report["relaxed"])
    out["stalled"] = sorted((report.get("stalled") or {}).keys())
    out["unmet_at_end"] = sorted((report.get("unmet_at_end") or {}).keys())
    plain = report.get("plain_constraints")
    if plain:  # reports written before it do not say
        out["plain_worst_constraint"] = max(float(v) for v in plain.values())
    return out


def _largest_joint_rise(report: dict) -> list | None:
    """[joint, deg]: the joint whose mean angle error grew most from the plain spline to the optimized path
    (None when the report has no joint errors)."""
    opt = _dig(report, (*_M, "optimized", "error", "joint_orientation_deg"))
    plain = _dig(report, (*_M, "plain", "error", "joint_orientation_deg"))
    if not opt or not plain:
        return None
    name = max((j for j in opt if j in plain), key=lambda j: opt[j]["mean"] - plain[j]["mean"], default=None)
    return None if name is None else [name, float(opt[name]["mean"] - plain[name]["mean"])]


def _root_moved(figures: dict) -> bool:
    """The root's position error grew by more than ROOT_MOVED_CM and by a larger factor than the joint-angle
    error (`CAUSES`); False when a figure is missing."""
    keys = ("root_error_cm", "plain_root_error_cm", "joint_error_deg", "plain_joint_error_deg")
    if not set(keys) <= set(figures):
        return False
    r1, r0, j1, j0 = (figures[k] for k in keys)
    return r1 - r0 > ROOT_MOVED_CM and r1 * j0 > j1 * r0  # r1 / r0 > j1 / j0 without dividing by 0


def _gaps_err(bound: Bound, figures: dict) -> bool:
    """The flight bound missed the way the schedule's gaps err (`CAUSES` "contact detection")."""
    if bound.name != "flight" or not {"schedule_flight_s", "capture_flight_s", "flight_s"} <= set(figures):
        return False
    capture, lim = figures["capture_flight_s"], bound.limit(figures)
    gap_error = figures["schedule_flight_s"] - capture
    return abs(gap_error) > lim and (gap_error > 0) == (figures["flight_s"] > capture)


def forced_out_of_reach(bound: Bound, figures: dict) -> bool:
    """True for a skate bound whose limit is below the skate the keyframes alone force ("forced_skate_mm"):
    no path through the keyframes holds it (`CAUSES` "keyframes force the skate")."""
    lim, forced = bound.limit(figures), figures.get("forced_skate_mm")
    return bound.value == "skate_mm" and lim is not None and forced is not None and forced > lim


def causes(bound: Bound, figures: dict) -> list[str]:
    """The cause categories (`CAUSES`) of a missed `bound` that the pair's `figures` show; empty when the
    data does not tell.

    scene fit: a surface bound the capture itself misses. contact detection: the flight bound missed the
    way the schedule errs (its gaps, which the clearance term lifts both feet through, are longer than
    the capture's flight by more than the flight bound and the path's flight is too long, or shorter and
    too short) where the schedule disagrees with the capture's stance (recall or precision under
    STANCE_AGREES; unknown agreement counts as disagreeing); gaps the capture does not fly: the same where
    it agrees. keyframes contradict the schedule: a surface or contact bound missed on a pair whose
    keyframes decide the bound's own constraint (`_keyframes_decide`). keyframes force the skate: a skate limit below what every path
    through the keyframes slides (`forced_out_of_reach`). bound out of reach: the bound's term stalled, or the
    capture itself misses a bound that is not about surfaces. the solve stopped short: the bound's term was
    still beyond its tolerance when the solve ended (the report's "unmet_at_end"). the optimizer moved the root: a joint or
    site error missed while the root error grew more (`_root_moved`). joints traded for the feet: the
    joint error missed while the site error is below the plain spline's. the plain spline met the
    constraints: a `PLAIN_RELATIVE` bound missed where the plain spline's worst constraint is within its
    tolerance ("plain_worst_constraint" <= 1).
    """
    out = []
    capture_misses = bound.capture is not None and bound.held(figures, bound.capture) is False
    if capture_misses and bound.kind == "surface":
        out.append("scene fit")
    if _gaps_err(bound, figures):
        agrees = min(figures.get("stance_recall", 0.0), figures.get("stance_precision", 0.0)) >= STANCE_AGREES
        out.append("gaps the capture does not fly" if agrees else "contact detection")
    if bound.kind in ("surface", "contact") and _keyframes_decide(bound, figures):
        out.append("keyframes contradict the schedule")
    if forced_out_of_reach(bound, figures):
        out.append(FORCED)
    if set(bound.terms) & set(figures.get("stalled", ())) or (capture_misses and bound.kind != "surface"):
        out.append(OUT_OF_REACH)
    if set(bound.terms) & set(figures.get("unmet_at_end", ())):
        out.append("the solve stopped short")
    if bound.name in ("joint_error", "site_error") and _root_moved(figures):
        out.append("the optimizer moved the root")
    if bound.name == "joint_error" and BOUND_BY_NAME["site_error"].held(figures):
        out.append("joints traded for the feet")
    if bound.name in PLAIN_RELATIVE and figures.get("plain_worst_constraint", math.inf) <= 1.0:
        out.append("the plain spline met the constraints")
    return out


def check_pair(figures: dict) -> list[dict]:
    """Every bound on one pair: [{"bound", "held" (True / False / None = n/a), "value", "limit", "causes",
    "counted" (`Bound.counted`)}], in `BOUNDS` order ("causes" only for a missed bound)."""
    rows = []
    for b in BOUNDS:
        held = b.held(figures)
        rows.append({"bound": b.name, "held": held, "value": b.measured(figures), "limit": b.limit(figures),
                     "causes": causes(b, figures) if held is False else [], "counted": b.counted})
    return rows


def _keyframes_decide(bound: Bound, figures: dict) -> bool:
    """Whether the keyframes set the limit of a constraint that bounds `bound` (the pair's relaxations,
    `figures["relaxed"]`); for a report that does not list them, whether there was any relaxation."""
    if "relaxed" in figures:
        return bool(set(bound.terms) & set(figures["relaxed"]))
    return figures.get("keyframe_conflicts", 0) > 0
