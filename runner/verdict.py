"""When a summary row is worse (`row_mark`, `motion_mark`: above the plain spline's figure, and above the
capture's where there is one; flight: further from the capture's), and the verdict above the summary
table: whether the constraints were met, the feet and the jolts (plain spline -> optimized, against the
capture), and how many rows came out worse and why (README "Reading the summary"). Text from figures the
caller gathers (`runner.console.summary_table`)."""
from __future__ import annotations

import math
import re
import textwrap

import numpy as np

#: a row's last column where the optimized path is worse than the plain spline (`runner.console`)
WORSE = "worse"
#: a row's last column where the optimized figure rose past the plain spline's margin, but no further from
#: the capture's own figure than the plain spline's: the least change moved it toward the motion the
#: keyframes came from, which is not worse
TOWARD = "toward capture"

#: flight is the keyframes' gait: without a capture the optimized path is marked when its flight differs
#: from the plain spline's by more than this fraction (and FLIGHT_ABS), longer or shorter
FLIGHT_CHANGE = 0.2
#: [s] flight is counted in samples: a change below 0.01 s (about a frame of a 120 Hz capture) is not judged
FLIGHT_ABS = 0.01
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
#: [characters] the verdict's lines wrap at this width (a little wider than the summary table with its marks)
WIDTH = 128

#: each constraint's unit as printed and its size in SI units (the `unit` and `scale` of the classes in
#: `solver.constraints`; a test checks them): a limit raised by `amount` [SI] prints as amount / scale
CONSTRAINT_UNITS = {
    "penetration": ("mm", 1e-3), "sole": ("mm", 1e-3), "planted": ("mm", 1e-3), "slide": ("mm", 1e-3), "flight": ("mm", 1e-3),
    "ground": ("mm", 1e-3), "hinge": ("deg", math.pi / 180.0), "hyperextension": ("deg", math.pi / 180.0),
    "rom": ("deg", math.pi / 180.0), "acceleration": ("m/s^2 | rad/s^2", 1.0), "effort": ("N m", 1.0),
    "tracking": ("mm", 1e-3), "unit": ("1", 1.0), "flight wrench": ("N | N m", 1.0), "ground force": ("N", 1.0),
}


def motion_mark(key: str, plain: float, opt: float, frame_s: float = 0.0, capture: float | None = None) -> bool | str:
    """How the optimized path's motion figure `opt` (metrics key `key`) compares with the plain spline's
    `plain`: True (worse), `TOWARD` (past the plain spline's margin, no further from the capture's `capture`)
    or False.

    Worse: above both the plain spline's and the capture's figure by 1 % and the row's floor
    (`MOTION_MARGINS`; `CAPTURE_LEVEL_ROWS`: no floor); flight time ("flight_time_s"): further from the
    capture's by 1 % and one frame `frame_s` [s] (not judged without a capture); a key without a margin is
    never marked. Lower is never worse.

    Args:
        key: the motion-metrics key. plain, opt: the two paths' figures (units of the key).
        frame_s: [s] the capture's frame time. capture: the capture's own figure, or None.
    """
    a, b = float(plain), float(opt)
    c = None if capture is None or not np.isfinite(float(capture)) else float(capture)
    if not (np.isfinite(a) and np.isfinite(b)):
        return False
    if key == "flight_time_s":
        if c is None:
            return False
        if abs(b - c) > abs(a - c) * 1.01 + frame_s:
            return True
        return TOWARD if abs(b - a) > abs(a) * 0.01 + frame_s else False
    if key in CAPTURE_LEVEL_ROWS:
        floor = 0.0
    elif key in MOTION_MARGINS:
        floor = MOTION_MARGINS[key][0]
        floor = frame_s if floor is None else floor
    else:
        return False
    return _level_mark(a, b, c, floor)


def _level_mark(a: float, b: float, c: float | None, floor: float) -> bool | str:
    """True when `b` is above both `a` and `c` (None: `a` alone) by 1 % and `floor`; `TOWARD` when only `c`
    keeps it from that; else False."""
    if b > max(a, a if c is None else c) * 1.01 + floor:
        return True
    return TOWARD if b > a * 1.01 + floor else False


