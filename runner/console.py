"""The console's tables: the summary of plain spline against optimized path (with `worse` marks and the
terms that target each row) and the motion metrics against a capture (progress: `runner.progress`)."""
from __future__ import annotations

import numpy as np

#: the figures where lower is better: (label, metrics key, format, absolute tolerance below which a rise is
#: round-off); the optimized path is marked worse when it is higher by more than 1% and the tolerance
_GEOMETRY = [
    ("max |1 - |q||", "max_norm_deviation", "{:.4f}", 1e-4),
    ("max hyperextension [deg]", "max_hyperextension_deg", "{:.2f}", 0.01),
    ("keyframe error (fixed comps)", "keyframe_error", "{:.1e}", 1e-9),
]
#: solver.metrics: contact-free inverse dynamics; flight = every contact site ~3 cm clear
_DYNAMICS = [
    ("peak pelvis acceleration [m/s^2]", "peak_pelvis_acceleration_ms2", "{:.1f}", 0.1),  # no jolts: always bounded
    ("RMS joint torque [N m]", "rms_joint_torque_Nm", "{:.1f}", 0.1),
    ("peak joint torque [N m]", "peak_joint_torque_Nm", "{:.1f}", 0.1),
    ("flight (all feet clear) [s]", "flight_s", "{:.3f}", None),  # worse: changed (see FLIGHT_CHANGE)
    ("RMS root force in flight [N]", "rms_root_force_flight_N", "{:.1f}", 0.1),
    ("peak root force in flight [N]", "peak_root_force_flight_N", "{:.1f}", 0.1),
    ("RMS root torque in flight [N m]", "rms_root_torque_flight_Nm", "{:.1f}", 0.1),
    ("peak root torque in flight [N m]", "peak_root_torque_flight_Nm", "{:.1f}", 0.1),
]
#: with the force bounds (`--terms all`): the ground force (its peak printed with its bound:
#: `solver.peak_bounds`)
_DYNAMICS_TERMS_ROWS = [
    ("RMS root force on ground [body wt]", "rms_root_force_ground_bw", "{:.2f}", 0.01),
    ("peak root force on ground [body wt]", "peak_root_force_ground_bw", "{:.2f}", 0.01),
]
#: flight is the keyframes' gait: the optimized path is marked when its flight differs from the plain
#: spline's by more than this fraction (and 0.01 s), longer or shorter
FLIGHT_CHANGE = 0.2
WORSE = "worse"
LEGEND = (f"{WORSE}: the optimized path is worse than the plain spline there (higher by > 1% and the row's "
          f"last printed digit; flight: changed by > {FLIGHT_CHANGE:.0%})")
OVER = "over bound"
#: the rows the force bounds limit: {metrics key: `solver.peak_bounds.PeakBounds` field}
BOUNDED_ROWS = {"peak_pelvis_acceleration_ms2": "pelvis_acceleration_ms2", "peak_root_force_ground_bw": "ground_force_bw"}
BOUND_LEGEND = (f"<= B: the force bounds' limit on the row (the larger of the plain spline's and the capture's "
                f"filtered peak); {OVER}: the optimized path is above it by > 1% and the row's last printed digit")

#: relaxations listed under the summary table (the rest counted)
RELAXATIONS_SHOWN = 6


