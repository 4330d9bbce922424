"""The console's tables: the summary of plain spline against optimized path (with `worse` marks and the
terms that target each row) and the motion metrics against a capture (progress: `runner.progress`)."""
from __future__ import annotations

import numpy as np

from runner.certificate_text import certificate_lines
from runner.verdict import (
    FLIGHT_CHANGE,
    TOWARD,
    WORSE,
    figure,
    is_worse_mark,
    motion_mark,
    motion_worse,
    motion_worse_text,
    refinement_text,
    row_mark,
    row_name,
    verdict_lines,
)

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
LEGEND = (f"{WORSE}: higher than the plain spline's (and the capture's, in the label) by > 1% and the row's floor; "
          f"flight: further from the capture's (without one: changed by > {FLIGHT_CHANGE:.0%}); {TOWARD}: past the "
          "plain spline's margin, no further from the capture's (README \"Reading the summary\")")
OVER = "over bound"
#: the rows the force bounds limit: {metrics key: `solver.peak_bounds.PeakBounds` field}
BOUNDED_ROWS = {"peak_pelvis_acceleration_ms2": "pelvis_acceleration_ms2", "peak_root_force_ground_bw": "ground_force_bw"}
BOUND_LEGEND = (f"<= B: the force bounds' limit on the row (the larger of the plain spline's and the capture's "
                f"filtered peak); {OVER}: the optimized path is above it by > 1% and the row's last printed digit")
#: the feet rows of the summary (`runner.run.contact_summary_rows`): (label, motion-metrics key, format); the
#: motion-metrics table under the summary leaves these keys out (`motion_metrics_table`)
FEET_ROWS = (("float in contact [mm]", "float_contact_mm", "{:.2f}"),
             ("float in capture stance [mm]", "float_stance_mm", "{:.2f}"),
             ("flight in capture stance [s]", "flight_in_stance_s", "{:.3f}"),
             ("skate in contact [mm/frame]", "skate_contact_mm", "{:.2f}"),
             ("skate, PhysDiff [mm/frame]", "skate_mm", "{:.2f}"),
             ("skating ratio (contacts)", "skating_ratio_contacts", "{:.3f}"),
             ("flight time [s]", "flight_time_s", "{:.3f}"))
#: the summary rows that have a figure of the capture itself (`capture_figures`): {`path_metrics` key:
#: the key of the capture's figure in a motion-metrics "reference" block (`runner.motion_metrics`: its
#: jolts are of the capture filtered at 6 Hz, its flight is every site 3 cm clear at the capture's frames)}
CAPTURE_FIGURES = {"peak_pelvis_acceleration_ms2": "peak_pelvis_acceleration_m_s2",
                   "rms_joint_torque_Nm": "rms_joint_torque_Nm", "flight_s": "flight_time_s"}
#: the rows of `CAPTURE_FIGURES` whose capture figure is of the capture filtered at 6 Hz: their label says so
#: ("(capture at 6 Hz X)"), as a clean's first column is the capture itself, unfiltered
FILTERED_FIGURES = ("peak_pelvis_acceleration_ms2", "rms_joint_torque_Nm")

#: relaxations listed under the summary table (the rest counted)
RELAXATIONS_SHOWN = 6


#: [deg] a joint (the root's orientation included) further than this from the capture at some frame has
#: lost the capture's motion: keys no more than a quarter turn apart (`runner.capture.keyframe_selection.turn_keys`)
#: leave no in-between that far from it unless the path goes round the other way (a full turn joined the
#: short way is 174 deg off); the joint-angle row is then marked even if the plain spline is as far off
LOST_TURN_DEG = 90.0
MOTION_LEGEND = (f"{WORSE}: higher than the plain spline's and the reference's by > 1% and a floor per row (README "
                 "\"Reading the summary\"); flight time: further from the reference's by more than one frame; joint "
                 f"angle: also a max over {LOST_TURN_DEG:g} deg (the path went round the other way); {TOWARD}: past the "
                 "plain spline's, but no further from the reference's")


