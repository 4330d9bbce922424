"""Figure 10 of the paper: Euler-Lagrange deviation integrated over tenths of the path.

    python -m runner.fig10 [KEYFRAMES.json] [--out renders/fig10_euler_lagrange.png]  (runner/commands/fig10.py)

Four paths through the same keyframes (default models/orient_example.json), as in the paper's figure:
the initial spline (keyframes only, dotted), one variable frame per keyframe interval (dashed), three
per interval (solid), and adaptive subdivision with only a few frames placed where the Euler-Lagrange
score is highest (dash-dot). For each, the strong-form residual of eq. 10-11 on the orientation shown
(u = q/|q|, tangential part; runner.euler_lagrange) is integrated over each tenth of the path.
`dynsplines orient ... --plot FILE.png` draws the same panel for its keyframes, with its own result added.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from runner.euler_lagrange import deviation_by_region
from runner.files import atomic_output
from solver.paper.orient import check_keyframes, default_options, orient

#: variable frames of the adaptive curve (the paper's used 2)
ADAPTIVE_FRAMES = 2
#: (label, matplotlib line style) of the figure's curves, in the paper's styles
CURVES = {
    "initial spline": ":",
    "1 per interval (global)": "--",
    "3 per interval (global)": "-",
    f"adaptive, {ADAPTIVE_FRAMES} frames": "-.",
}


def compute(times, quats, n_regions: int = 10) -> dict:
    """The figure's data.

    Args:
        times: (k,) keyframe times [s]. quats: (k, 4) keyframe quaternions (w x y z).
    Returns:
        {label: (frames FrameSet, deviation (n_regions,) [1/s^3])} for the four curves of `CURVES`.
    """
    runs = {
        "1 per interval (global)": default_options(subdivision="global", per_segment=1),
        "3 per interval (global)": default_options(subdivision="global", per_segment=3),
        f"adaptive, {ADAPTIVE_FRAMES} frames": default_options(per_segment=0, rounds=1, per_round=ADAPTIVE_FRAMES),
    }
    out = {}
    first = None
    for label, opts in runs.items():
        r = orient(times, quats, options=opts)
        if first is None:
            first = r
            init = r.solution.initial
            out["initial spline"] = (init, _deviation(init, n_regions))
        out[label] = (r.frames, _deviation(r.frames, n_regions))
    return {label: out[label] for label in CURVES}


def _deviation(frames, n_regions):
    return deviation_by_region(frames.times, frames.values, n_regions=n_regions, normalized=True)


def figure10(times, quats, out_png, result=None, source: str = "keyframes") -> dict:
    """Compute and plot figure 10 for these keyframes; write a PNG.

    Args:
        times, quats: keyframes (see `compute`). out_png: output file (.png).
        result: an OrientResult to add as a fifth curve ("this run"), e.g. from `dynsplines orient`.
        source: name of the keyframes in the title.
    Returns:
        {label: deviation (10,) [1/s^3]}.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    check_keyframes(times, quats, source)
    data = compute(times, quats)
    rows = {label: dev for label, (_, dev) in data.items()}
    frames_used = {label: fr.n_variable for label, (fr, _) in data.items()}
    if result is not None:
        label = f"this run ({result.n_variable} frames)"
        rows[label] = _deviation(result.frames, 10)
        frames_used[label] = result.n_variable
    fig, ax = plt.subplots(figsize=(7.5, 4.5), dpi=120)
    x = np.arange(1, 11)
    for label, dev in rows.items():
        style = CURVES.get(label, "-")
        name = label if label not in CURVES or label == "initial spline" else f"{label} [{frames_used[label]}]"
        ax.plot(x, dev, style, marker="o", ms=3, lw=2.2 if label in CURVES else 1.2, label=name,
                color=None if label in CURVES else "0.5")
    ax.set_yscale("log")
    ax.set_xticks(x)
    ax.set_xlabel("tenth of the path")
    ax.set_ylabel(r"$\int |EL(t)|\,dt$ over the tenth  [1/s$^3$]")
    ax.set_title(f"Euler-Lagrange deviation (eq. 10-11, on q/|q|): {Path(source).name}", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, title="variable frames in [ ]", title_fontsize=8)
    fig.tight_layout()
    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    with atomic_output(out_png, suffix=".png") as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return rows


def format_table(rows: dict) -> str:
    """The figure's numbers as a text table: one row per curve, one column per tenth, and the total."""
    head = f"{'curve':<28}" + "".join(f"{k:>9}" for k in range(1, 11)) + f"{'total':>10}"
    lines = [head]
    for label, dev in rows.items():
        lines.append(f"{label:<28}" + "".join(f"{v:9.3g}" for v in dev) + f"{dev.sum():10.4g}")
    return "\n".join(lines)