#: the motion rows (the summary's feet rows and the motion-metrics table against the capture): the
#: optimized figure is marked worse when it exceeds the plain spline's by more than 1 % (figures move by
#: less between machines) and the row's absolute floor, here with its reason: {metrics key: (floor, reason)}
MOTION_MARGINS = {
    "penetration_mm": (0.1, "mm; a tenth of the 1 mm penetration bound"),
    "float_contact_mm": (0.1, "mm; a fiftieth of the 5 mm float bound"),
    "float_stance_mm": (0.1, "mm; as float in contact"),
    "float_physdiff_mm": (0.1, "mm; as float in contact"),
    "skate_mm": (0.05, "mm/frame; a tenth of the 0.5 mm/frame skate margin"),
    "skate_contact_mm": (0.05, "mm/frame; as skate"),
    "phys_err_mm": (0.2, "mm; the sum of a penetration, a float and a skate floor"),
    "skating_ratio": (0.01, "one step in a hundred"),
    "skating_ratio_contacts": (0.01, "one step in a hundred"),
    "flight_in_stance_s": (None, "s; one frame of the capture: flight is counted in whole frames"),
    "flight_phase_error_s": (None, "s; one frame of the capture: flight is counted in whole frames"),
    "root_position_cm": (0.05, "cm; half a printed digit of the mean"),
    "joint_orientation_deg": (0.05, "deg; half a printed digit of the mean"),
    "site_position_cm": (0.05, "cm; half a printed digit of the mean"),
    "accel_error_root_m_s2": (0.05, "m/s^2; half a printed digit"),
    "accel_error_sites_m_s2": (0.05, "m/s^2; half a printed digit"),
    "cone_rms": (0.1, "N; the printed digit"),
    "cone_peak": (0.1, "N; the printed digit"),
    "off_hinge_knee_deg": (3.0, "deg; the corpus bound: off the hinge by at most 3 deg more than the capture"),
    "off_hinge_elbow_deg": (3.0, "deg; as the knees"),
    "rom_excess_deg": (0.5, "deg; the hyperextension bound's half degree"),
}
#: rows whose figure the capture itself shows at a higher level (the spline is smoother than any real
#: motion): worse only above both the plain spline's and the capture's, by 1 %
CAPTURE_LEVEL_ROWS = ("jerk_root_m_s3", "jerk_sites_m_s3")
#: [deg] a joint (the root's orientation included) further than this from the capture at some frame has
#: lost the capture's motion: keys no more than a quarter turn apart (`runner.mocap.keyframe_selection.turn_keys`)
#: leave no in-between that far from it unless the path goes round the other way (a full turn joined the
#: short way is 174 deg off); the joint-angle row is then marked even if the plain spline is as far off
LOST_TURN_DEG = 90.0
MOTION_LEGEND = (f"{WORSE}: higher than the plain spline's by > 1% and a floor per row (float, penetration 0.1 mm; "
                 "skate 0.05 mm/frame; skating ratio 0.01; errors half a printed digit); flight time: further from "
                 "the capture's by more than one frame; jerk: above the plain spline's and the capture's; joint "
                 f"angle: also a max over {LOST_TURN_DEG:g} deg (the path went round the other way)")


def motion_worse(key: str, plain: float, opt: float, frame_s: float = 0.0, capture: float | None = None) -> bool:
    """Whether the optimized path's motion figure `opt` (metrics key `key`) is worse than the plain
    spline's `plain` beyond the row's margin (`MOTION_MARGINS`, `CAPTURE_LEVEL_ROWS`); flight time
    ("flight_time_s") is worse when further from the capture's `capture` by more than one frame
    (`frame_s` [s]); a key without a margin is never marked.

    Args:
        key: the motion-metrics key. plain, opt: the two paths' figures (units of the key).
        frame_s: [s] the capture's frame time. capture: the capture's own figure (flight, jerk).
    """
    a, b = float(plain), float(opt)
    if not (np.isfinite(a) and np.isfinite(b)):
        return False
    if key == "flight_time_s":
        return capture is not None and abs(b - capture) > abs(a - capture) * 1.01 + frame_s
    if key in CAPTURE_LEVEL_ROWS:
        return b > max(a, capture if capture is not None else a) * 1.01
    if key not in MOTION_MARGINS:
        return False
    floor = MOTION_MARGINS[key][0]
    return b > a * 1.01 + (frame_s if floor is None else floor)


