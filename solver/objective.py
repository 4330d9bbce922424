"""The objective E = sum_j lambda_j integral f_j(Y, Y', Y'') dt (paper eq. 1), optionally renormalized
by each term's value on the initial path (eq. 7), and its gradient with respect to the frame values.

Quadrature is uniform (midpoint) as in the paper, or (`quadrature="gauss"`) Gauss-Legendre on every
spline segment: the integrand is smooth inside a segment, so a few nodes per segment integrate it far
more accurately than a uniform grid of the same size. Renormalization divides each term's *integral* by its
integral on the plain spline (the initial path), so every active term starts at lambda_j. The paper
writes the ratio inside the integral; pointwise it is undefined where the initial integrand is zero
(a foot above the floor), so we take the ratio of integrals; a term that is zero on the initial path
keeps scale 1 (its own units).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from solver.errors import DynsplinesError, InputError
from solver.path_context import PathContext
from solver.quadrature import GAUSS_POINTS, check_points, gauss_times, quadrature_times
from solver.spline import BLOCK_DOUBLES
from solver.spline_basis import SplineBasis
from solver.terms.base import Term, TermEval
from solver.terms.covariant import NormalizedCovariantAcceleration, unit_and_normalized
from solver.terms.unit import UnitQuaternion

#: Plain-spline integrals below this keep their term's scale 1 in `Objective.renormalize` (as a term
#: that is zero there does): a term that is zero up to rounding on the plain spline (a penetration of
#: 1e-16 m, an integral ~1e-31) would otherwise be divided by its rounding error and weigh ~1e30 times
#: its weight. 1e-12 [the term's units x s]: a residual of 1e-6 (1 micrometre, 1e-6 rad) over 1 s.
RENORMALIZE_FLOOR = 1e-12

#: Quadrature rules: "uniform" (midpoint rule at `rate` points per second, the paper's) and "gauss"
#: (Gauss-Legendre with `points` nodes on every spline segment; the nodes move with the frames).
QUADRATURES = ("uniform", "gauss")


class NonFiniteError(DynsplinesError):
    """A term produced NaN or inf; `term` names it."""

    def __init__(self, term: str, what: str):
        super().__init__(f"objective term {term!r} produced a non-finite {what}")
        self.term = term


@dataclass
class Evaluation:
    """One evaluation of the objective.

    Attributes:
        E: total weighted (normalized) objective.
        grad: (m, nq) dE/dP, or None.
        integrals: {term name: integral of f_j dt in the term's units times s} (unweighted, unnormalized).
    """

    E: float
    grad: np.ndarray | None
    integrals: dict[str, float]


@dataclass
class Objective:
    """Weighted sum of terms integrated over [t0, t1] by uniform quadrature.

    Attributes:
        terms: the objective terms.
        weights: (len(terms),) lambda_j >= 0.
        t0, t1: time interval [s] (the first and last keyframe).
        rate: quadrature points per second [1/s]; uniform quadrature needs it, Gauss quadrature ignores it.
        scales: (len(terms),) divisors of each integral (1 unless `renormalize` was called).
        quadrature: one of QUADRATURES. "gauss" needs terms without per-point state (no `prepare`,
            no `Term.fixed_points`: not the contact and inverse-dynamics terms), since its nodes change
            with the frames.
        points: Gauss-Legendre nodes per spline segment (quadrature "gauss").
        t, h: the uniform quadrature's points (n,) [s] and weight [s]; None with "gauss" (the nodes
            and weights of a frame set are its `basis(knots)`'s t and weights).
    Raises:
        InputError: negative or non-finite weight, weights/terms length mismatch, bad interval or rate,
            more than MAX_QUADRATURE_POINTS quadrature points, unknown quadrature, bad `points`, a term
            "gauss" does not support.
    """

    terms: list[Term]
    weights: np.ndarray
    t0: float
    t1: float
    rate: float | None = None
    scales: np.ndarray = field(default=None)
    quadrature: str = "uniform"
    points: int = GAUSS_POINTS

    def __post_init__(self):
        self.weights = np.asarray(self.weights, dtype=float).reshape(-1)
        if len(self.weights) != len(self.terms):
            raise InputError(f"{len(self.terms)} objective terms but {len(self.weights)} weights")
        for term, w in zip(self.terms, self.weights):
            if not np.isfinite(w) or w < 0:
                raise InputError(f"weight of objective term {term.name!r} is {w}; weights must be >= 0")
        if not (np.isfinite(self.t0) and np.isfinite(self.t1) and self.t1 > self.t0):
            raise InputError(f"objective interval [{self.t0}, {self.t1}] s is empty")
        if self.quadrature not in QUADRATURES:
            raise InputError(f"unknown quadrature {self.quadrature!r}; choose one of: {', '.join(QUADRATURES)}")
        if self.quadrature == "gauss":
            if not isinstance(self.points, (int, np.integer)) or isinstance(self.points, bool) or self.points < 1:
                raise InputError(f"Gauss quadrature points per segment must be a whole number >= 1, got {self.points!r}")
            for term in self.terms:
                if term.fixed_points or type(term).prepare is not Term.prepare:
                    raise InputError(f"objective term {term.name!r} keeps per-point state, which Gauss quadrature "
                                     "(nodes moving with the frames) does not support; use quadrature='uniform'")
        if self.quadrature == "uniform":
            if self.rate is None:
                raise InputError("uniform quadrature needs rate= (points per second, e.g. 400), or use quadrature='gauss'")
            if not np.isfinite(self.rate) or self.rate <= 0:
                raise InputError(f"quadrature rate {self.rate} must be > 0 points per second")
            check_points(self.t0, self.t1, self.rate)
        if self.scales is None:
            self.scales = np.ones(len(self.terms))
        if self.quadrature == "uniform":
            self.t, self.h = quadrature_times(self.t0, self.t1, self.rate)
        else:
            self.t, self.h = None, None
        self._needs = tuple(sorted({k for term in self.terms for k in term.needs}))
        self._basis_cache: dict[bytes, SplineBasis] = {}
        # the orientation objective (unit + normalized covariant acceleration of one quaternion filling
        # the state) with Gauss quadrature: one fused pass (`unit_and_normalized`) in `evaluate_path`
        self._fused = (self.quadrature == "gauss" and len(self.terms) == 2
                       and type(self.terms[0]) is UnitQuaternion and self.terms[0].single_quaternion
                       and type(self.terms[1]) is NormalizedCovariantAcceleration and self.terms[1].single_quaternion)

    @property
    def fused_orientation(self) -> bool:
        """True for the orientation objective (unit + normalized covariant acceleration of one
        quaternion filling the state, Gauss quadrature), which `unit_and_normalized` evaluates in one
        pass (`evaluate_path`, and `solver.paper.round`'s component-major fast path)."""
        return self._fused

    @property
    def names(self) -> list[str]:
        """The terms' names, in order."""
        return [term.name for term in self.terms]

    @property
    def needs(self) -> tuple[int, ...]:
        """Which spline derivatives the terms read, sorted: 0 (Y), 1 (Y'), 2 (Y'')."""
        return self._needs

    def basis(self, knots: np.ndarray) -> SplineBasis:
        """The spline matrices for a frame set's knots at this objective's quadrature points (cached)."""
        key = np.asarray(knots, float).tobytes()
        b = self._basis_cache.get(key)
        if b is None:
            if len(self._basis_cache) > 8:
                self._basis_cache.clear()
            knots = np.asarray(knots, float)
            if self.quadrature == "gauss":
                b = SplineBasis(knots, *gauss_times(knots, self.points))
            else:
                b = SplineBasis(knots, self.t)
            self._basis_cache[key] = b
        return b

    def evaluate(self, knots: np.ndarray, P: np.ndarray, grad: bool = True) -> Evaluation:
        """E and dE/dP for frames P at knot times `knots`.

        Args:
            knots: (m,) frame times [s]. P: (m, nq) frame values.
            grad: compute the gradient.
        Returns:
            Evaluation.
        Raises:
            NonFiniteError: a term returned NaN/inf (value or gradient); names the term.
        """
        basis = self.basis(knots)
        Y, Y1, Y2 = basis.evaluate(P, self._needs)
        E, integrals, acc = self.evaluate_path(basis, Y, Y1, Y2, grad)
        G = None
        if grad:
            G = np.zeros_like(P) if all(a is None for a in acc) else basis.pullback(*acc)
            if not np.all(np.isfinite(G)):
                raise NonFiniteError(self.blame(basis, Y, Y1, Y2), "gradient")
        return Evaluation(E, G, integrals)

    def evaluate_path(self, basis: SplineBasis, Y, Y1, Y2, grad: bool = True):
        """E, the term integrals and dE/dY, dE/dY', dE/dY'' for a path given at the quadrature points
        of `basis`: the part of `evaluate` before the chain rule through the spline.

        Args:
            basis: `basis(knots)` of the frame set. Y, Y1, Y2: (n, nq) at basis.t (None if not needed).
            grad: compute the gradients.
        Returns:
            (E, {term name: integral}, [dE/dY, dE/dY', dE/dY''] (each (n, nq), or None where no term
            depends on it; all None without grad)).
        Raises:
            NonFiniteError: a term's integral is NaN/inf; names the term.
        """
        if self._fused and Y.shape[1] == 4 and basis.weights is not None:
            return self._evaluate_fused(basis, Y, Y1, Y2, grad)
        t = basis.t
        wq = None if basis.weights is None else basis.weights[:, None]
        E = 0.0
        integrals = {}
        acc = [None, None, None]  # dE/dY, dE/dY', dE/dY'' at the quadrature points
        deferred = {}  # key -> summed deferred gradient (terms sharing an engine)
        ctx = PathContext(t, Y, Y1, Y2)  # each engine's forward pass once, for every term that reads it
        terms = list(zip(self.terms, self.weights, self.scales))
        block = max(64, BLOCK_DOUBLES // max(1, Y.shape[1]))
        i = 0
        while i < len(terms):
            j = i + 1
            if len(t) > 4 * block and terms[i][0].pointwise:  # a run of pointwise terms, block by block
                while j < len(terms) and terms[j][0].pointwise:
                    j += 1
                evs = self._blocked(terms[i:j], block, t, Y, Y1, Y2, wq, grad, acc)
            else:
                term, w = terms[i][:2]
                evs = [term.evaluate_in(ctx, grad=grad and w != 0.0)]
            for (term, w, s), ev in zip(terms[i:j], evs):
                I = float(self.h * ev.f.sum()) if wq is None else float(basis.weights @ ev.f)
                if not math.isfinite(I):
                    raise NonFiniteError(term.name, "value")
                integrals[term.name] = I
                if w == 0.0:
                    continue
                if wq is None:
                    c = self.h * w / s
                    E += c * ev.f.sum()
                else:
                    c = (w / s) * wq
                    E += (w / s) * I
                if grad:
                    for k, g in enumerate((ev.dY, ev.dY1, ev.dY2)):
                        if g is not None:
                            if acc[k] is None:
                                acc[k] = c * g
                            else:
                                acc[k] += c * g
                    d = ev.deferred
                    if d is not None:
                        deferred[d.key] = d.scaled(c) if d.key not in deferred else deferred[d.key].plus(d, c)
            i = j
        if grad:
            for d in deferred.values():  # one reverse pass per shared engine
                for k, g in enumerate(d.pullback()):
                    if g is not None:
                        acc[k] = g if acc[k] is None else acc[k] + g
        return E, integrals, acc

    def _blocked(self, run, block, t, Y, Y1, Y2, wq, grad, acc) -> list[TermEval]:
        """Pointwise terms `run` ((term, weight, scale), ...) on blocks of `block` points, term after
        term within a block, their weighted gradients added to `acc` (allocated here if None) block by
        block: element by element the same sums in the same order as whole-path evaluation (the same
        bits), with temporaries a block long.

        Returns:
            one TermEval per term with its whole f (n,) and no gradients (they are in `acc`).
        """
        n = len(t)
        fs = [np.empty(n) for _ in run]
        for a in range(0, n, block):
            b = slice(a, a + block)
            for (term, w, s), f in zip(run, fs):
                ev = term.evaluate(t[b], Y[b], None if Y1 is None else Y1[b], None if Y2 is None else Y2[b],
                                   grad=grad and w != 0.0)
                f[b] = ev.f
                if not (grad and w != 0.0):
                    continue
                c = self.h * w / s if wq is None else (w / s) * wq[b]
                for k, g in enumerate((ev.dY, ev.dY1, ev.dY2)):
                    if g is not None:
                        if acc[k] is None:
                            acc[k] = np.zeros((n,) + g.shape[1:])
                        acc[k][b] += c * g
        return [TermEval(f) for f in fs]

    def _evaluate_fused(self, basis: SplineBasis, Y, Y1, Y2, grad: bool):
        """`evaluate_path` for the orientation objective (`_fused`): the same results in one pass."""
        (w1, w2), (s1, s2) = self.weights, self.scales
        c1, c2 = w1 / s1, w2 / s2
        X = np.empty((3, 4, len(Y)))  # component-major for the kernel
        X[0], X[1], X[2] = Y.T, Y1.T, Y2.T
        I1, I2, D = unit_and_normalized(X, basis.weights, c1, c2, grad)
        for term, I in zip(self.terms, (I1, I2)):
            if not math.isfinite(I):
                raise NonFiniteError(term.name, "value")
        E = (c1 * I1 if w1 != 0.0 else 0.0) + (c2 * I2 if w2 != 0.0 else 0.0)
        integrals = {self.terms[0].name: I1, self.terms[1].name: I2}
        return E, integrals, ([D[0].T, D[1].T, D[2].T] if grad else [None, None, None])

    def prepare(self, knots: np.ndarray, P: np.ndarray) -> None:
        """Let the terms fix what they hold constant during a round (`Term.prepare`) from the path
        through frames P at times `knots`. `solve` calls it on the plain spline and before each round.

        Args:
            knots: (m,) frame times [s]. P: (m, nq) frame values.
        """
        terms = self._stateful_terms()
        if not terms:  # nothing to fix (the path is not even needed)
            return
        basis = self.basis(knots)
        Y, Y1, Y2 = basis.evaluate(P, (0, 1, 2))
        for term in terms:
            if hasattr(term, "set_knots"):  # a term that reads the spline's knots (`PeakForces`)
                term.set_knots(knots)
            term.prepare(basis.t, Y, Y1, Y2)

    @property
    def keeps_state(self) -> bool:
        """True if a term fixes something per round (`Term.prepare`): `prepare` can change E."""
        return bool(self._stateful_terms())

    def _stateful_terms(self) -> list[Term]:
        return [term for term in self.terms if type(term).prepare is not Term.prepare]

    def blame(self, basis: SplineBasis, Y, Y1, Y2) -> str:
        """The name of the first term whose value or gradient is not finite on a path (to name it in
        a `NonFiniteError`), or all names joined by "+" if each alone is finite.

        Args:
            basis: `basis(knots)` of the frame set. Y, Y1, Y2: (n, nq) at basis.t (None if not needed).
        """
        for term in self.terms:
            ev = term.evaluate(basis.t, Y, Y1, Y2, grad=True)
            if any(g is not None and not np.all(np.isfinite(g)) for g in (ev.f, ev.dY, ev.dY1, ev.dY2)):
                return term.name
        return "+".join(self.names)

    def renormalize(self, knots: np.ndarray, P: np.ndarray) -> dict[str, float]:
        """Set each term's scale to its integral on the path (knots, P): paper eq. 7.

        Call once on the initial (plain spline) path and keep the scales through subdivision, so the
        objective stays the same function. Terms that are zero there keep scale 1, and so do terms
        whose weight is absolute (a term's `renormalized` False: a bound, zero there up to rounding).

        Returns:
            {term name: scale}.
        """
        ints = self.evaluate(knots, P, grad=False).integrals
        self.scales = np.array([ints[n] if ints[n] > RENORMALIZE_FLOOR and getattr(term, "renormalized", True)
                                else 1.0 for n, term in zip(self.names, self.terms)])
        return dict(zip(self.names, self.scales.tolist()))