def _bound_mark(mark: bool | str, value: float, bound: float | None, atol: float, fmt: str) -> bool | str:
    """The last column of a bounded row: `OVER` (with `WORSE` if also worse) when `value` is above
    `bound` by more than 1 % and `atol` (and prints differently), else `mark` as it is."""
    if bound is None or not np.isfinite(float(value)) or fmt.format(value) == fmt.format(bound):
        return mark
    if float(value) > float(bound) * 1.01 + atol:
        return f"{WORSE}, {OVER}" if mark is True else OVER
    return mark


def comparison_rows(plain: dict, opt: dict, dynamics_terms: bool = False, bounds=None,
                    capture: dict | None = None) -> list[tuple]:
    """The acceptance figures of two `path_metrics`, plain spline and optimized, each marked when the
    optimized path is worse (`row_mark`).

    Args:
        plain, opt: `solver.metrics.path_metrics` of the two paths.
        dynamics_terms: also the rows that matter with the dynamics terms (pelvis acceleration, root
            force on the ground in body weights).
        bounds: the forces term's `solver.peak_bounds.PeakBounds`, or None: its two rows (`BOUNDED_ROWS`)
            then print the bound in the label ("<= B") and are marked `OVER` above it.
        capture: {`path_metrics` key: the capture's own figure} (`capture_figures`), or None: those rows
            print it in the label ("(capture X)") and are judged against it as well.
    Returns:
        list of (label, plain value, optimized value, format, mark), rows whose key is missing from
        either dict left out, and the contact sites that no path puts in a surface (0.00 mm in both);
        mark: True (worse), False, or a text (`TOWARD`, `OVER`, "worse, over bound").
    """
    capture = capture or {}
    rows = [("max penetration [mm] (1000 Hz)", plain["max_penetration_mm"], opt["max_penetration_mm"], "{:.2f}",
             row_mark(plain["max_penetration_mm"], opt["max_penetration_mm"], 0.01, "{:.2f}"))]
    for key in ("penetration_mm_by_site", "sole_mm_by_site"):  # the contact sites, then the soles' edges
        for site in plain.get(key, {}):
            a, b = plain[key][site], opt[key][site]
            if cell("{:.2f}", a) != "0.00" or cell("{:.2f}", b) != "0.00":
                rows.append((f"  {site} [mm]", a, b, "{:.2f}", row_mark(a, b, 0.01, "{:.2f}")))
    more = _GEOMETRY + _DYNAMICS + (_DYNAMICS_TERMS_ROWS if dynamics_terms else [])
    for label, key, fmt, atol in more:
        if key == "keyframe_error":
            a, b = plain.get(key, np.nan), opt.get(key, np.nan)
        elif key in plain and key in opt:
            a, b = plain[key], opt[key]
        else:
            continue
        c = capture.get(key)
        mark = row_mark(a, b, atol, fmt, c)
        if c is not None:
            label = f"{label} (capture{' at 6 Hz' if key in FILTERED_FIGURES else ''} {cell(fmt, c)})"
        if bounds is not None and key in BOUNDED_ROWS:
            bound = float(getattr(bounds, BOUNDED_ROWS[key]))
            label, mark = f"{label} <= {cell(fmt, bound)}", _bound_mark(mark, b, bound, atol, fmt)
        rows.append((label, a, b, fmt, mark))
    return rows


def capture_figures(motion: dict | None) -> dict:
    """{`path_metrics` key: the capture's own figure} for the summary rows that have one (`CAPTURE_FIGURES`)
    from a run's metrics["motion"] (None without a capture: {})."""
    if motion is None:
        return {}
    ref = motion["plain"]["reference"]
    return {key: float(ref[k]) for key, k in CAPTURE_FIGURES.items()
            if ref.get(k) is not None and np.isfinite(float(ref[k]))}