def motion_worse(key: str, plain: float, opt: float, frame_s: float = 0.0, capture: float | None = None) -> bool:
    """Whether the optimized path's motion figure is worse than the plain spline's (`motion_mark` is True)."""
    return motion_mark(key, plain, opt, frame_s, capture) is True


def row_mark(plain: float, opt: float, atol: float | None, fmt: str, capture: float | None = None) -> bool | str:
    """How the optimized figure `opt` of a summary row compares with the plain spline's `plain`: True (worse),
    `TOWARD` (past the plain spline's margin but no further from the capture's figure `capture`) or False.

    Worse: higher by more than 1 % and `atol` (the row's round-off), and than the capture's figure where
    there is one; flight (`atol` None): further from the capture's by 1 % and FLIGHT_ABS, without a
    capture changed by more than FLIGHT_CHANGE and FLIGHT_ABS. Figures that print alike are never marked.
    """
    a, b = float(plain), float(opt)
    if not (np.isfinite(a) and np.isfinite(b)) or fmt.format(a) == fmt.format(b):
        return False
    c = None if capture is None or not np.isfinite(float(capture)) else float(capture)
    if atol is None:  # flight
        changed = abs(b - a) > FLIGHT_CHANGE * abs(a) + FLIGHT_ABS
        if c is None:
            return changed
        if abs(b - c) > abs(a - c) * 1.01 + FLIGHT_ABS:
            return True
        return TOWARD if changed else False
    return _level_mark(a, b, c, atol)


def is_worse_mark(mark) -> bool:
    """Whether a row's mark (False, True, or a text: `WORSE`, "worse, over bound", "over bound", `TOWARD`)
    says the optimized path is worse there."""
    return mark is True or (isinstance(mark, str) and mark.startswith(WORSE))


def row_name(label: str) -> str:
    """A row's label without its unit, capture figure, sampling, bound or statistics ("peak pelvis
    acceleration [m/s^2] (capture 16.5) <= 30.0" -> "peak pelvis acceleration")."""
    name = re.sub(r" <= .*$| mean( / max)?$", "", label.strip())
    return re.sub(r" \[[^]]*\]| \(capture [^)]*\)| \(1000 Hz\)", "", name).strip()


def _join_names(names: list[str]) -> str:
    """Row names joined by commas, an "RMS X" and a "peak X" as one "RMS/peak X"."""
    out = []
    for name in names:
        first, _, rest = name.partition(" ")
        pair = {"RMS": "peak", "peak": "RMS"}.get(first)
        if pair and f"{pair} {rest}" in names:
            merged = f"RMS/peak {rest}"
            if merged not in out:
                out.append(merged)
        else:
            out.append(name)
    return ", ".join(out)


def figure(name: str, plain, opt, fmt: str, unit: str, capture=None) -> tuple[str, str, str] | None:
    """("NAME PLAIN -> OPT UNIT", the capture's figure or "-", PLAIN as shown), or None when a path's figure is
    missing or not finite."""
    try:
        a, b = float(plain), float(opt)
    except (TypeError, ValueError):
        return None
    if not (math.isfinite(a) and math.isfinite(b)):
        return None
    c = "-" if capture is None or not math.isfinite(float(capture)) else _num(fmt, float(capture))
    return f"{name} {_num(fmt, a)} -> {_num(fmt, b)} {unit}", c, _num(fmt, a)


def _num(fmt: str, v: float) -> str:
    text = fmt.format(v)
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text  # no negative zero


def raised_limits(unmet: dict, certificate=()) -> str:
    """{constraint: amount [SI]} as "penetration by 41.6 mm, acceleration by 1.05e+03 m/s^2 | rad/s^2"; where the
    `certificate` (`solver.feasibility.Raise`s) holds the constraint, its largest raise in its column's own unit
    and where: "acceleration by 3.08e+03 rad/s^2 at r_elbow"."""
    parts = []
    for name, amount in unmet.items():
        unit, scale = CONSTRAINT_UNITS.get(name, ("[SI]", 1.0))
        where = ""
        raises = [r for r in certificate if r.constraint == name]
        if raises:
            top = max(raises, key=lambda r: r.amount)
            amount, unit, scale, where = top.amount, top.unit, top.scale, f" at {top.label}" if top.label else ""
        parts.append(f"{name} by {float(amount) / scale:.3g} {unit}{where}")
    return ", ".join(parts)


