"""Seeded random orientation keyframe sets, and the accuracy distribution of `orient` over them.

`random_set(seed)`: 4-9 keyframes, neighbouring orientations 20-170 degrees apart about random axes,
keyframe intervals whose neighbouring ratios are up to 5:1 (each interval is the previous one times
exp(uniform(-ln 5, ln 5)), kept within [0.2, 3] s). Deterministic per seed (numpy default_rng).

`evaluate(seeds, ...)`: runs `orient` on each set (default settings and `tol=1e-4`, or other runs
given) and measures the true relative gap (E - E*)/E* against the exact optimum E* (the natural
Riemannian cubic spline on S^3, computed independently by `runner.bench.sphere_reference`, which imports
nothing from solver; another reference module may be passed in or loaded from a path), with the
estimate the result reports, frames, wall time and max |1 - |q||.

Seeds: tune on 0-49 (`TUNING_SEEDS`), report acceptance on 1000-1049 (`ACCEPTANCE_SEEDS`), never used
for tuning.
"""
from __future__ import annotations

import importlib.util
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

TUNING_SEEDS = range(0, 50)
ACCEPTANCE_SEEDS = range(1000, 1050)
KEYFRAMES = (4, 9)
ANGLE_DEG = (20.0, 170.0)
MAX_INTERVAL_RATIO = 5.0
INTERVAL_S = (0.2, 3.0)


@dataclass(frozen=True)
class RandomSet:
    seed: int
    times: np.ndarray  # (K,) [s]
    quats: np.ndarray  # (K, 4) unit, w x y z (not hemisphere-aligned: orient does that)
    angles_deg: np.ndarray  # (K-1,) rotation between neighbours


def _qmul(a, b):
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw])


def random_set(seed: int) -> RandomSet:
    """One keyframe set (see the module docstring)."""
    rng = np.random.default_rng(seed)
    k = int(rng.integers(KEYFRAMES[0], KEYFRAMES[1] + 1))
    q0 = rng.normal(size=4)
    quats = [q0 / np.linalg.norm(q0)]
    angles = rng.uniform(*ANGLE_DEG, size=k - 1)
    for ang in angles:
        ax = rng.normal(size=3)
        ax /= np.linalg.norm(ax)
        a = np.radians(ang)
        quats.append(_qmul(quats[-1], np.concatenate([[np.cos(a / 2)], np.sin(a / 2) * ax])))
    dt = [rng.uniform(0.3, 2.0)]
    for _ in range(k - 2):
        dt.append(float(np.clip(dt[-1] * np.exp(rng.uniform(-1, 1) * np.log(MAX_INTERVAL_RATIO)), *INTERVAL_S)))
    times = np.concatenate([[0.0], np.cumsum(dt)])
    return RandomSet(seed, times, np.array(quats), angles)


def load_reference(path: str | Path):
    """A sphere reference module loaded from a file path (the default reference is the package
    `runner.bench.sphere_reference`; this is for another implementation of the same functions)."""
    path = Path(path)
    name = "_dynsplines_sphere_reference"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


def true_energy(ref, frames) -> float:
    """E of an orient result's normalized path by the reference module's own code (160 samples per
    spline segment, knots as breaks; no solver quadrature)."""
    t = np.concatenate([np.linspace(a, b, 161)[:-1] for a, b in zip(frames.times[:-1], frames.times[1:])]
                       + [frames.times[-1:]])
    return ref.covariant_energy(t, frames.path(t), breaks=frames.times)


@dataclass
class Run:
    seed: int
    label: str
    true_gap: float
    estimated_gap: float
    converged_to_tol: bool
    frames: int
    time_s: float
    drift: float


