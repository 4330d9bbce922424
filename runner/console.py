"""The console: progress lines, Ctrl-C during an optimization, the summary table."""
from __future__ import annotations

import signal
import sys
import time

import numpy as np


class StopRequest:
    """Ctrl-C during the optimization sets a flag (the solver returns its best path); a second
    Ctrl-C aborts at once."""

    def __init__(self, quiet=False):
        self.requested = False
        self.quiet = quiet

    def __enter__(self):
        self._old = signal.signal(signal.SIGINT, self._handle)
        return self

    def __exit__(self, *exc):
        signal.signal(signal.SIGINT, self._old)

    def _handle(self, signum, frame):
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True
        print("\nstopping: keeping the best path so far (Ctrl-C again to abort)", file=sys.stderr, flush=True)

    def __call__(self) -> bool:
        return self.requested


class Progress:
    """One line of progress, rewritten in place on a terminal, a line a second otherwise."""

    def __init__(self, quiet=False, stream=None):
        self.quiet, self.stream = quiet, sys.stdout if stream is None else stream
        self.tty = self.stream.isatty()
        self.t0 = time.perf_counter()
        self.last = 0.0
        self.info = {}
        self.E0 = None

    def __call__(self, event, info):
        if self.quiet:
            return
        if event == "boost":
            worst = ", ".join(f"{k} {v:.3g}" for k, v in info["terms"].items())
            self.stream.write(("\n" if self.tty else "") + f"  over the limit ({worst}): weight x10, again\n")
            return
        if event == "round":
            self.info.update(info)
            self._print(force=True)
        else:
            self.info.update(info)
            self._print()

    def _print(self, force=False):
        now = time.perf_counter()
        if not force and now - self.last < (0.1 if self.tty else 1.0):
            return
        self.last = now
        i = self.info
        E = f"E {i['E']:.6g}" if "E" in i else "E -"
        msg = (f"  round {i.get('round', 0) + 1}: {i.get('frames', 0)} frames ({i.get('variable', 0)} variable)"
               f"  evals {i.get('evals', 0):5d}  {E}  {now - self.t0:6.1f} s")
        if self.tty:
            self.stream.write("\r" + msg.ljust(90))
        else:
            self.stream.write(msg + "\n")
        self.stream.flush()

    def done(self):
        if not self.quiet and self.tty:
            self.stream.write("\n")
            self.stream.flush()


#: the figures where lower is better: (label, metrics key, format, absolute tolerance below which a rise is
#: round-off); the optimized path is marked worse when it is higher by more than 1% and the tolerance
_GEOMETRY = [
    ("max |1 - |q||", "max_norm_deviation", "{:.4f}", 1e-4),
    ("max hyperextension [deg]", "max_hyperextension_deg", "{:.2f}", 0.01),
    ("keyframe error (fixed comps)", "keyframe_error", "{:.1e}", 1e-9),
]
#: solver.metrics: contact-free inverse dynamics; flight = every contact site ~3 cm clear
_DYNAMICS = [
    ("RMS joint torque [N m]", "rms_joint_torque_Nm", "{:.1f}", 0.1),
    ("peak joint torque [N m]", "peak_joint_torque_Nm", "{:.1f}", 0.1),
    ("flight (all feet clear) [s]", "flight_s", "{:.3f}", None),  # worse: changed (see FLIGHT_CHANGE)
    ("RMS root force in flight [N]", "rms_root_force_flight_N", "{:.1f}", 0.1),
    ("peak root force in flight [N]", "peak_root_force_flight_N", "{:.1f}", 0.1),
    ("RMS root torque in flight [N m]", "rms_root_torque_flight_Nm", "{:.1f}", 0.1),
    ("peak root torque in flight [N m]", "peak_root_torque_flight_Nm", "{:.1f}", 0.1),
]
#: with the dynamics terms (`--terms all`): what the root term's price is paid in
_DYNAMICS_TERMS_ROWS = [
    ("peak pelvis acceleration [m/s^2]", "peak_pelvis_acceleration_ms2", "{:.1f}", 0.1),
    ("RMS root force on ground [body wt]", "rms_root_force_ground_bw", "{:.2f}", 0.01),
    ("peak root force on ground [body wt]", "peak_root_force_ground_bw", "{:.2f}", 0.01),
]
#: flight is the keyframes' gait: the optimized path is marked when its flight differs from the plain
#: spline's by more than this fraction (and 0.01 s), longer or shorter
FLIGHT_CHANGE = 0.2
WORSE = "worse"
LEGEND = (f"{WORSE}: the optimized path is worse than the plain spline there (higher by > 1%; flight: "
          f"changed by > {FLIGHT_CHANGE:.0%})")