#: the summary rows each objective term penalizes (what the optimizer is asked to lower), by the row
#: label's start; a term's own "integral NAME" row is its own. Rows no chosen term penalizes are free
#: for the optimizer to trade away: the peak torque, and with the default terms the root wrench in
#: flight, which only the force bounds target (`--terms all`, README "Reading the summary").
TERM_ROWS = {
    "penetration": ("max penetration",),  # and the per-site rows under it (`row_targets`)
    "sole": (),  # the soles' edges' rows (`row_targets`)
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


def row_targets(labels, constraints, sites=(), soles=()) -> dict[str, str]:
    """{row label: the constraints, comma-separated, that bound the row's figure} (`TERM_ROWS`).

    Args:
        labels: the summary's row labels. constraints: the constraint names of the solve.
        sites: the contact sites whose "  SITE [mm]" penetration rows belong to the penetration constraint.
        soles: the soles' edge sites whose rows belong to the sole constraint.
    Returns:
        only the labels some constraint bounds; a "  NAME: worst / tolerance" row belongs to NAME.
    """
    site_rows, sole_rows = {f"  {site} [mm]" for site in sites}, {f"  {site} [mm]" for site in soles}
    out = {}
    for label in labels:
        terms = [name for name in constraints if name in TERM_ROWS and (
            label.strip().startswith(TERM_ROWS[name]) or (name == "penetration" and label in site_rows) or (name == "sole" and label in sole_rows))]
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


def summary_table(plain: dict, opt: dict, solution, contact_rows=(), force_bounds=None, motion=None,
                  tol: float | None = None) -> str:
    """The verdict (`runner.verdict.verdict_lines`), then plain spline vs optimized, the acceptance figures,
    as a text table; a "target" column names the constraints that bound each row's figure (`row_targets`),
    and a last column marks a figure on which the optimized path is worse ("worse", `comparison_rows`) or
    moved toward the capture's ("toward capture"), with legend lines for the marks printed. A figure that
    is not defined (the in-flight rows of a path without flight) is printed "-", never "nan".

    Args:
        plain, opt: `path_metrics` of the two paths. solution: the least change's Solution (its
            `integrals_*`: each constraint's worst value over its tolerance; `unmet`, `final_estimate`).
        contact_rows: (label, plain, optimized, format[, mark]) rows about the feet, printed after
            penetration (`runner.run.contact_summary_rows`, marked by `motion_mark`).
        force_bounds: the problem's `solver.peak_bounds.PeakBounds` (with the force bounds), or None:
            printed with the two rows it bounds (`comparison_rows`) and described under the table.
        motion: the run's metrics["motion"] (with a capture), or None: the capture's own figures, and the
            motion-metrics rows marked worse, which the verdict counts too.
        tol: the refinement's tolerance (`LeastChangeOptions.tol`), or None: the verdict then gives the
            refinement estimate without judging it.
    """
    rows = comparison_rows(plain, opt, dynamics_terms=force_bounds is not None, bounds=force_bounds,
                           capture=capture_figures(motion))
    n_pen = 1 + sum(r[0].startswith("  ") for r in rows)  # the feet rows go after the penetration rows
    rows[n_pen:n_pen] = list(contact_rows)
    rows.append(("change E = D / (m g^2 T)", solution.E_initial, solution.E_final, "{:.5g}"))
    constraints = list(solution.integrals_final)
    unmet = getattr(solution, "unmet", None) or {}
    shown = [name for name in constraints if name in unmet or max(solution.integrals_initial.get(name, 0.0),
                                                                    solution.integrals_final[name]) > 1.0]
    for name in shown:  # a constraint's worst value over its tolerance, where either path breaks it
        rows.append((f"  {name}: worst / tolerance", solution.integrals_initial.get(name), solution.integrals_final[name],
                     "{:.4g}"))
    rows += getattr(solution, "extra_rows", None) or []
    targets = row_targets([r[0] for r in rows], constraints, plain["penetration_mm_by_site"], plain.get("sole_mm_by_site", {}))
    feet, jolts = verdict_figures(plain, opt, motion)
    lines = verdict_lines(feet, jolts, rows, targets, solution, refinement_text(solution, tol), _motion_text(motion))
    lines += format_rows(rows, targets)
    marks = [r[4] for r in rows if len(r) > 4 and r[4]]
    if any(is_worse_mark(m) or m == TOWARD for m in marks):
        lines.append(LEGEND)
    if force_bounds is not None:
        lines += [BOUND_LEGEND, force_bounds.describe()]
    lines.append(TARGET_LEGEND)
    if any(cell("{}", v) == MISSING for r in rows for v in r[1:3]):
        lines.append(MISSING_LEGEND)
    met = [name for name in constraints if name not in shown]
    lines.append("NAME: worst / tolerance: a constraint's worst value over its tolerance (met at <= 1)"
                 + (f"; met by both paths, not shown: {', '.join(met)}" if met else ""))
    keys = solution.frames.count - solution.frames.n_variable  # a clean's: its pins and the clip's ends
    lines.append(f"frames: {keys} keyframes + {solution.frames.n_variable} variable; "
                 f"{len(solution.rounds)} rounds, {solution.n_evals} evaluations, {solution.wall_time_s:.2f} s")
    lines += _keyframe_lines(solution)
    return "\n".join(lines)


def _motion_text(motion: dict | None) -> str:
    """The verdict's words on the motion-metrics rows marked worse (`motion_rows`, less the feet rows)."""
    if motion is None:
        return ""
    top, accuracy = motion_rows(motion["plain"], motion["optimized"], [k for _, k, _ in FEET_ROWS])
    return motion_worse_text(*([row_name(label) for label, _, mark in block if is_worse_mark(mark)]
                               for block in (top, accuracy)))


def _keyframe_lines(solution) -> list[str]:
    """Where the keyframes decide a limit (`Solution.relaxations`) and the limits the least violation raised
    (`certificate_lines`; the verdict names them too)."""
    lines = []
    relaxed = getattr(solution, "relaxations", ()) or ()
    if relaxed:
        shown = ", ".join(f"{r.constraint} {r.label} at keyframe {r.keyframe} ({r.start:.2f}-{r.end:.2f} s, "
                          f"{r.amount * 1e3:.1f} mm)" for r in relaxed[:RELAXATIONS_SHOWN])
        more = f" and {len(relaxed) - RELAXATIONS_SHOWN} more" if len(relaxed) > RELAXATIONS_SHOWN else ""
        lines.append(f"where the keyframes decide (limit set to what they force): {shown}{more}")
    lines += certificate_lines(solution)
    return lines


def verdict_figures(plain: dict, opt: dict, motion: dict | None) -> tuple[list, list]:
    """The verdict's figures (`runner.verdict.figure` texts, None where missing): the feet (penetration at
    1000 Hz; with a capture float and skate in contact) and the jolts (peak pelvis acceleration at 1000 Hz;
    with a capture the peak joint angular acceleration at its frames; RMS joint torque), each with the
    capture's own figure where there is one."""
    ref, p, o = ({}, {}, {}) if motion is None else (motion["plain"]["reference"], motion["plain"]["path"],
                                                     motion["optimized"]["path"])
    cap = capture_figures(motion)
    pen = ref.get("penetration_mm", {}).get("max")
    feet = [figure("penetration", plain["max_penetration_mm"], opt["max_penetration_mm"], "{:.2f}", "mm", pen),
            figure("float", p.get("float_contact_mm"), o.get("float_contact_mm"), "{:.2f}", "mm",
                   ref.get("float_contact_mm")),
            figure("skate", p.get("skate_contact_mm"), o.get("skate_contact_mm"), "{:.2f}", "mm/frame",
                   ref.get("skate_contact_mm"))]
    key = "peak_pelvis_acceleration_ms2"
    jolts = [figure("peak pelvis", plain.get(key), opt.get(key), "{:.1f}", "m/s^2", cap.get(key)),
             figure("peak joint", p.get("peak_angular_acceleration_max_rad_s2"),
                    o.get("peak_angular_acceleration_max_rad_s2"), "{:.0f}", "rad/s^2",
                    ref.get("peak_angular_acceleration_max_rad_s2")),
             figure("RMS torque", plain.get("rms_joint_torque_Nm"), opt.get("rms_joint_torque_Nm"), "{:.1f}",
                    "N m", cap.get("rms_joint_torque_Nm"))]
    return feet, jolts


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


def motion_rows(plain: dict, optimized: dict, shown=()) -> tuple[list, list]:
    """The rows of `motion_metrics_table`: (the plausibility and no-jolt rows, the accuracy rows), each a list
    of (label, cells: [reference, plain, optimized] texts, mark: False, True (worse), `TOWARD` or `OVER`)."""
    ref = plain["reference"]
    frame_s = 1.0 / float(plain["fps"])
    cols = (ref, plain["path"], optimized["path"])
    rows = []
    for label, key, sub, fmt in (row for row in _PLAUSIBILITY_ROWS if row[1] not in shown):
        vals = [c[key][sub] if sub else c[key] for c in cols]
        rows.append((label, [cell(fmt, v) for v in vals], motion_mark(key, vals[1], vals[2], frame_s, vals[0])))
    for label, key, fmt, bound in (row for row in _JOLT_ROWS if any(row[1] in c for c in cols)):
        rows.append((label, [cell(fmt, c.get(key)) for c in cols], OVER if _over_jolt_bound(bound, key, cols) else False))
    accuracy = []
    pairs = zip(_accuracy_rows(plain["error"]), _accuracy_rows(optimized["error"]), strict=True)
    for (label, key, pm, px), (_, _, om, ox) in pairs:
        cells = [MISSING] + [cell("{:.2f}", m) + (f" / {cell('{:.1f}', x)}" if np.isfinite(x) else "")
                             for m, x in ((pm, px), (om, ox))]
        bad = motion_worse(key, pm, om) or motion_worse(key, px, ox) or (key == "joint_orientation_deg"
                                                                            and ox > LOST_TURN_DEG)
        accuracy.append((label + (" mean / max" if np.isfinite(px) else " mean"), cells, bool(bad)))
    return rows, accuracy


def motion_metrics_table(plain: dict, optimized: dict, shown=()) -> str:
    """The motion metrics against the reference (`runner.motion_metrics`), reference | plain | optimized,
    a row marked "worse" where the optimized path is worse than the plain spline, or "toward capture"
    (`runner.verdict.motion_mark`).

    Args:
        plain, optimized: `motion_metrics(...)` of the plain spline and of the optimized path, both
            sampled at the reference's frames; the "reference" column is their (equal) "reference" block.
        shown: the keys of plausibility rows the summary table already prints (`FEET_ROWS`): left out, and
            the title says so.
    Returns:
        the table as text: plausibility rows for all three, the no-jolt rows (`_JOLT_ROWS`, when the blocks
        have them; marked `OVER` beyond the corpus's bound), then the accuracy rows (mean, max over
        frames; the joint angle is the mean over joints of each joint's mean, and the largest max; worse
        when the mean or the max is), then the legends of the marks printed.
    """
    top, accuracy = motion_rows(plain, optimized, shown)
    w = max(max(len(r[0]) for r in top), 38) + 2
    head = f"{'':{w}}{'reference':>14}{'plain':>14}{'optimized':>14}"
    rule = "-" * (len(head) + len(WORSE) + 2)
    left_out = "; the feet rows of the summary left out" if any(r[1] in shown for r in _PLAUSIBILITY_ROWS) else ""
    lines = [f"motion metrics against the reference ({plain['frames']} frames at {plain['fps']:g} Hz{left_out}; "
             "docs/contacts.md \"Motion metrics\")", head, rule]
    for block in (top, accuracy):
        lines += [f"{label:{w}}" + "".join(f"{v:>14}" for v in cells)
                  + (f"  {mark if isinstance(mark, str) else WORSE}" if mark else "") for label, cells, mark in block]
        lines += [rule] if block is top else []
    marked = [mark for *_, mark in top + accuracy if mark]
    if OVER in marked:
        lines.append(JOLT_LEGEND)
    if any(m != OVER for m in marked):
        lines.append(MOTION_LEGEND)
    return "\n".join(lines)