@dataclass
class Distribution:
    label: str
    runs: list = field(default_factory=list)

    def column(self, name) -> np.ndarray:
        return np.array([getattr(r, name) for r in self.runs], float)

    @property
    def ratio(self) -> np.ndarray:
        """true / estimated gap per set."""
        return self.column("true_gap") / self.column("estimated_gap")

    def within(self, factor: float = 3.0) -> int:
        r = self.ratio
        return int(np.sum((r <= factor) & (r >= 1.0 / factor)))

    def summary(self) -> str:
        def mmm(x, fmt):
            return "/".join(format(v, fmt) for v in (np.min(x), np.median(x), np.max(x)))

        n = len(self.runs)
        return (f"{self.label}: {n} sets; true gap min/med/max {mmm(self.column('true_gap'), '.2e')}; "
                f"estimated {mmm(self.column('estimated_gap'), '.2e')}; "
                f"true/est {mmm(self.ratio, '.2f')}, within 3x {self.within()}/{n}; "
                f"converged {int(self.column('converged_to_tol').sum())}/{n}; "
                f"frames {mmm(self.column('frames'), '.0f')}; time [ms] {mmm(1e3 * self.column('time_s'), '.1f')}; "
                f"max|1-|q|| {mmm(self.column('drift'), '.3f')}")


#: what `evaluate` runs by default: (label, orient keyword arguments)
RUNS = (("default", {}), ("tol=1e-4", {"tol": 1e-4}))


def exact_energy(ref, times, quats, method: str = "discrete", ref_tol: float = 1e-6) -> float:
    """E* of the exact optimum by the reference module: "discrete" (`discrete_sphere_reference`, fine
    discretization on the sphere with Richardson extrapolation, 1-5 s a set) or "bvp"
    (`riemannian_cubic_reference`, solve_bvp at `ref_tol`), falling back to the discrete one when
    solve_bvp fails. On the acceptance sets the two agreed to 6e-11-1.4e-9 relative where both
    ran; solve_bvp took from seconds to minutes a set on the loaded 2-core machine and ran out of memory
    on one set (docs/orient.md "Accuracy on request: tol and the gap estimate")."""
    if method == "bvp":
        try:
            return ref.riemannian_cubic_reference(times, quats, tol=ref_tol).E_star
        except (RuntimeError, MemoryError):
            pass
    elif method != "discrete":
        raise ValueError(f"unknown reference method {method!r}: 'discrete' or 'bvp'")
    return ref.discrete_sphere_reference(times, quats).E_star


def evaluate(seeds=ACCEPTANCE_SEEDS, reference=None, runs=RUNS, method: str = "discrete",
             ref_tol: float = 1e-6) -> dict:
    """Run `orient` on the random sets of `seeds` and measure each run against the exact optimum.

    Args:
        seeds: iterable of ints (`random_set`).
        reference: the sphere reference module, or a path to one (`load_reference`); default
            `runner.bench.sphere_reference`.
        runs: ((label, orient keyword arguments), ...).
        method, ref_tol: how E* is computed (`exact_energy`).
    Returns:
        {label: Distribution}.
    """
    from solver.paper.orient import orient

    if reference is None:
        from runner.bench import sphere_reference as reference
    ref = load_reference(reference) if isinstance(reference, (str, Path)) else reference
    out = {label: Distribution(label) for label, _ in runs}
    for seed in seeds:
        s = random_set(seed)
        E_star = exact_energy(ref, s.times, s.quats, method, ref_tol)
        for label, kw in runs:
            t0 = time.perf_counter()
            r = orient(s.times, s.quats, **kw)
            dt = time.perf_counter() - t0
            g = (true_energy(ref, r.frames) - E_star) / E_star
            out[label].runs.append(Run(seed, label, g, getattr(r, "estimated_gap", np.nan),
                                       bool(getattr(r, "converged_to_tol", False)), r.n_variable, dt,
                                       r.max_norm_deviation))
    return out


def main(argv=None) -> int:
    """python -m runner.bench.random_sets [N] [--tuning] [--bvp]: the distribution over N sets (default
    50) of the acceptance seeds (or the tuning seeds); E* by the discrete reference (or solve_bvp)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    base = TUNING_SEEDS if "--tuning" in argv else ACCEPTANCE_SEEDS
    nums = [a for a in argv if not a.startswith("--")]
    n = int(nums[0]) if nums else 50
    for d in evaluate(list(base)[:n], method="bvp" if "--bvp" in argv else "discrete").values():
        print(d.summary())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

