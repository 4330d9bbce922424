"""A toy objective term in a module of its own, for the registry's test: it pulls the root down."""
import numpy as np

from solver.terms.base import Residual, Term, TermEval


class RootHeight(Term):
    """f = (z - target)^2 [m^2], z the root's height (qpos 2): a term no built-in has, easy to see act.

    Args:
        target: [m] the height the term pulls the root to.
    """

    name = "toy"
    units = "m^2"
    needs = (0,)
    pointwise = True

    def __init__(self, target: float):
        self.target = float(target)

    def evaluate(self, t, Y, Y1, Y2, grad=True) -> TermEval:
        e = Y[:, 2] - self.target
        if not grad:
            return TermEval(e * e)
        dY = np.zeros_like(Y)
        dY[:, 2] = 2.0 * e
        return TermEval(e * e, dY=dY)

    def residual(self, ctx) -> Residual:
        J = np.zeros((len(ctx.Y), 1, ctx.Y.shape[1]))
        J[:, 0, 2] = 1.0
        return Residual((ctx.Y[:, 2] - self.target)[:, None], blocks=(J, None, None))
