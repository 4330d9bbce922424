"""The tables of `dynsplines bench corpus` (`runner.corpus`) as Markdown: per set (tuning, validation) a
held / not-held table per pair, the pass rate per bound, and the failing pairs with the bound missed and
its cause (`runner.corpus_bounds.causes`). docs/corpus.md explains how to read them."""
from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

from runner.corpus_bounds import BOUNDS, CAUSES, NOT_TOLD
from runner.corpus_sets import SETS, TUNING_SET

#: what each set is, in the report
SET_TITLES = {
    TUNING_SET: "Tuning clips (the defaults were chosen on these)",
    "validation": "Validation clips (never used to choose a default)",
}
#: the pass rates the acceptance list asks for, per set
REQUIRED = {TUNING_SET: 0.95, "validation": 0.90}
NA = "n/a"


def number(v: float | None) -> str:
    """A figure for a table: 3 significant digits, scientific below 1e-3 (keyframe errors); "n/a" for None."""
    if v is None or not math.isfinite(v):
        return NA
    if v != 0 and abs(v) < 1e-3:
        return f"{v:.1e}"
    return f"{v:.3g}"


def check_cell(check: dict) -> str:
    """"0.31 <= 1" (held), "**3.2 > 1**" (missed; "<" for a strict bound), or "n/a"."""
    if check["held"] is None:
        return NA
    v, lim = number(check["value"]), number(check["limit"])
    if check["held"]:
        return f"{v} <= {lim}"
    return f"**{v} > {lim}**"


def _pair_name(r: dict) -> str:
    return f"{Path(r['clip']).stem} {r['keying']}"


def pair_table(results: Sequence[dict]) -> list[str]:
    """A row per pair, a column per bound: value and limit, missed ones in bold; a pair that did not run
    shows its status. "all" counts the missed bounds that count (`Bound.counted`)."""
    head = "| pair | " + " | ".join(b.name for b in BOUNDS) + " | all |"
    lines = [head, "|---|" + "---|" * (len(BOUNDS) + 1)]
    for r in results:
        if not r["checks"]:
            lines.append(f"| {_pair_name(r)} | {r['status']}: {r['error']} |" + " |" * len(BOUNDS))
            continue
        cells = [check_cell(c) for c in r["checks"]]
        missed = sum(c["held"] is False and c.get("counted", True) for c in r["checks"])
        lines.append(f"| {_pair_name(r)} | " + " | ".join(cells) + f" | {'held' if not missed else f'{missed} missed'} |")
    return lines


def rate_table(rates: dict) -> list[str]:
    """Pass rate per bound and of whole pairs, a column per set."""
    lines = ["| bound | " + " | ".join(SETS) + " |", "|---|" + "---|" * len(SETS)]
    for b in BOUNDS:
        cells = []
        for s in SETS:
            held, n = rates[s][b.name]
            cells.append(f"{held}/{n} ({held / n:.0%})" if n else NA)
        lines.append(f"| {b.name}: {b.source} | " + " | ".join(cells) + " |")
    cells = []
    for s in SETS:
        n, ok = rates[s]["pairs"], rates[s]["held_all"]
        cells.append(f"**{ok}/{n} ({ok / n:.0%})**, required {REQUIRED[s]:.0%}" if n else NA)
    lines.append("| **every bound held (pairs)** | " + " | ".join(cells) + " |")
    cells = [f"{rates[s]['held_but_forced']}/{rates[s]['pairs']}" if rates[s]["pairs"] else NA for s in SETS]
    lines.append("| every bound held that the keyframes leave in reach (pairs; the rest miss only a skate bound "
                 "below what the keyframes force) | " + " | ".join(cells) + " |")
    cells = [f"{rates[s]['held_but_certified']}/{rates[s]['pairs']}" if rates[s]["pairs"] else NA for s in SETS]
    lines.append("| every bound held but those out of reach (pairs; the rest miss only bounds the keyframes force or "
                 "whose constraint the solve certified out of reach) | " + " | ".join(cells) + " |")
    return lines


def failing_lines(results: Sequence[dict]) -> list[str]:
    """One line per failing pair: each bound missed with its value, limit and cause categories."""
    lines = []
    for r in results:
        if not r["checks"]:
            lines.append(f"- {_pair_name(r)} ({r['set']}): did not run ({r['status']}): {r['error']}")
            continue
        missed = [c for c in r["checks"] if c["held"] is False and c.get("counted", True)]
        if not missed:
            continue
        n = r["figures"].get("keyframe_conflicts", 0)
        what = "; ".join(f"{c['bound']} {number(c['value'])} (limit {number(c['limit'])}): "
                         + (", ".join(_cause(k, n) for k in c["causes"]) or NOT_TOLD) + _where(c, r["figures"])
                         for c in missed)
        lines.append(f"- {_pair_name(r)} ({r['set']}): {what}")
    return lines


def _where(check: dict, figures: dict) -> str:
    """What a missed bound's figure was made of, for the failing-pairs list: for the joint-angle error the
    joint whose mean error grew most (`corpus_bounds.pair_figures` "joint_rise": " (largest rise: r_hip +2.3
    deg)"); for a skate bound the skate the keyframes force (`runner.motion_metrics.forced_skate_mm`); for a
    no-jolt bound the optimized path's peak (when, which joint) and the plain spline's and the capture's
    figures its limit is the larger of (`_jolt_where`); "" otherwise."""
    rise, forced = figures.get("joint_rise"), figures.get("forced_skate_mm")
    if check["bound"].startswith("skate") and forced is not None:
        return f" (the keyframes force {number(forced)})"
    if check["bound"] in ("pelvis_acc", "joint_acc", "torque_rms"):
        return _jolt_where(check["bound"], figures)
    if check["bound"] != "joint_error" or not rise:
        return ""
    return f" (largest rise: {rise[0]} {rise[1]:+.1f} deg)"