def is_worse(plain: float, opt: float, atol: float | None, fmt: str) -> bool:
    """Whether the optimized figure `opt` is worse than the plain spline's `plain` (see `comparison_rows`)."""
    a, b = float(plain), float(opt)
    if not (np.isfinite(a) and np.isfinite(b)) or fmt.format(a) == fmt.format(b):
        return False
    if atol is None:  # flight
        return abs(b - a) > FLIGHT_CHANGE * abs(a) + 0.01
    return b > a * 1.01 + atol


def comparison_rows(plain: dict, opt: dict, dynamics_terms: bool = False) -> list[tuple]:
    """The acceptance figures of two `path_metrics`, plain spline and optimized, each marked when the
    optimized path is worse.

    Args:
        plain, opt: `solver.metrics.path_metrics` of the two paths.
        dynamics_terms: also the rows that matter with the dynamics terms (pelvis acceleration, root
            force on the ground in body weights).
    Returns:
        list of (label, plain value, optimized value, format, worse: bool), rows whose key is missing
        from either dict left out. Worse: for every figure but flight, higher by more than 1% (and a
        per-row round-off tolerance); for flight, changed by more than FLIGHT_CHANGE (the gait).
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
        rows.append((label, a, b, fmt, is_worse(a, b, atol, fmt)))
    return rows


def format_rows(rows) -> list[str]:
    """Rows (label, plain, optimized, format[, worse]) as text lines under a header, a rule above and below."""
    w = max(len(r[0]) for r in rows) + 2
    lines = [f"{'':{w}}{'plain spline':>14}{'optimized':>14}", "-" * (w + 28 + len(WORSE) + 2)]
    for label, a, b, fmt, *flag in rows:
        mark = f"  {WORSE}" if flag and flag[0] else ""
        lines.append(f"{label:{w}}{fmt.format(a):>14}{fmt.format(b):>14}{mark}")
    lines.append("-" * (w + 28 + len(WORSE) + 2))
    return lines


def summary_table(plain: dict, opt: dict, solution, weights: dict, final_weights: dict | None = None) -> str:
    """Plain spline vs optimized, the acceptance figures, as a text table; a figure on which the optimized
    path is worse is marked "worse" in a last column (`comparison_rows`), with a legend line.

    Args:
        plain, opt: `path_metrics` of the two paths. solution: the Solution. weights: {term: weight}
            chosen. final_weights: {term: weight} at the end (penalty continuation raises some).
    """
    rows = comparison_rows(plain, opt, dynamics_terms=bool({"torque", "root"} & set(weights)))
    rows.append(("objective E", solution.E_initial, solution.E_final, "{:.5g}"))
    for name in weights:
        rows.append((f"  integral {name}", solution.integrals_initial[name], solution.integrals_final[name],
                     "{:.4g}"))
    extra = getattr(solution, "extra_rows", None) or []
    rows += extra
    lines = format_rows(rows)
    lines.append(LEGEND)
    lines.append(f"frames: {solution.initial.count} keyframes + {solution.frames.n_variable} variable; "
                 f"{len(solution.rounds)} rounds, {solution.n_evals} evaluations, {solution.wall_time_s:.2f} s")
    final = final_weights or {}
    terms = []
    for name, w0 in weights.items():
        w1 = final.get(name, w0)
        terms.append(f"{name} {w0:g}" + (f" -> {w1:g}" if w1 != w0 else ""))
    lines.append("terms (weight; -> after penalty continuation): " + ", ".join(terms))
    return "\n".join(lines)