def constraint_verdict(integrals_final: dict, unmet: dict, certificate=()) -> str:
    """The first words of the verdict: "every constraint met", or the limits raised and the constraints
    still over their tolerance at the end (worst value / tolerance > 1; the "stopped:" line above the
    summary says why the solve ended).

    Args:
        integrals_final: {constraint: worst value over its tolerance on the optimized path} (met at <= 1).
        unmet: {constraint: by how much its limit was raised [SI]} (`Solution.unmet`). certificate: the
            `Raise`s behind it (`Solution.certificate`), for each raise's column and unit.
    """
    over = {k: v for k, v in integrals_final.items() if v > 1.0 and k not in unmet}
    parts = []
    if unmet:
        parts.append(f"limits raised (the solve found no path that meets them): {raised_limits(unmet, certificate)}")
    if over:
        parts.append("over tolerance: " + ", ".join(f"{k} {v:.3g} x tol" for k, v in over.items()))
    if not parts:
        return "every constraint met"
    return "; ".join(parts) + ("; every other constraint met" if len(over) + len(unmet) < len(integrals_final)
                               else "")


def worse_reasons(rows, targets: dict, broken: list, unmet: dict, over: list) -> list[tuple[str, list[str]]]:
    """The rows marked worse grouped by why: [(reason, [row names]), ...] in the order first met.

    A row a constraint bounds rose inside that constraint's limit, or its limit was raised (`unmet`), or the
    constraint is still over its tolerance (`over`); a row no constraint bounds was traded for the
    constraints the plain spline breaks (`broken`: the least change moves the path only to meet them)."""
    groups: dict[str, list[str]] = {}
    for label, *_, mark in (r for r in rows if len(r) > 4):
        if not is_worse_mark(mark):
            continue
        bound = [t for t in targets.get(label, "").split(",") if t]
        raised, missed = [t for t in bound if t in unmet], [t for t in bound if t in over]
        if raised:
            why = f"limit of {' and '.join(raised)} raised"
        elif missed:
            why = f"{' and '.join(missed)} over tolerance"
        elif bound:
            why = f"inside the limit of {' and '.join(bound)}"
        elif broken:
            why = f"bounded by no constraint: traded for {', '.join(broken)}, which the plain spline breaks"
        else:
            why = "bounded by no constraint"
        names = groups.setdefault(why, [])
        if row_name(label) not in names:
            names.append(row_name(label))
    return list(groups.items())


def worse_line(rows, targets: dict, integrals_initial: dict, integrals_final: dict, unmet: dict) -> str:
    """"worse: N of M rows: ROWS (why); ...; K moved toward the capture: ROWS" ("none" for N = 0)."""
    judged = [r for r in rows if len(r) > 4]
    n_worse = sum(is_worse_mark(r[4]) for r in judged)
    broken = [k for k, v in integrals_initial.items() if v > 1.0]
    over = [k for k, v in integrals_final.items() if v > 1.0]
    text = f"worse: {n_worse or 'none'} of {len(judged)} rows"
    reasons = worse_reasons(judged, targets, broken, unmet, over)
    if reasons:
        text += ": " + "; ".join(f"{_join_names(names)} ({why})" for why, names in reasons)
    toward = [row_name(r[0]) for r in judged if r[4] == TOWARD]
    if toward:
        text += f"; {len(toward)} moved toward the capture: {_join_names(toward)}"
    return text


def motion_worse_text(plausibility: list[str], errors: list[str]) -> str:
    """"; motion metrics worse: ..." for the motion-metrics rows marked worse (their names): plausibility
    rows, and errors against the capture, which no constraint tracks; "" when none is."""
    parts = ([", ".join(plausibility)] if plausibility else []) + (
        [f"{', '.join(errors)} (no constraint tracks the capture's path)"] if errors else [])
    return f"; motion metrics worse: {'; '.join(parts)}" if parts else ""


