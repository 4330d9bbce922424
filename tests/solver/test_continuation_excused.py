"""Penalty continuation against keyframes that contradict the contact schedule (solver/continuation.py,
`Planted.for_boost`): a boost stiffens only the contacts the planted term's violation measures.

The hand-built case: the toy figure stands on its left foot; its right thigh is turned back 20 degrees
with the knee straight, so the keyframes hold the right heel about 7 cm up and the right toe on the
floor, all through a contact of both right sites. The heel's contact contradicts the keyframes
(excused). Pulling that heel down harder between the keyframes, with the toe and the left foot
planted, can only turn the shin forward: the knee bends backward (hyperextension), the mechanism that
a planted boost against a clip's excused contacts showed.
"""

import numpy as np
import pytest

from solver.contacts import Contact
from solver.continuation import boost_terms
from solver.frames import FrameSet
from solver.layout import StateLayout
from solver.objective import Objective
from solver.schedule_conflicts import ScheduleConflicts
from solver.solve import SolveOptions, solve
from solver.terms.bending import Hyperextension
from solver.terms.contact import Planted
from solver.terms.covariant import CovariantAcceleration
from solver.terms.penetration import Penetration

T = 0.4  # [s] the two keyframes' interval
HIP = 20.0  # [deg] the right thigh turned back about the knee's flexion axis (y)
BOOST = 10.0



def keyframes(layout, planted):
    """(2, nq) the pose twice: left foot on the floor, right thigh turned back, both knees straight."""
    pose = np.zeros(layout.nq)
    pose[layout.quat_slots[:, 0]] = 1.0
    pose[layout.joint("r_hip").quat_index] = [np.cos(np.radians(HIP) / 2), 0.0, np.sin(np.radians(HIP) / 2), 0.0]
    pose[2] = -planted.kin.positions(pose[None])[0, planted.kin.names.index("l_heel"), 2]
    return np.repeat(pose[None], 2, axis=0)


def solve_with(toy_model, boost: str):
    """Hyperextension [deg] of the path after one solve with planted at weight 10, boosted x10 as `boost`
    says: "none", "weight" (the whole term's weight, as before `for_boost`), "continuation"
    (`boost_terms`), or "apart" (the reference: the excused contact as its own term at weight 10)."""
    layout = StateLayout.from_model(toy_model)
    contacts = [Contact(s, 0.0, T) for s in ("l_heel", "l_toe", "r_heel", "r_toe")]
    probe = Planted(toy_model, contacts, rest_height=0.0)
    Y = keyframes(layout, probe)
    found = probe.conflicts(np.array([0.0, T]), Y)
    assert {c.site for c in found.planted} == {"r_heel"}  # held ~7 cm up: excused; the toe is on the floor
    heel = [c for c in probe.contacts if c.site == "r_heel"]
    bending = Hyperextension(layout, {"l_knee": [0, 1, 0], "r_knee": [0, 1, 0]})
    common = [bending, CovariantAcceleration(layout.quat_slots, layout.linear_index), Penetration(toy_model, margin=0.0)]
    if boost == "apart":
        rest = [c for c in probe.contacts if c.site != "r_heel"]
        terms = [Planted(toy_model, rest, rest_height=0.0), Planted(toy_model, heel, rest_height=0.0), *common]
        weights = [10.0 * BOOST, 10.0, 1.0, 1e-4, 100.0]
    else:
        terms = [Planted(toy_model, contacts, rest_height=0.0, conflicts=ScheduleConflicts(planted=heel)), *common]
        weights = [10.0, 1.0, 1e-4, 100.0]
    obj = Objective(terms, weights, 0.0, T, rate=200.0)
    if boost == "weight":
        obj.weights[0] *= BOOST
    elif boost == "continuation":
        boost_terms(obj, ["planted"], BOOST)
    fs = FrameSet(np.array([0.0, T]), Y, np.ones_like(Y, bool), np.ones(2, bool))
    sol = solve(obj, fs, SolveOptions(subdivision="global", per_segment=3, renormalize=False, ftol_rel=1e-9))
    return float(np.degrees(bending.violation(sol.frames.path(np.linspace(0.0, T, 401)))))


@pytest.mark.slow
def test_a_planted_boost_leaves_an_excused_contact_alone_and_the_knee_straight(toy_model):
    whole = solve_with(toy_model, "weight")
    boosted = solve_with(toy_model, "continuation")
    apart = solve_with(toy_model, "apart")
    # the mechanism: the whole term's weight x10 drags the excused heel down by turning the knee backward
    assert whole > boosted + 2.0, (whole, boosted)
    # the fix: the boost leaves the excused contact's weight as it was - the same objective as the
    # reference built apart (to rounding), so the same optimum to the optimizer's tolerance
    assert boosted == pytest.approx(apart, abs=0.1)
