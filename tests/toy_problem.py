"""The toy figure (conftest.TOY_SCENE) keyed low over the floor with a contact schedule, shared by the
least-squares tests: its feet are in the floor, so penetration, planted and clearance act and hinge rows
switch on and off along the steps."""
import numpy as np

import solver
from solver.contacts import Contact

#: the toy's contacts: left heel and toe planted first, then the right toe
SCHEDULE = (Contact("l_heel", 0.0, 0.45), Contact("l_toe", 0.0, 0.5), Contact("r_toe", 0.55, 1.2))


def toy_keyframes(model, turn_last=False, partial=False) -> solver.Keyframes:
    """Four keyframes of the toy (root 0.9-0.95 m up, two joints turned); `turn_last` also turns a joint in
    the last one, `partial` frees the third keyframe's root height."""
    layout = solver.StateLayout.from_model(model)
    V = np.zeros((4, model.nq))
    V[:, 0], V[:, 2] = [0.0, 0.3, 0.7, 1.0], [0.9, 0.95, 0.92, 0.9]
    V[:, layout.quat_slots[:, 0]] = 1.0
    V[1, layout.quat_slots[1]] = [np.cos(0.3), np.sin(0.3), 0, 0]
    V[2, layout.quat_slots[3]] = [np.cos(0.4), 0, np.sin(0.4), 0]
    if turn_last:
        V[3, layout.quat_slots[2]] = [np.cos(0.2), 0, 0, np.sin(0.2)]
    mask = np.ones_like(V, bool)
    if partial:
        mask[2, 2] = False
    return solver.Keyframes(np.array([0.0, 0.35, 0.8, 1.2]), V, mask)


def moved(problem, seed=3):
    """The problem's objective (prepared at the moved frames, renormalized on the plain spline) and its
    frames with a variable frame in every segment, the free components moved at random by 0.03 (residuals
    of every kind nonzero)."""
    objective = problem.objective
    frames = problem.initial.with_midpoints()
    frames = frames.with_x(frames.x() + 0.03 * np.random.default_rng(seed).normal(size=frames.n_free))
    objective.prepare(frames.times, frames.values)
    objective.renormalize(problem.initial.times, problem.initial.values)
    return objective, frames
