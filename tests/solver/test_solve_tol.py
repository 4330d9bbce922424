"""The accuracy request of `solve` (`SolveOptions.tol`) on a figure's soft preferences (covariant
acceleration, the unit term; paper eq. 9): the decrease of E that refinement still predicts, relative to E
(`refinement_estimate`), on cases with a known answer."""
from dataclasses import replace

import mujoco
import numpy as np
import pytest

from solver.errors import InputError
from solver.frames import FrameSet
from solver.keyframes import Keyframes
from solver.layout import StateLayout
from solver.objective import Objective
from solver.paper.solve import SolveOptions, refinement_estimate, solve
from solver.terms import CovariantAcceleration, UnitQuaternion

from conftest import TOY_SCENE


def keyframes(model, rotate: bool) -> Keyframes:
    """Three full keyframes of the toy figure: the root moves (x, z); with `rotate` a hip and a knee turn."""
    layout = StateLayout.from_model(model)
    V = np.zeros((3, model.nq))
    V[:, 0], V[:, 2] = [0.0, 0.5, 1.0], [1.0, 1.1, 1.0]
    V[:, layout.quat_slots[:, 0]] = 1.0
    if rotate:
        V[1, layout.quat_slots[1]] = [np.cos(0.3), np.sin(0.3), 0, 0]
        V[2, layout.quat_slots[3]] = [np.cos(0.4), 0, np.sin(0.4), 0]
    return Keyframes(np.array([0.0, 0.4, 1.0]), V, np.ones_like(V, bool))


#: the settings of a figure solve: one frame per interval, adaptive rounds ranked by the predicted decrease,
#: renormalized terms (eq. 7), L-BFGS in the spline-acceleration metric
OPTIONS = SolveOptions(subdivision="adaptive", per_segment=1, renormalize=True, ftol_rel=1e-6, precondition=True,
                       radial_weight="auto", score="decrease", refine="tol", tol=1e-2)


def figure_solve(model, kf, terms: str, progress=None, **changes):
    """`solve` on the figure with "smooth" (the covariant acceleration with the root's linear part) and
    optionally "unit" (weights 0.05 and 1)."""
    layout = StateLayout.from_model(model)
    smooth = CovariantAcceleration(layout.quat_slots, layout.linear_index)
    chosen = [(smooth, 0.05)] + ([(UnitQuaternion(layout.quat_slots), 1.0)] if "unit" in terms else [])
    objective = Objective([t for t, _ in chosen], [w for _, w in chosen], kf.times[0], kf.times[-1], rate=400.0)
    return solve(objective, FrameSet.from_keyframes(kf, layout.quat_slots), replace(OPTIONS, **changes),
                  progress=progress)


@pytest.fixture(scope="module")
def model():
    return mujoco.MjModel.from_xml_string(TOY_SCENE)


def test_nothing_to_gain_estimates_zero(model):
    """Only the root moves and every joint stays at identity: the smoothness term is then integral |x''|^2
    of the root, which the natural cubic spline through the keyframes already minimizes. No frame can
    lower E: the estimate is ~0 and the tolerance is met after the first round."""
    sol = figure_solve(model, keyframes(model, rotate=False), "smooth", tol=1e-6)
    assert sol.converged_to_tol is True and len(sol.rounds) == 1
    assert sol.refinement_estimate < 1e-8 and sol.refinement_estimates == (sol.refinement_estimate,)
    assert "refinement estimate" in sol.message and "<= tol 1e-06" in sol.message
    np.testing.assert_allclose(sol.E_final, sol.E_initial, rtol=1e-8)


def test_refines_until_the_estimate_is_below_tol(model):
    """Turning joints: the optimum needs frames. The estimate starts above tol and ends below it; fixed
    rounds report the same estimate for the same frames (computed when read)."""
    kf = keyframes(model, rotate=True)
    events = []
    sol = figure_solve(model, kf, "unit,smooth", tol=1e-3, progress=lambda e, i: events.append((e, i)))
    est = sol.refinement_estimates
    assert sol.converged_to_tol is True and len(est) >= 2
    assert est[0] > 1e-3 >= est[-1] == sol.refinement_estimate
    assert sol.frames.n_variable > 2  # frames were added beyond the starting one per interval
    assert [i["estimate"] for e, i in events if e == "estimate"] == list(est)  # reported after every round
    # the same frames by fixed rounds: the estimate computed on the result agrees
    fixed = figure_solve(model, kf, "unit,smooth", refine="rounds", tol=0.0, rounds=len(est) - 1)
    np.testing.assert_array_equal(fixed.frames.values, sol.frames.values)
    assert fixed.converged_to_tol is None and fixed.refinement_estimates == est[:-1]
    assert fixed.refinement_estimate == pytest.approx(est[-1], rel=1e-9)
    direct, D = refinement_estimate(fixed.objective, fixed.frames, fixed.E_final)
    assert direct == pytest.approx(est[-1], rel=1e-9) and D.shape == (fixed.frames.count - 1,)


def test_budgets_end_the_refinement_and_say_so(model):
    kf = keyframes(model, rotate=True)
    sol = figure_solve(model, kf, "unit,smooth", tol=1e-9, max_frames=4)
    assert sol.converged_to_tol is False and sol.frames.n_variable <= 4
    assert "frame budget of 4 variable frames reached at refinement estimate" in sol.message
    assert sol.refinement_estimate > 1e-9


def test_tol_option_checks():
    with pytest.raises(InputError, match="tol must be a number >= 0"):
        SolveOptions(tol=-1.0)
    with pytest.raises(InputError, match="tol must be a number >= 0"):
        SolveOptions(tol=float("inf"))
