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


def summary_table(plain: dict, opt: dict, solution, weights: dict, final_weights: dict | None = None,
                  contact_rows=()) -> str:
    """Plain spline vs optimized, the acceptance figures, as a text table.

    Args:
        plain, opt: `path_metrics` of the two paths. solution: the Solution. weights: {term: weight}
            chosen. final_weights: {term: weight} at the end (penalty continuation raises some).
        contact_rows: (label, plain, optimized, format) rows about the feet, printed after penetration.
    """
    rows = [
        ("max penetration [mm] (1000 Hz)", plain["max_penetration_mm"], opt["max_penetration_mm"], "{:.2f}"),
    ]
    for site in plain["penetration_mm_by_site"]:
        rows.append((f"  {site} [mm]", plain["penetration_mm_by_site"][site],
                     opt["penetration_mm_by_site"][site], "{:.2f}"))
    rows += list(contact_rows)
    rows += [
        ("max |1 - |q||", plain["max_norm_deviation"], opt["max_norm_deviation"], "{:.4f}"),
        ("max hyperextension [deg]", plain["max_hyperextension_deg"], opt["max_hyperextension_deg"], "{:.2f}"),
        ("keyframe error (fixed comps)", plain.get("keyframe_error", np.nan), opt.get("keyframe_error", np.nan),
         "{:.1e}"),
    ]
    dynamics = [  # solver.metrics: contact-free inverse dynamics; flight = every contact site ~3 cm clear
        ("RMS joint torque [N m]", "rms_joint_torque_Nm", "{:.1f}"),
        ("peak joint torque [N m]", "peak_joint_torque_Nm", "{:.1f}"),
        ("flight (all feet clear) [s]", "flight_s", "{:.3f}"),
        ("RMS root force in flight [N]", "rms_root_force_flight_N", "{:.1f}"),
        ("peak root force in flight [N]", "peak_root_force_flight_N", "{:.1f}"),
        ("RMS root torque in flight [N m]", "rms_root_torque_flight_Nm", "{:.1f}"),
        ("peak root torque in flight [N m]", "peak_root_torque_flight_Nm", "{:.1f}"),
    ]
    rows += [(label, plain[key], opt[key], fmt) for label, key, fmt in dynamics if key in plain and key in opt]
    rows.append(("objective E", solution.E_initial, solution.E_final, "{:.5g}"))
    for name in weights:
        rows.append((f"  integral {name}", solution.integrals_initial[name], solution.integrals_final[name],
                     "{:.4g}"))
    extra = getattr(solution, "extra_rows", None) or []
    rows += extra
    w = max(len(r[0]) for r in rows) + 2
    lines = [f"{'':{w}}{'plain spline':>14}{'optimized':>14}", "-" * (w + 28)]
    for label, a, b, fmt in rows:
        lines.append(f"{label:{w}}{fmt.format(a):>14}{fmt.format(b):>14}")
    lines.append("-" * (w + 28))
    lines.append(f"frames: {solution.initial.count} keyframes + {solution.frames.n_variable} variable; "
                 f"{len(solution.rounds)} rounds, {solution.n_evals} evaluations, {solution.wall_time_s:.2f} s")
    final = final_weights or {}
    terms = []
    for name, w0 in weights.items():
        w1 = final.get(name, w0)
        terms.append(f"{name} {w0:g}" + (f" -> {w1:g}" if w1 != w0 else ""))
    lines.append("terms (weight; -> after penalty continuation): " + ", ".join(terms))
    return "\n".join(lines)