def _jolt_where(bound: str, figures: dict) -> str:
    """" (peak 31.2 m/s^2 at 1.23 s; plain 12.1, capture 19.8)", " (l_knee 412 rad/s^2 at 1.23 s; plain 180,
    capture 275)", " (plain 95.1, capture 110 N m)"; "" when the figures are missing."""
    if bound == "joint_acc":
        worst = figures.get("joint_acc_worst")
        if not worst:
            return ""
        joint, _, peak, plain, capture, when = worst
        at = "" if when is None else f" at {when:.3g} s"
        return f" ({joint} {number(peak)} rad/s^2{at}; plain {number(plain)}, capture {number(capture)})"
    if bound == "pelvis_acc":
        plain, capture = figures.get("plain_pelvis_acc_m_s2"), figures.get("capture_pelvis_acc_m_s2")
        when = figures.get("pelvis_acc_t_s")
        at = "" if when is None else f" at {when:.3g} s"
        return f" (peak{at}; plain {number(plain)}, capture {number(capture)} m/s^2)"
    plain, capture = figures.get("plain_torque_rms_Nm"), figures.get("capture_torque_rms_Nm")
    return f" (plain {number(plain)}, capture {number(capture)} N m)"


def _cause(name: str, conflicts: int) -> str:
    """A cause category, with the count of keyframe conflicts for "keyframes contradict the schedule"."""
    return f"{name} ({conflicts})" if name == "keyframes contradict the schedule" else name


def stance_lines(results: Sequence[dict]) -> list[str]:
    """Per clip, the contact schedule's recall and precision of the capture's stance frames
    (`runner.capture.stance.schedule_agreement`; the schedule is the clip's, whatever the keying)."""
    seen = {}
    for r in results:
        f = r["figures"]
        if "stance_recall" in f and "stance_precision" in f:
            seen.setdefault(Path(r["clip"]).stem, (f["stance_recall"], f["stance_precision"]))
    if not seen:
        return []
    return ["Contact schedule against the capture's stance (recall / precision of stance frames): "
            + ", ".join(f"{c} {rc:.3f} / {pr:.3f}" for c, (rc, pr) in sorted(seen.items())) + "."]


#: [s] a solve round's wall time per 10 s of clip the report counts pairs beyond: the bound on the rounds
#: (docs/corpus.md "Speed"); a round's cost grows with the clip's quadrature points, so it is per clip length
ROUND_PER_10_S = 5.0


def round_lines(results: Sequence[dict]) -> list[str]:
    """The solve rounds' line: the longest round per 10 s of clip [s] (wall time on this machine), its pair,
    and how many pairs have a round over `ROUND_PER_10_S`; [] when no pair recorded its rounds."""
    rows = [(10.0 * f["longest_round_s"] / f["clip_s"], r) for r in results
            for f in [r.get("figures", {})] if f.get("longest_round_s") is not None and f.get("clip_s")]
    if not rows:
        return []
    per10, worst = max(rows, key=lambda x: x[0])
    f = worst["figures"]
    over = sum(p > ROUND_PER_10_S for p, _ in rows)
    return [f"Solve rounds (wall time on this machine): the longest is {per10:.3g} s per 10 s of clip "
            f"({_pair_name(worst)}: {number(f['longest_round_s'])} s on a {number(f['clip_s'])} s clip); "
            f"{over}/{len(rows)} pairs have a round over {ROUND_PER_10_S:g} s per 10 s of clip."]


def markdown_report(results: Sequence[dict], rates: dict, meta: dict) -> str:
    """The whole report: a line on the run, the pass rates of both sets, then per set the pair table and
    the failing pairs, then the bounds' limits and the cause categories."""
    n_na = [b.name for b in BOUNDS if all(c["held"] is None for r in results for c in r["checks"]
                                          if c["bound"] == b.name)]
    lines = [f"# Corpus: {len(results)} pairs ({', '.join(meta.get('keyings', []))}), "
             f"{meta.get('workers', 1)} worker(s), {meta.get('engine', 'local')}, {meta.get('wall_time_s', 0):.0f} s",
             "", "Pass rate per bound (pairs where the bound could be measured) and of whole pairs:", "",
             *rate_table(rates)]
    if n_na:
        lines += ["", f"n/a: not measured by this build ({', '.join(n_na)})."]
    rounds = round_lines(results)
    if rounds:
        lines += ["", *rounds]
    for s in SETS:
        rs = [r for r in results if r["set"] == s]
        if not rs:
            continue
        clips = sorted({Path(r["clip"]).stem for r in rs})
        lines += ["", f"## {SET_TITLES[s]}: {', '.join(clips)}", "", *pair_table(rs), ""]
        failing = failing_lines(rs)
        lines += ["Failing pairs:", "", *(failing or ["- none"])]
        lines += ["", *stance_lines(rs)]
    lines += ["", "Causes: " + "; ".join(f"*{k}*: {v}" for k, v in CAUSES.items()) + f"; *{NOT_TOLD}*: none of these."]
    return "\n".join(lines) + "\n"