def is_worse(plain: float, opt: float, atol: float | None, fmt: str) -> bool:
    """Whether the optimized figure `opt` is worse than the plain spline's `plain` (see `comparison_rows`)."""
    a, b = float(plain), float(opt)
    if not (np.isfinite(a) and np.isfinite(b)) or fmt.format(a) == fmt.format(b):
        return False
    if atol is None:  # flight
        return abs(b - a) > FLIGHT_CHANGE * abs(a) + 0.01
    return b > a * 1.01 + atol


def _bound_mark(worse: bool, value: float, bound: float | None, atol: float, fmt: str) -> bool | str:
    """The last column of a bounded row: `OVER` (with `WORSE` if also worse) when `value` is above
    `bound` by more than 1 % and `atol` (and prints differently), else `worse` as it is."""
    if bound is None or not np.isfinite(float(value)) or fmt.format(value) == fmt.format(bound):
        return worse
    if float(value) > float(bound) * 1.01 + atol:
        return f"{WORSE}, {OVER}" if worse else OVER
    return worse


def comparison_rows(plain: dict, opt: dict, dynamics_terms: bool = False, bounds=None) -> list[tuple]:
    """The acceptance figures of two `path_metrics`, plain spline and optimized, each marked when the
    optimized path is worse.

    Args:
        plain, opt: `solver.metrics.path_metrics` of the two paths.
        dynamics_terms: also the rows that matter with the dynamics terms (pelvis acceleration, root
            force on the ground in body weights).
        bounds: the forces term's `solver.peak_bounds.PeakBounds`, or None: its two rows (`BOUNDED_ROWS`)
            then print the bound in the label ("<= B") and are marked `OVER` above it.
    Returns:
        list of (label, plain value, optimized value, format, mark), rows whose key is missing from
        either dict left out; mark: worse (bool), or a text (`OVER`, "worse, over bound"). Worse: for
        every figure but flight, higher by more than 1% (and a per-row round-off tolerance); for
        flight, changed by more than FLIGHT_CHANGE (the gait).
    """
    specs = [("max penetration [mm] (1000 Hz)", "max_penetration_mm", "{:.2f}", 0.01)]
    rows = []
    for label, key, fmt, atol in specs:
        rows.append((label, plain[key], opt[key], fmt, is_worse(plain[key], opt[key], atol, fmt)))
    for site in plain["penetration_mm_by_site"]:
        a, b = plain["penetration_mm_by_site"][site], opt["penetration_mm_by_site"][site]
        rows.append((f"  {site} [mm]", a, b, "{:.2f}", is_worse(a, b, 0.01, "{:.2f}")))
    more = _GEOMETRY + _DYNAMICS + (_DYNAMICS_TERMS_ROWS if dynamics_terms else [])
    for label, key, fmt, atol in more:
        if key == "keyframe_error":
            a, b = plain.get(key, np.nan), opt.get(key, np.nan)
        elif key in plain and key in opt:
            a, b = plain[key], opt[key]
        else:
            continue
        mark = is_worse(a, b, atol, fmt)
        if bounds is not None and key in BOUNDED_ROWS:
            bound = float(getattr(bounds, BOUNDED_ROWS[key]))
            label, mark = f"{label} <= {cell(fmt, bound)}", _bound_mark(mark, b, bound, atol, fmt)
        rows.append((label, a, b, fmt, mark))
    return rows


#: the summary rows each objective term penalizes (what the optimizer is asked to lower), by the row
#: label's start; a term's own "integral NAME" row is its own. Rows no chosen term penalizes are free
#: for the optimizer to trade away: the peak torque, and with the default terms the root wrench in
#: flight, which only the force bounds target (`--terms all`, README "Reading the summary").
TERM_ROWS = {
    "penetration": ("max penetration",),  # and the per-site rows under it (`row_targets`)
    "unit": ("max |1 - |q||",),
    "hyperextension": ("max hyperextension",),
    "hinge": ("knee rotation off the hinge", "elbow rotation off the hinge"),
    "rom": ("beyond range of motion",),
    "acceleration": ("peak pelvis acceleration",),
    "effort": ("RMS joint torque",),
    "flight wrench": ("RMS root force in flight", "peak root force in flight", "RMS root torque in flight",
                      "peak root torque in flight"),
    "planted": ("float in contact", "float in capture stance", "flight in capture stance"),
    "slide": ("skate in contact", "skate, PhysDiff", "skating ratio"),
    "flight": ("flight (all feet clear)", "flight time", "flight phase error"),
    "ground": ("flight (all feet clear)", "flight time", "flight phase error"),
    "ground force": ("peak root force on ground",),
}
TARGET_LEGEND = ("target: the constraint that bounds the row's figure; rows without one are not constrained, "
                 "and the least change may trade them away")
