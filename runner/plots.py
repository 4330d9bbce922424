"""`--plot DIR`: figures of what the optimization did (matplotlib, Agg backend, PNG).

    foot_heights.png    height of the four contact sites above the surface below them [mm] over time:
                        plain spline, optimized, motion capture; keyframe times marked, contacts shaded
    dynamics.png        joint torque and root residual force over time (plain vs optimized), flight
                        phases shaded (the definitions of `solver.metrics`)
    objective.png       the measure of change E after each evaluation, subproblems marked
    euler_lagrange.png  the Euler-Lagrange residual per segment before and after refinement (the weighted
                        objective's weak-form score, or the least change's predicted decrease)

Only drawing here: the numbers come from `solver.metrics` and `solver.subdivide`.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from solver.errors import InputError
from solver.figure import Figure
from solver.layout import site_ids
from solver.metrics import dynamics_series, sample_times
from solver.surfaces import StaticSurfaces
from solver.terms.penetration import site_positions

#: line styles of the three motions, the same in every figure
STYLE = {
    "plain spline": dict(color="#d62728", lw=1.3, alpha=0.9),
    "optimized": dict(color="#1f77b4", lw=1.8),
    "motion capture": dict(color="0.35", lw=1.0, ls="--"),
}


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _savefig(fig, path) -> None:
    """PNG written atomically (runner.files.atomic_output): never a truncated figure."""
    from runner.files import atomic_output

    with atomic_output(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110, format="png")


def _site_heights(model, data, surfaces, sites, Y) -> np.ndarray:
    return surfaces.height_above(site_positions(model, data, Y, sites))


def _mark_keyframes(ax, keyframe_times, label=True):
    for i, tk in enumerate(keyframe_times):
        ax.axvline(tk, color="0.75", lw=0.8, zorder=0, label="keyframe" if (label and i == 0) else None)


def _shade(ax, t, mask, color, label=None):
    """Shade the intervals of t where mask is True."""
    if not np.any(mask):
        return
    m = np.concatenate([[False], mask, [False]]).astype(int)
    starts = np.flatnonzero(np.diff(m) == 1)
    ends = np.flatnonzero(np.diff(m) == -1) - 1
    for i, (a, b) in enumerate(zip(starts, ends)):
        ax.axvspan(t[a], t[b], color=color, alpha=0.15, lw=0, label=label if i == 0 else None, zorder=0)


def foot_height_title(surfaces: StaticSurfaces) -> str:
    """The foot-height figure's title for the scene's surfaces: the floor only, or the floor and its
    boxes (named), where a site's height jumps as it crosses a box's edge.

    Args:
        surfaces: the scene's `StaticSurfaces` (planes first in `names`, then boxes).
    Returns:
        two lines of text.
    """
    n_planes = len(surfaces.plane_point)
    boxes = list(surfaces.names[n_planes:])
    if not boxes:
        return ("Contact-site height above the floor; below 0 = inside the floor\n"
                "(a flat scene: heights are measured from the floor everywhere)")
    tops = ", ".join(boxes[:4]) + (f" and {len(boxes) - 4} more" if len(boxes) > 4 else "")
    return (f"Contact-site height above the surface below it (the floor, or the top of {tops}); below 0 = "
            "inside it;\na jump is a site crossing the edge of a box")


def plot_foot_heights(path, model, tracks: dict, keyframe_times, rate: float = 500.0, contacts=()) -> Path:
    """Heights of the contact sites above the surface below them, one panel per site.

    Args:
        path: output PNG. model: the scene's MjModel.
        tracks: {label: (frame_times (m,), frames (m, nq))} splines, or {label: (times, qpos, "samples")}
            for sampled motion (the motion capture).
        keyframe_times: (k,) [s]. rate: samples per second of the splines.
        contacts: `solver.contacts.Contact`s (the reference's or the keyframe file's), shaded green on
            their site's panel over [start, end], labelled with the surface.
    """
    import mujoco

    from solver.spline import interpolate

    plt = _pyplot()
    data = mujoco.MjData(model)
    surfaces = StaticSurfaces.from_model(model, data)
    names = Figure.from_model(model).contact_sites
    sites = site_ids(model, names)
    t0, t1 = float(keyframe_times[0]), float(keyframe_times[-1])
    fig, axes = plt.subplots(len(names), 1, figsize=(10, 8.5), sharex=True)
    lo, hi = 0.0, 50.0  # [mm] the y range of the data, the same on every panel
    for label, track in tracks.items():
        if len(track) == 3:  # samples
            t, Y = np.asarray(track[0]), np.asarray(track[1])
            keep = (t >= t0 - 1e-9) & (t <= t1 + 1e-9)
            t, Y = t[keep], Y[keep]
        else:
            t = sample_times(t0, t1, rate)
            Y = interpolate(track[0], track[1], t)
        h = _site_heights(model, data, surfaces, sites, Y) * 1000.0
        finite = h[np.isfinite(h)]
        if finite.size:
            lo, hi = min(lo, float(finite.min())), max(hi, float(finite.max()))
        for k, ax in enumerate(axes):
            ax.plot(t, h[:, k], label=label, **STYLE.get(label, {}))
    for k, (ax, name) in enumerate(zip(axes, names)):
        ax.axhline(0.0, color="k", lw=0.8)
        ax.axhspan(-1e4, 0.0, color="#d62728", alpha=0.06, lw=0)
        _mark_keyframes(ax, keyframe_times, label=(k == 0))
        mine = [c for c in contacts if c.site == name]
        for i, c in enumerate(mine):
            ax.axvspan(c.start, c.end, color="#2ca02c", alpha=0.15, lw=0, zorder=0,
                       label="contact (reference)" if i == 0 else None)
            if c.surface:
                ax.text((c.start + c.end) / 2, 0.97, c.surface, transform=ax.get_xaxis_transform(),
                        ha="center", va="top", fontsize=7, color="#2ca02c")
        ax.set_ylabel(f"{name}\nheight [mm]")
        ax.set_ylim(max(lo, -150.0) - 15.0, hi + 0.25 * (hi - lo))  # headroom for the legend
        ax.grid(alpha=0.3)
    handles, labels = [], []
    for ax in axes:  # the contact label may be on any panel
        for h_, l_ in zip(*ax.get_legend_handles_labels()):
            if l_ not in labels:
                handles.append(h_)
                labels.append(l_)
    axes[0].legend(handles, labels, loc="upper left", ncol=5, fontsize=9, framealpha=0.9)
    axes[0].set_title(foot_height_title(surfaces), fontsize=10)
    axes[-1].set_xlabel("time [s]")
    fig.tight_layout()
    _savefig(fig, path)
    plt.close(fig)
    return Path(path)


def plot_dynamics(path, series: dict, keyframe_times) -> Path:
    """Joint torque and root residual force over time, plain spline vs optimized.

    Args:
        path: output PNG. series: {label: `solver.metrics.dynamics_series` result} (same times).
        keyframe_times: (k,) [s].
    """
    plt = _pyplot()
    fig, (a1, a2, a3) = plt.subplots(3, 1, figsize=(10, 9), sharex=True)
    for label, s in series.items():
        st = STYLE.get(label, {})
        t = s["t"]
        a1.plot(t, np.linalg.norm(s["joint_torque"], axis=1), label=label, **st)
        a2.plot(t, np.linalg.norm(s["root_force"], axis=1), label=label, **st)
        a3.plot(t, np.linalg.norm(s["root_torque"], axis=1), label=label, **st)
    colors = {"plain spline": "#d62728", "optimized": "#1f77b4"}
    for label, s in series.items():
        for ax in (a2, a3):
            _shade(ax, s["t"], s["flight"], colors.get(label, "0.5"),
                   label=f"flight, {label}" if ax is a2 else None)
    for k, ax in enumerate((a1, a2, a3)):
        _mark_keyframes(ax, keyframe_times, label=(k == 0))
        ax.grid(alpha=0.3)
        ax.set_ylim(bottom=0.0)
    a1.set_ylabel("joint torque |tau| [N m]\n(33 ball-joint DOFs)")
    a2.set_ylabel("root residual force |F| [N]")
    a3.set_ylabel("root residual torque |T| [N m]")
    a1.set_title("Contact-free inverse dynamics: joint torques, and the wrench on the root besides gravity\n"
                 "(should be 0 in flight; on the ground the feet supply it)")
    a1.legend(loc="upper left", fontsize=9)
    a2.legend(loc="upper left", fontsize=9, ncol=2)
    a3.set_xlabel("time [s]")
    fig.tight_layout()
    _savefig(fig, path)
    plt.close(fig)
    return Path(path)


def plot_objective(path, solution) -> Path:
    """The measure of change E (best so far) after each evaluation, subproblems marked (each an L-BFGS
    run of the method of multipliers; between them the multipliers, the penalty or the frames change).

    Args:
        path: output PNG. solution: `solver.paper.solve.Solution`.
    """
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(10, 4.8))
    start = 0
    for i, rnd in enumerate(solution.rounds):
        tr = np.asarray(rnd.result.trace)
        x = start + np.arange(1, len(tr) + 1)
        ax.plot(x, tr, lw=1.6, label=f"subproblem {i + 1}: {rnd.n_variable} variable frames")
        if i:
            ax.axvline(start + 0.5, color="0.6", lw=0.8, ls=":")
        start += len(tr)
    ax.set_yscale("log")
    ax.set_xlabel("objective evaluation")
    ax.set_ylabel("augmented Lagrangian (E + multiplier terms)")
    ax.set_title("The least change during the optimization (best so far after each evaluation)\n"
                 "between subproblems the multipliers and the penalty are updated, or frames are added",
                 fontsize=10)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, ncol=2)
    fig.tight_layout()
    _savefig(fig, path)
    plt.close(fig)
    return Path(path)


#: the Euler-Lagrange figure's floor, relative to its largest bar (dimensionless): eight decades show
#: where refinement pays; below them a segment is as good as optimal (or too short to split)
FLOOR_RATIO = 1e-8
#: the axis and title of the Euler-Lagrange figure: the weighted objective's scores (`solve`), the least
#: change's predicted decreases
EL_LABELS = {
    "solve": ("|dE/dP| of a midpoint frame\n[E per unit of qpos]",
              "Weak-form Euler-Lagrange score per segment (solver.subdivide.weak_form_scores):\n"
              "how fast E would fall if a frame were added at the segment's midpoint"),
    "least change": ("predicted decrease of Phi\nby a midpoint frame [1]",
                     "Euler-Lagrange residual of the augmented integrand per segment (solver.least_change_refine):\n"
                     "the decrease of Phi a frame at the segment's midpoint predicts"),
}


def plot_euler_lagrange(path, before: tuple, after: tuple, keyframe_times, chosen=None, kind: str = "solve") -> Path:
    """The Euler-Lagrange residual per segment, before and after refinement (bars over segments).

    Args:
        path: output PNG.
        before, after: (frame_times (m,), scores (m-1,)) of the two frame sets.
        keyframe_times: (k,) [s]. chosen: times of the frames the refinement added (marked).
        kind: "solve" (weak-form scores of the weighted objective) or "least change" (predicted
            decreases of Phi), for the axis and title (`EL_LABELS`).
    """
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(10, 4.8))
    top = max([float(np.max(sc)) for _, sc in (before, after) if len(sc)] + [1e-300])
    floor = FLOOR_RATIO * top  # a segment too short to split (or already optimal) is drawn at the floor
    for (times, scores), label, color in ((before, "before refinement", "#d62728"),
                                          (after, "after refinement", "#1f77b4")):
        times = np.asarray(times)
        scores = np.maximum(np.asarray(scores), floor)
        ax.stairs(scores, times, label=f"{label} ({len(times)} frames)", color=color, lw=1.8,
                  baseline=None)
    _mark_keyframes(ax, keyframe_times)
    ax.set_yscale("log")
    ax.set_ylim(bottom=floor)
    if chosen is not None and len(chosen):
        ax.plot(chosen, np.zeros(len(chosen)), "^", color="k", ms=7, clip_on=False,
                transform=ax.get_xaxis_transform(), label="frames added by refinement")
    ax.set_xlabel("time [s]")
    ax.set_ylabel(EL_LABELS[kind][0])
    ax.set_title(EL_LABELS[kind][1])
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=9)
    fig.tight_layout()
    _savefig(fig, path)
    plt.close(fig)
    return Path(path)


def plot_solution(directory, model, solution, keyframes, reference=None, objective=None, contacts=()) -> list[Path]:
    """Write the figures of a solved run into `directory` (created if missing).

    Args:
        directory: output folder. model: the scene's MjModel. solution: `solver.paper.solve.Solution`.
        keyframes: the keyframes. reference: motion capture (`.times`, `.qpos`) or None.
        objective: the solved Objective, for the Euler-Lagrange scores after refinement; without it
            the least change's own (`Solution.segment_decreases`: the first check against the last on
            the final frames; the figure is skipped when there is neither). contacts: Contacts shaded in the foot-height plot.
    Returns:
        the written paths.
    """
    from solver.subdivide import weak_form_scores

    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    out = []
    tracks = {"plain spline": (solution.initial.times, solution.initial.values),
              "optimized": (solution.frames.times, solution.frames.values)}
    if reference is not None and len(reference.times):
        tracks["motion capture"] = (reference.times, reference.qpos, "samples")
    out.append(plot_foot_heights(d / "foot_heights.png", model, tracks, keyframes.times, contacts=contacts))
    try:
        series = {label: dynamics_series(model, fs.times, fs.values, rate=500.0)
                  for label, fs in (("plain spline", solution.initial), ("optimized", solution.frames))}
    except InputError:  # a model the analytic inverse dynamics does not support: no such figure
        series = None
    if series is not None:
        out.append(plot_dynamics(d / "dynamics.png", series, keyframes.times))
    out.append(plot_objective(d / "objective.png", solution))
    if objective is not None:
        rounds = solution.rounds
        i = next((k for k, r in enumerate(rounds) if k and r.scores is not None and rounds[k - 1].times is not None),
                 None)
        if i is not None:  # the scores that chose the first adaptive frames, on the frames before them
            before = (rounds[i - 1].times, rounds[i].scores)
        else:  # no adaptive round: the scores on the frames the optimization started with
            before = (solution.initial.times, weak_form_scores(objective, solution.initial))
        added = np.setdiff1d(solution.frames.times, before[0])
        after = (solution.frames.times, weak_form_scores(objective, solution.frames))
        out.append(plot_euler_lagrange(d / "euler_lagrange.png", before, after, keyframes.times, added))
    elif _least_change_checks(solution) is not None:
        before, after = _least_change_checks(solution)
        added = np.setdiff1d(solution.frames.times, before[0])
        out.append(plot_euler_lagrange(d / "euler_lagrange.png", before, after, keyframes.times, added,
                                       kind="least change"))
    return out


def _least_change_checks(solution):
    """(before, after) of the least change's refinement checks: the first, and the last when it was made
    on the final frames; None with fewer than two such checks."""
    checks = getattr(solution, "segment_decreases", ()) or ()
    if len(checks) < 2 or not np.array_equal(checks[-1][0], solution.frames.times):
        return None
    return checks[0], checks[-1]