def verdict_lines(feet: list, jolts: list, rows, targets: dict, solution, estimate_text: str = "",
                  motion_text: str = "") -> list[str]:
    """The verdict: three or four lines that go above the summary table.

    Args:
        feet, jolts: `figure`s (None: left out) of the feet (penetration, float, skate) and of the
            jolts and the torque (peak pelvis and joint acceleration, RMS joint torque).
        rows: the table's rows (label, plain, optimized, format[, mark]). targets: {label: constraints}
            (`runner.console.row_targets`). solution: its `integrals_initial`, `integrals_final` and
            `unmet`. estimate_text: the refinement's verdict ("refinement converged ..."), or "".
            motion_text: `motion_worse_text` of the motion-metrics table, added to the worse line.
    Returns:
        ["verdict: ...", "  feet: ...", "  jolts: ...", "  worse: ..."], the feet and jolts lines only when
        they have a figure, with the capture's figures after them unless those are the first column's (a clean's;
        the jolts' are of the capture filtered at 6 Hz, and say so), each wrapped at WIDTH.
    """
    unmet = getattr(solution, "unmet", None) or {}
    head = constraint_verdict(solution.integrals_final, unmet, getattr(solution, "certificate", None) or ())
    lines = [f"verdict: {head}" + (f"; {estimate_text}" if estimate_text else "")]
    for name, parts in (("feet", feet), ("jolts", jolts)):
        shown = [p for p in parts if p]
        if shown:
            captures, firsts = [c for _, c, _ in shown], [f for _, _, f in shown]  # a clean's first column: the capture
            who = "capture at 6 Hz" if name == "jolts" else "capture"  # the jolts' figures: the capture filtered at 6 Hz
            against = f" ({who} {', '.join(captures)})" if any(c != "-" for c in captures) and captures != firsts else ""
            lines.append(f"  {name}: " + ", ".join(t for t, _, _ in shown) + against)
    lines.append("  " + worse_line(rows, targets, solution.integrals_initial, solution.integrals_final, unmet)
                 + motion_text)
    return [part for line in lines for part in textwrap.wrap(line, WIDTH, subsequent_indent="    ",
                                                             break_on_hyphens=False)]


def refinement_text(solution, tol: float | None) -> str:
    """The convergence verdict against `tol`: the decrease of Phi, relative, that more frames still predict
    (`Solution.final_estimate`), or on a clean's grid what its last subproblem lowered Phi by (`estimate_kind`
    "progress"), or that it ended on the least violation's path ("search"); when the solve refined after its last
    estimate, that the final frames have none; without an estimate, that the solve stopped first ("" without `tol`
    either)."""
    estimate = getattr(solution, "final_estimate", None)
    if getattr(solution, "estimate_kind", "refinement") == "search":
        return "converged (the least violation's path meets every constraint)"
    if estimate is None or not np.isfinite(estimate):
        return "" if tol is None else "no refinement estimate (the solve stopped before one)"
    checks = getattr(solution, "segment_decreases", ()) or ()
    if checks and len(checks[-1][0]) != solution.frames.count:
        return (f"no refinement estimate on the final frames (the last: {estimate:.3g} on {len(checks[-1][0])} "
                "frames, before more were added)")
    if getattr(solution, "estimate_kind", "refinement") == "reference":
        return "nothing to change: the reference motion already meets every constraint within its tolerance"
    if getattr(solution, "estimate_kind", "refinement") == "progress":  # a clean: no frame to add
        what = f"the last subproblem lowered Phi by {estimate:.3g} of it"
        return what if tol is None else f"{'converged' if estimate <= tol else 'not converged'} ({what}, tol {tol:g})"
    if tol is None:
        return f"refinement estimate {estimate:.3g}"
    if estimate <= tol:
        return f"refinement converged (estimate {estimate:.3g} <= tol {tol:g})"
    return f"refinement not converged (estimate {estimate:.3g} > tol {tol:g})"