MISSING = "-"
MISSING_LEGEND = f"{MISSING}: not defined for this path (the in-flight rows of a path with no flight phase)"


def cell(fmt: str, value) -> str:
    """`value` formatted with `fmt` for a table: "-" (`MISSING`) for None, NaN or inf, and never a
    negative zero ("-0.00" is printed "0.00")."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        return MISSING
    if not np.isfinite(v):
        return MISSING
    text = fmt.format(v)
    if text.startswith("-"):
        try:
            if float(text) == 0.0:
                return text[1:]
        except ValueError:
            pass
    return text


def row_targets(labels, constraints, sites=()) -> dict[str, str]:
    """{row label: the constraints, comma-separated, that bound the row's figure} (`TERM_ROWS`).

    Args:
        labels: the summary's row labels. constraints: the constraint names of the solve.
        sites: the contact sites whose "  SITE [mm]" penetration rows belong to the penetration constraint.
    Returns:
        only the labels some constraint bounds; a "  NAME: worst / tolerance" row belongs to NAME.
    """
    site_rows = {f"  {site} [mm]" for site in sites}
    out = {}
    for label in labels:
        terms = [name for name in constraints if name in TERM_ROWS and (
            label.strip().startswith(TERM_ROWS[name]) or (name == "penetration" and label in site_rows))]
        own = label.strip().removesuffix(": worst / tolerance")
        if label.endswith(": worst / tolerance") and own in constraints:
            terms.append(own)
        if terms:
            out[label] = ",".join(terms)
    return out


def format_rows(rows, targets: dict | None = None) -> list[str]:
    """Rows (label, plain, optimized, format[, worse]) as text lines under a header, a rule above and below.

    Values go through `cell` (no "nan", no "-0.00"). With `targets` ({label: term names}, `row_targets`)
    a "target" column names the terms that penalize each row's figure."""
    w = max(len(r[0]) for r in rows) + 2
    tw = max([len("target")] + [len(v) for v in (targets or {}).values()]) + 2 if targets is not None else 0
    head = f"{'':{w}}{'plain spline':>14}{'optimized':>14}" + (f"  {'target':<{tw - 2}}" if tw else "")
    rule = "-" * (w + 28 + tw + len(WORSE) + 2)
    lines = [head.rstrip(), rule]
    for label, a, b, fmt, *flag in rows:
        mark = f"  {flag[0] if isinstance(flag[0], str) else WORSE}" if flag and flag[0] else ""
        target = f"  {(targets or {}).get(label, ''):<{tw - 2}}" if tw else ""
        line = f"{label:{w}}{cell(fmt, a):>14}{cell(fmt, b):>14}"
        lines.append((line + target).rstrip() if not mark else line + target + mark)
    lines.append(rule)
    return lines


def summary_table(plain: dict, opt: dict, solution, contact_rows=(), force_bounds=None) -> str:
    """Plain spline vs optimized, the acceptance figures, as a text table; a "target" column names the
    constraints that bound each row's figure (`row_targets`), and a figure on which the optimized path is
    worse is marked "worse" in a last column (`comparison_rows`), with legend lines. A figure that is
    not defined (the in-flight rows of a path without flight) is printed "-", never "nan".

    Args:
        plain, opt: `path_metrics` of the two paths. solution: the least change's Solution (its
            `integrals_*`: each constraint's worst value over its tolerance).
        contact_rows: (label, plain, optimized, format[, worse]) rows about the feet, printed after
            penetration (`runner.run.contact_summary_rows`, marked by `motion_worse`).
        force_bounds: the problem's `solver.peak_bounds.PeakBounds` (with the force bounds), or None:
            printed with the two rows it bounds (`comparison_rows`) and described under the table.
    """
    rows = comparison_rows(plain, opt, dynamics_terms=force_bounds is not None, bounds=force_bounds)
    n_pen = 1 + len(plain["penetration_mm_by_site"])  # the feet rows go after the penetration rows
    rows[n_pen:n_pen] = list(contact_rows)
    rows.append(("change E = D / (m g^2 T)", solution.E_initial, solution.E_final, "{:.5g}"))
    constraints = list(solution.integrals_final)
    for name in constraints:  # a constraint's worst value over its tolerance
        rows.append((f"  {name}: worst / tolerance", solution.integrals_initial[name], solution.integrals_final[name],
                     "{:.4g}"))
    rows += getattr(solution, "extra_rows", None) or []
    lines = format_rows(rows, row_targets([r[0] for r in rows], constraints, plain["penetration_mm_by_site"]))
    lines.append(LEGEND)
    if force_bounds is not None:
        lines += [BOUND_LEGEND, force_bounds.describe()]
    if contact_rows:
        lines.append("feet rows: " + MOTION_LEGEND)
    lines.append(TARGET_LEGEND)
    if any(cell("{}", v) == MISSING for r in rows for v in r[1:3]):
        lines.append(MISSING_LEGEND)
    lines.append(f"frames: {solution.initial.count} keyframes + {solution.frames.n_variable} variable; "
                 f"{len(solution.rounds)} rounds, {solution.n_evals} evaluations, {solution.wall_time_s:.2f} s")
    estimate = getattr(solution, "final_estimate", None)
    if estimate is not None and np.isfinite(estimate):
        ok = getattr(solution, "converged_to_tol", None)
        how = f"tolerance met ({solution.message})" if ok else f"tolerance NOT met: {solution.message}"
        lines.append(f"refinement estimate (decrease of E still predicted, relative to E): {estimate:.3g}; {how}")
    lines.append("least change (docs/design.md): E = D / (m g^2 T), the mass-weighted change of the accelerations; "
                 "a constraint row is its worst value over its tolerance (met at <= 1)")
    relaxed = getattr(solution, "relaxations", ()) or ()
    if relaxed:
        shown = ", ".join(f"{r.constraint} {r.label} at keyframe {r.keyframe} ({r.start:.2f}-{r.end:.2f} s, "
                          f"{r.amount * 1e3:.1f} mm)" for r in relaxed[:RELAXATIONS_SHOWN])
        more = f" and {len(relaxed) - RELAXATIONS_SHOWN} more" if len(relaxed) > RELAXATIONS_SHOWN else ""
        lines.append(f"where the keyframes decide (limit set to what they force): {shown}{more}")
    lines += certificate_lines(solution)
    return "\n".join(lines)


#: raised limits shown one per line under the table (the rest counted): the summary stays short
CERTIFIED_SHOWN = 6


def certificate_lines(solution) -> list[str]:
    """The summary's lines on the limits the least violation raised (`Solution.certificate`): per
    constraint and column, the amount no path through the keyframes beats, where, and the keyframes
    around it; [] when nothing was raised."""
    raises = sorted(getattr(solution, "certificate", ()) or (), key=lambda r: -r.amount / max(r.scale, 1e-300))
    if not raises:
        return []
    keys = np.asarray(solution.initial.times)
    out = ["out of reach (certified: the least violation no path through the keyframes beats; the limit raised by it):"]
    for r in raises[:CERTIFIED_SHOWN]:
        i = int(np.clip(np.searchsorted(keys, r.time, side="right") - 1, 0, len(keys) - 1))
        near = int(np.argmin(np.abs(keys - r.time)))
        if abs(keys[near] - r.time) <= 1e-3:
            where = f"at keyframe {near}"
        else:
            where = f"between keyframes {i} and {min(i + 1, len(keys) - 1)}"
        out.append(f"  {r.describe()}, {where}")
    if len(raises) > CERTIFIED_SHOWN:
        out.append(f"  and {len(raises) - CERTIFIED_SHOWN} more (the saved path's certificate_json)")
    return out


#: rows of `motion_metrics_table`: (label, key in a `plausibility` block, sub-key or None, format)
_PLAUSIBILITY_ROWS = (
    ("penetration mean [mm]", "penetration_mm", "mean", "{:.2f}"),
    ("penetration max [mm]", "penetration_mm", "max", "{:.2f}"),
    ("float, ref. contacts [mm]", "float_contact_mm", None, "{:.1f}"),
    ("float, PhysDiff [mm]", "float_physdiff_mm", None, "{:.1f}"),
    ("skate, PhysDiff [mm]", "skate_mm", None, "{:.2f}"),
    ("skate, ref. contacts [mm]", "skate_contact_mm", None, "{:.2f}"),
    ("Phys-Err [mm]", "phys_err_mm", None, "{:.1f}"),
    ("skating ratio, GMD", "skating_ratio", None, "{:.3f}"),
    ("skating ratio, ref. contacts", "skating_ratio_contacts", None, "{:.3f}"),
    ("flight time [s]", "flight_time_s", None, "{:.3f}"),
    ("jerk root [m/s^3]", "jerk_root_m_s3", None, "{:.0f}"),
    ("jerk sites [m/s^3]", "jerk_sites_m_s3", None, "{:.0f}"),
)


#: the no-jolt rows of `motion_metrics_table` (`runner.jolts`: finite differences at the capture's frames,
#: torques by mj_inverse; the reference column is the capture low-pass filtered at 6 Hz): (label, key in a
#: motion-metrics block, format, the `bench corpus` bound that marks the row `OVER`)
_JOLT_ROWS = (
    ("peak pelvis acceleration [m/s^2]", "peak_pelvis_acceleration_m_s2", "{:.1f}", "pelvis_acc"),
    ("peak joint ang. acceleration [rad/s^2]", "peak_angular_acceleration_max_rad_s2", "{:.0f}", "joint_acc"),
    ("RMS joint torque [N m]", "rms_joint_torque_Nm", "{:.1f}", "torque_rms"),
)
JOLT_LEGEND = (f"{OVER}: a no-jolt row above its `bench corpus` bound (peaks 1.5x, torque 1.25x the larger of the "
               "plain spline's and the capture's, per joint for the joints; reference column: the capture filtered "
               "at 6 Hz)")


def _over_jolt_bound(bound: str, key: str, cols: tuple[dict, dict, dict]) -> bool:
    """Whether the optimized path misses the no-jolt `bound` (`runner.corpus_bounds`) on the blocks `cols`
    (reference, plain, optimized); False when a figure is missing."""
    from runner.corpus_bounds import BOUND_BY_NAME
    from runner.jolts import worst_joint_ratio

    b = BOUND_BY_NAME[bound]
    ref, plain, opt = cols
    if bound == "joint_acc":
        peaks = [c.get("peak_angular_acceleration_rad_s2") for c in (opt, plain, ref)]
        worst = worst_joint_ratio(*peaks) if all(peaks) else None
        return worst is not None and b.held({b.value: worst[1]}) is False
    vals = [c.get(key) for c in cols]
    if any(v is None for v in vals):
        return False
    return b.held({b.value: float(vals[2]), b.reference: max(float(vals[0]), float(vals[1]))}) is False


def _accuracy_rows(error: dict) -> list[tuple[str, str, float, float]]:
    """(label, metrics key, mean, max) of the accuracy figures of one `motion_metrics` "error" block."""
    joints = error["joint_orientation_deg"]
    sites = error["site_position_cm"]
    return [
        ("root position error [cm]", "root_position_cm", error["root_position_cm"]["mean"],
         error["root_position_cm"]["max"]),
        ("joint angle error [deg]", "joint_orientation_deg", float(np.mean([v["mean"] for v in joints.values()])),
         max(v["max"] for v in joints.values())),
        ("contact-site error [cm]", "site_position_cm", float(np.mean([v["mean"] for v in sites.values()])),
         max(v["max"] for v in sites.values())),
        ("acceleration error root [m/s^2]", "accel_error_root_m_s2", error["accel_error_root_m_s2"], float("nan")),
        ("acceleration error sites [m/s^2]", "accel_error_sites_m_s2", error["accel_error_sites_m_s2"], float("nan")),
    ]


def motion_metrics_table(plain: dict, optimized: dict) -> str:
    """The motion metrics against the reference (`runner.motion_metrics`), reference | plain | optimized,
    a row marked "worse" where the optimized path is worse than the plain spline (`motion_worse`).

    Args:
        plain, optimized: `motion_metrics(...)` of the plain spline and of the optimized path, both
            sampled at the reference's frames; the "reference" column is their (equal) "reference" block.
    Returns:
        the table as text: plausibility rows for all three, the no-jolt rows (`_JOLT_ROWS`, when the blocks
        have them; marked `OVER` beyond the corpus's bound), then the accuracy rows (mean, max over
        frames; the joint angle is the mean over joints of each joint's mean, and the largest max; worse
        when the mean or the max is), then the legend of the mark.
    """
    ref = plain["reference"]
    frame_s = 1.0 / float(plain["fps"])
    cols = (ref, plain["path"], optimized["path"])
    rows = []
    for label, key, sub, fmt in _PLAUSIBILITY_ROWS:
        vals = [c[key][sub] if sub else c[key] for c in cols]
        rows.append((label, [cell(fmt, v) for v in vals], motion_worse(key, vals[1], vals[2], frame_s, vals[0])))
    jolts = [row for row in _JOLT_ROWS if any(row[1] in c for c in cols)]
    for label, key, fmt, bound in jolts:
        rows.append((label, [cell(fmt, c.get(key)) for c in cols], OVER if _over_jolt_bound(bound, key, cols) else ""))
    w = max(max(len(r[0]) for r in rows), 38) + 2
    head = f"{'':{w}}{'reference':>14}{'plain':>14}{'optimized':>14}"
    lines = [f"motion metrics against the reference ({plain['frames']} frames at {plain['fps']:g} Hz; "
             "docs/contacts.md \"Motion metrics\")", head, "-" * (len(head) + len(WORSE) + 2)]
    lines += [f"{label:{w}}" + "".join(f"{v:>14}" for v in vals) + (f"  {bad if isinstance(bad, str) else WORSE}"
                                                                     if bad else "") for label, vals, bad in rows]
    lines.append("-" * (len(head) + len(WORSE) + 2))
    pairs = zip(_accuracy_rows(plain["error"]), _accuracy_rows(optimized["error"]), strict=True)
    for (label, key, pm, px), (_, _, om, ox) in pairs:
        cells = [MISSING] + [cell("{:.2f}", m) + (f" / {cell('{:.1f}', x)}" if np.isfinite(x) else "")
                             for m, x in ((pm, px), (om, ox))]
        bad = motion_worse(key, pm, om) or motion_worse(key, px, ox) or (key == "joint_orientation_deg"
                                                                            and ox > LOST_TURN_DEG)
        lines.append(f"{label + (' mean / max' if np.isfinite(px) else ' mean'):{w}}"
                     + "".join(f"{c:>14}" for c in cells) + (f"  {WORSE}" if bad else ""))
    if jolts:
        lines.append(JOLT_LEGEND)
    lines.append(MOTION_LEGEND)
    return "\n".join(lines)
