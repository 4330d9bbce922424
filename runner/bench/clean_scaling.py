"""Cost of `dynsplines clean` against clip length (docs/scaling.md "Cleaning a longer clip"): the first L,
2L, 4L, 8L frames of one real continuous capture (by default), or a shipped clip looped 1x, 2x, 4x, 8x.

    python -m runner.bench.clean_scaling [--clip CLIP.bvh] [--factors 1,2,4,8] [--repeat 1] [--loop]

Prefixes (`prefix_bvh`, the default): with n captured frames after the rest frames and k the largest
factor, L = floor(n / k) frames, and the clip of factor f is the capture's first f L frames, cut from the
file as written (its header, `Frames:` set to the rows kept, the rows unchanged). Every length is the same
take, so it holds what a longer capture holds: more steps, turns, contacts and floats, each where the
subject made it, and no seam the capture did not have. The default clip is `PREFIX_CLIP`, a 26 s walk at
30 fps (models/long/zombie.bvh, Animated Drawings: 778 frames after its first, L = 97 frames, 3.2 s, at k = 8).

The loop (`loop_bvh`, `--loop`) plays the clip forward, then backward, then forward again, ...: every copy
after the first starts on the frame the one before it ended on (which it drops), so the looped clip is
continuous in every joint and in the root with no transform to choose for any skeleton or axes, exactly
`copies` times as long (frames after the rest frames: `copies` (n - 1) + 1), and each copy holds the same
contacts, floats and skates (played backward, a slide is the same distance). What a loop adds is a turn at
each seam: the velocities change sign there, over one frame, in the capture itself; its 6 Hz filtered
copy, the no-jolt constraint's reference, sees the turn too. On 16_23 (`LOOP_CLIP`, the loop's default,
2.5 s) the clean certifies every looped length infeasible at the seams and returns the least violation, so
the loop times that search more than a clean of a longer take.

Both keep the clip's leading rest frames (`REST_FRAMES`: the synthetic T-pose a CMU conversion starts
with) once, in front.

Each length is cleaned by `dynsplines clean --no-render` in its own subprocess (one BLAS thread); the CPU
time compared is the clean's own as its metrics report gives it (`cpu_time_s`: reading, retargeting,
contacts, the solve, the outputs), beside the whole process's (imports included). The cleaned clip is
measured afterwards by `runner.bench.clean_measure`, outside those times.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from runner.bench.scaling import SINGLE_THREAD
from runner.paths import MODELS

#: the prefixes' default clip: a 26 s walk (models/long/README.md: source, licence), L = 97 frames (3.2 s) at 8x
PREFIX_CLIP = MODELS / "long" / "zombie.bvh"
#: the loop's default clip
LOOP_CLIP = MODELS / "cmu" / "16_23.bvh"
#: leading frames of a shipped (CMU, cgspeed) clip that are its synthetic T-pose rest frame, kept once
REST_FRAMES = 1


def _split(src: Path, rest: int) -> tuple[list[str], list[str], list[str]]:
    """(the lines up to and including "MOTION", the "Frame Time:" line, the frame rows) of the BVH file `src`.

    Raises:
        ValueError: the file has no MOTION section, or fewer than `rest` frame rows.
    """
    lines = Path(src).read_text().splitlines()
    m = next((i for i, ln in enumerate(lines) if ln.strip() == "MOTION"), None)
    if m is None or len(lines) < m + 3:
        raise ValueError(f"{src}: no MOTION section with Frames: and Frame Time: lines")
    frames = [ln for ln in lines[m + 3:] if ln.strip()]
    if len(frames) < rest:
        raise ValueError(f"{src}: {len(frames)} frames, fewer than its {rest} rest frames")
    return lines[:m + 1], [lines[m + 2]], frames


def _write(dst: Path, head: list[str], frame_time: list[str], rows: list[str]) -> int:
    """Write a BVH file: `head` (up to "MOTION"), `Frames: len(rows)`, the frame time line, the rows. Returns
    the frames written."""
    Path(dst).write_text("\n".join([*head, f"Frames: {len(rows)}", *frame_time, *rows]) + "\n")
    return len(rows)


def prefix_bvh(src: Path, dst: Path, frames: int, rest: int = REST_FRAMES) -> int:
    """Write the first `frames` captured frames of `src` to `dst`, after its `rest` leading rest frames
    (module docstring): the header as written, `Frames:` the rows kept, the rows unchanged.

    Args:
        src: a BVH clip. dst: the prefix. frames: >= 2 captured frames, at most the clip's. rest: leading
            rest frames kept in front.
    Returns:
        the frames written (rest + frames).
    Raises:
        ValueError: the clip has no MOTION section, or `frames` is below 2 or beyond the clip's.
    """
    head, frame_time, rows = _split(src, rest)
    n = len(rows) - rest
    if not 2 <= frames <= n:
        raise ValueError(f"{src}: a prefix of {frames} frames; the clip has {n} after its {rest} rest frames "
                         "(give 2 to that many)")
    return _write(dst, head, frame_time, rows[:rest + frames])


def prefix_frames(src: Path, factors, rest: int = REST_FRAMES) -> dict[int, int]:
    """{factor: captured frames of its prefix}: factor f gets f L frames, L = floor(n / max(factors)) with n
    the clip's captured frames after its rest frames, so the lengths are in the factors' exact ratios.

    Raises:
        ValueError: the clip has no MOTION section, or L would be below 2 frames.
    """
    _, _, rows = _split(src, rest)
    n, top = len(rows) - rest, max(factors)
    unit = n // top
    if unit < 2:
        raise ValueError(f"{src}: {n} frames after {rest} rest frames; {top}x needs at least {2 * top}")
    return {f: f * unit for f in factors}


def loop_bvh(src: Path, dst: Path, copies: int, rest: int = REST_FRAMES) -> int:
    """Write `src` looped forward and backward `copies` times to `dst` (module docstring).

    Args:
        src: a BVH clip with at least rest + 2 frames. dst: the looped clip. copies: >= 1. rest: leading
            frames kept once, in front.
    Returns:
        the frames written.
    Raises:
        ValueError: copies < 1, or the clip has no MOTION section or too few frames.
    """
    if copies < 1:
        raise ValueError(f"copies must be at least 1, got {copies}")
    head_lines, frame_time, frames = _split(src, rest)
    head, motion = frames[:rest], frames[rest:]
    if len(motion) < 2:
        raise ValueError(f"{src}: {len(motion)} frames after {rest} rest frames; a loop needs at least 2")
    out = list(motion)
    for r in range(1, copies):
        out += (motion[::-1] if r % 2 else motion)[1:]
    return _write(dst, head_lines, frame_time, head + out)


def clean_one(clip: Path, out: Path) -> dict:
    """`dynsplines clean CLIP --no-render` in a subprocess with one BLAS thread, outputs in `out`: {"frames",
    "displacement_frames", "evals", "status", "cpu_s" (the clean's own CPU time [s], `cpu_time_s` of its
    metrics report), "process_cpu_s" (the whole subprocess's, imports included), and the cleaned clip's
    figures (`runner.bench.clean_measure.clean_figures_of`)}.

    Raises:
        RuntimeError: the command failed (its stderr in the message).
    """
    import resource

    from runner.bench.clean_measure import clean_figures_of

    cmd = [sys.executable, "-m", "runner", "clean", str(clip), "--out-dir", str(out), "--no-render", "--quiet",
           "--no-summary"]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    res = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, **SINGLE_THREAD}, check=False)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if res.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{res.stderr}")
    report = json.loads((out / f"{clip.stem}.clean.metrics.json").read_text())
    npz = out / f"{clip.stem}.clean.npz"
    f = clean_figures_of(npz, np.load(npz)["path_qpos"])
    return {"frames": report["frames"], "displacement_frames": report["displacement_frames"],
            "evals": report.get("n_evals"), "status": report["status"], "cpu_s": report["cpu_time_s"],
            "process_cpu_s": (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime),
            **{k: v for k, v in f.items() if k != "change_joint"}}


def clean_scaling(clip: Path, factors=(1, 2, 4, 8), repeat: int = 1, rest: int = REST_FRAMES,
                  loop: bool = False) -> list[dict]:
    """Per length factor and repeat (the lengths alternating), `clean_one` of the clip's prefix
    (`prefix_frames`, `prefix_bvh`) or, with `loop`, of the clip looped (`loop_bvh`): its dict with "factor"
    and "repeat".

    Raises:
        ValueError: the clip is too short for the factors (prefixes) or has no MOTION section.
        RuntimeError: a clean failed.
    """
    rows = []
    with tempfile.TemporaryDirectory(prefix="dynsplines-clean-scaling-") as tmp:
        paths = {f: Path(tmp) / f"{clip.stem}_x{f}.bvh" for f in factors}
        if loop:
            for f in factors:
                loop_bvh(clip, paths[f], f, rest)
        else:
            for f, frames in prefix_frames(clip, factors, rest).items():
                prefix_bvh(clip, paths[f], frames, rest)
        for rep in range(max(1, repeat)):
            for f in factors:
                rows.append(clean_one(paths[f], Path(tmp) / f"x{f}.{rep}") | {"factor": f, "repeat": rep})
    return rows


def print_rows(rows: list[dict]) -> None:
    """A row per length (median CPU over its repeats): frames, displacement frames, CPU, CPU per frame, the
    ratios to the first length, and the cleaned clip's penetration, skate and mean deviation."""
    factors = list(dict.fromkeys(r["factor"] for r in rows))
    cpu = {f: float(np.median([r["cpu_s"] for r in rows if r["factor"] == f])) for f in factors}
    first = {f: next(r for r in rows if r["factor"] == f) for f in factors}
    base = factors[0]
    proc = {f: float(np.median([r["process_cpu_s"] for r in rows if r["factor"] == f])) for f in factors}
    print(f"{'length':>6} {'frames':>6} {'disp fr':>7} {'evals':>5} {'cpu s':>7} {'proc s':>7} {'ms/frame':>8} "
          f"{'cpu/1x':>6} {'len/1x':>6} | {'pen mm':>6} {'skate':>6} {'dev cm':>6}  status")
    for f in factors:
        r = first[f]
        print(f"{f:>5}x {r['frames']:>6} {r['displacement_frames']:>7} {r['evals'] or 0:>5} {cpu[f]:>7.2f} {proc[f]:>7.2f} "
              f"{1e3 * cpu[f] / r['frames']:>8.2f} "
              f"{cpu[f] / cpu[base]:>6.2f} {r['frames'] / first[base]['frames']:>6.2f} | {r['penetration_mm']:>6.2f} "
              f"{r['skate_mm']:>6.2f} {r['deviation_mean_cm']:>6.2f}  {r['status']}")
    top = factors[-1]
    if top != base:
        print(f"CPU {top}x / {base}x: {cpu[top] / cpu[base]:.2f} (acceptance: at most {1.125 * top / base:g} "
              f"for {top / base:g}x the length)")


def preconditioner_rows(model, times, qpos, contacts, factors=(1, 2, 4, 8), repeat: int = 10) -> list[dict]:
    """Per length factor f: D's preconditioner on the grid of a clean of the capture's first f/max(factors) of its
    frames (`solver.displacement.build_displacement`, the contacts that end within them), the dense Kronecker one
    (`solver.lagrangian.frame_maps`) and the banded one (`solver.grid_preconditioner.grid_maps`) side by side in this
    process: {"factor", "frames", "build_ms" and "apply_ms" (each (dense, banded): the build's CPU time [ms] and an
    application's, `apply` and `apply_transpose`, the median of `repeat`), "eval_ms" (an evaluation of Phi and its
    gradient at the capture, for scale), "difference" (the largest relative difference of the two S S^T g over
    three random g: the same matrix, to round-off)}.

    Args:
        model: the scene's MjModel. times: (n,) [s]. qpos: (n, nq) the retargeted capture. contacts: its contacts.
    Raises:
        ValueError: the capture is too short for the factors (fewer than 4 frames at the shortest).
    """
    top, rows = max(factors), []
    for f in factors:
        n = len(times) * f // top
        if n < 4:
            raise ValueError(f"{len(times)} frames: {f}/{top} of them is {n}, fewer than the 4 a clean needs")
        rows.append({"factor": f, "frames": n} | _preconditioner_row(model, times[:n], qpos[:n],
                                                                     [c for c in contacts if c.end <= times[n - 1]], repeat))
    return rows


def _preconditioner_row(model, times, qpos, contacts, repeat: int) -> dict:
    """`preconditioner_rows`' figures of one clean's grid ("build_ms", "apply_ms", "eval_ms", "difference")."""
    import time

    from runner.bench.common import median_time
    from solver.displacement import build_displacement
    from solver.grid_preconditioner import grid_maps
    from solver.lagrangian import frame_maps
    from solver.manifold import FrameVariables

    lc = build_displacement(model, times, qpos, contacts=contacts).lc
    quat, frames = lc.layout.quat_slots, lc.plain  # the grid: a frame at every capture frame, free but at the pins
    cpu = time.process_time  # this process's CPU time
    built = [median_time(lambda maps=maps: maps(lc.al, frames, quat), 1, cpu) for maps in (frame_maps, grid_maps)]
    (basis, dense), (_, banded) = (maps for maps, _ in built)
    rng = np.random.default_rng(0)
    gs = [rng.standard_normal(dense.size) for _ in range(3)]
    applied = [median_time(lambda pre=pre: pre.apply(pre.apply_transpose(gs[0])), repeat, cpu) for pre in (dense, banded)]
    diff = max(float(np.linalg.norm(dense.apply(dense.apply_transpose(g)) - banded.apply(banded.apply_transpose(g)))
                     / np.linalg.norm(dense.apply(dense.apply_transpose(g)))) for g in gs)
    var = FrameVariables(frames, quat)
    _, ev = median_time(lambda: lc.al.evaluate(basis, var.values(np.zeros(var.size))), 3, cpu)
    return {"build_ms": tuple(1e3 * t for _, t in built), "apply_ms": tuple(1e3 * t for _, t in applied),
            "eval_ms": 1e3 * ev, "difference": diff}


def print_preconditioner_rows(rows: list[dict]) -> None:
    """A row per length: frames, the two preconditioners' build and application [ms], an evaluation's, the
    difference; and the growth of each from the shortest length to the longest against the length's."""
    print(f"{'length':>6} {'frames':>6} | {'build ms':>17} | {'apply ms':>15} | {'eval ms':>7} | {'S S^T g':>8}")
    print(f"{'':>6} {'':>6} | {'dense':>8} {'banded':>8} | {'dense':>7} {'banded':>7} | {'':>7} | {'rel diff':>8}")
    for r in rows:
        print(f"{r['factor']:>5}x {r['frames']:>6} | {r['build_ms'][0]:>8.1f} {r['build_ms'][1]:>8.1f} | "
              f"{r['apply_ms'][0]:>7.2f} {r['apply_ms'][1]:>7.2f} | {r['eval_ms']:>7.1f} | {r['difference']:>8.1e}")
    a, b = rows[0], rows[-1]
    if b["frames"] > a["frames"]:
        grow = [f"{what} {kind} x{b[key][i] / max(a[key][i], 1e-9):.1f}" for what, key in (("build", "build_ms"),
                ("apply", "apply_ms")) for i, kind in enumerate(("dense", "banded"))]
        print(f"{b['frames'] / a['frames']:.0f}x the frames: " + ", ".join(grow) +
              f"; an evaluation x{b['eval_ms'] / a['eval_ms']:.1f}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m runner.bench.clean_scaling", description=__doc__.splitlines()[0])
    p.add_argument("--clip", type=Path, default=None,
                   help="the BVH clip [prefixes: models/long/zombie.bvh; --loop: models/cmu/16_23.bvh]")
    p.add_argument("--factors", default="1,2,4,8", help="lengths, as multiples of the shortest [1,2,4,8]")
    p.add_argument("--repeat", type=int, default=1, help="cleans per length, alternating; median CPU [1]")
    p.add_argument("--rest-frames", type=int, default=REST_FRAMES, help=f"leading rest frames kept once [{REST_FRAMES}]")
    p.add_argument("--loop", action="store_true",
                   help="the clip looped forward and backward 1x..8x instead of the prefixes of one capture")
    args = p.parse_args(argv)
    factors = [int(f) for f in args.factors.split(",")]
    clip = args.clip or (LOOP_CLIP if args.loop else PREFIX_CLIP)
    how = (f"looped {args.factors}x (forward, backward, ...)" if args.loop
           else f"its first {args.factors} x L frames (L = its frames / {max(factors)})")
    print(f"clean scaling: {clip.name} {how}, `dynsplines clean --no-render` in one subprocess per length, "
          "one BLAS thread; cpu s: the clean's own, proc s: the process's")
    print_rows(clean_scaling(clip, factors, args.repeat, args.rest_frames, loop=args.loop))
    return 0


if __name__ == "__main__":
    sys.exit(main())
