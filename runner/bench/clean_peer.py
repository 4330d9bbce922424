"""The peer of `dynsplines clean`: footskate cleanup by per-frame inverse kinematics (Kovar, Schreiner &
Gleicher, "Footskate cleanup for motion capture editing", SCA 2002), with mink (`pip install mink`, the
`peer` extra) on the same retargeted capture, contacts and scene.

Each contact of the capture's schedule plants its site at one place: the mean of the site's captured
horizontal position over the contact, at the height that sets its sphere on the floor (a box: the
captured mean height). At every frame, from the captured pose, differential IK (mink's `solve_ik`, QP
solver daqp) moves the figure toward those targets of the sites in contact there (position only) and
toward the captured pose (a posture task of lower cost), ITERATIONS steps. Frames are solved one by one,
as the method does: nothing joins one frame's correction to the next but the capture itself.
"""
from __future__ import annotations

import time

import numpy as np

__all__ = ["ITERATIONS", "ik_clean"]

#: IK steps per frame: enough for the site targets to converge to within 0.1 mm on the shipped walks
ITERATIONS = 20
#: [s] the integration step of a differential-IK iteration (velocities over it move the pose)
DT = 0.1
#: task costs (dimensionless): the planted sites' positions dominate, the captured pose keeps the rest,
#: the root (its position and orientation) held as firmly as the sites (Kovar et al. move the root by what
#: the legs cannot reach; an unweighted root let two planted feet drag the body away: 1.7 m on 16_23)
SITE_COST, POSTURE_COST, ROOT_COST = 1.0, 1e-2, 1.0
#: the damping of the IK's least squares (mink's `solve_ik`): 1e-3, steps toward an unreachable target stay finite
DAMPING = 1e-3


def _targets(model, times: np.ndarray, qpos: np.ndarray, contacts, sites) -> list[dict]:
    """Per frame {site: (3,) target [m]} of the sites in contact (module docstring)."""
    from solver.contacts import contact_radii, site_positions

    pos = site_positions(model, qpos, sites)  # (n, s, 3)
    radii = contact_radii(model, sites)
    out: list[dict] = [{} for _ in times]
    for c in contacts:
        on = np.flatnonzero((times >= c.start - 1e-9) & (times <= c.end + 1e-9))
        if not on.size or c.site not in sites:
            continue
        k = sites.index(c.site)
        target = pos[on, k].mean(axis=0)
        if c.surface in ("", "floor"):
            target[2] = radii[k]
        for i in on:
            out[i][c.site] = target
    return out


def ik_clean(model, times: np.ndarray, qpos: np.ndarray, contacts) -> tuple[np.ndarray, float]:
    """The capture cleaned by per-frame IK (module docstring).

    Args:
        model: the scene's MjModel. times: (n,) [s]. qpos: (n, nq) the retargeted capture.
        contacts: the capture's contact schedule (`solver.contacts.Contact`s).
    Returns:
        ((n, nq) the cleaned clip, [s] CPU time of the method: its targets and the IK).
    Raises:
        ImportError: mink is not installed (`pip install -e ".[peer]"`).
    """
    import mink

    from solver.figure import Figure

    cpu = time.process_time()  # the method's own work: its targets and its IK, as the clean's solve
    sites = tuple(Figure.from_model(model).contact_sites)
    targets = _targets(model, np.asarray(times, float), np.asarray(qpos, float), contacts, sites)
    cfg = mink.Configuration(model)
    cost = np.full(model.nv, POSTURE_COST)
    cost[:6] = ROOT_COST  # the free root's dofs come first in the figure
    posture = mink.PostureTask(model, cost=cost)
    tasks = {s: mink.FrameTask(s, "site", position_cost=SITE_COST, orientation_cost=0.0) for s in sites}
    out = np.array(qpos, float)
    for i, q in enumerate(out):
        cfg.update(q)
        posture.set_target(q)
        active = [posture]
        for s, x in targets[i].items():
            tasks[s].set_target(mink.SE3.from_translation(x))
            active.append(tasks[s])
        if len(active) == 1:
            continue
        for _ in range(ITERATIONS):
            v = mink.solve_ik(cfg, active, DT, solver="daqp", damping=DAMPING)
            cfg.integrate_inplace(v, DT)
        out[i] = cfg.q
    return out, time.process_time() - cpu
