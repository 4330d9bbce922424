"""The subject's soles, measured on the clip: where the figure's heel and toe contact sites sit in the foot.

The skeleton's OFFSETs give the ankle and the ball of the foot (the toe joint), not the sole: how far
below the ankle the heel rests, and where the forefoot touches the floor once the heel is up, are not in
the HIERARCHY. The published ratios (`runner.mocap.subject_figure`: the sole 0.039 x stature below the
ankle, the heel 0.24 x foot length behind it, the toe site under the ball) place them for an average
foot in the skeleton's rest pose, which is not the foot's pose when it stands flat: on the shared clips
the heel site of a flat, still foot rests 3 to 30 mm above or below its toe site, and the two feet
1-2 cm apart.

`fit_soles` measures them on the clip itself (docs/mocap.md, "The soles"). A foot that rests on a
surface touches it with its lowest point; with a rigid foot whose sole is the segment from the heel
site to the toe site, in every frame the foot rests the lower of its two sites is on the surface. The
fit moves each site in the foot's sagittal plane (forward and along the foot's vertical axis; its
lateral position is kept) to minimise, over the frames the foot rests,

    sum_i rho( min(h_heel,i, h_toe,i) )

where h is a site's height above the surface under it (the scene fitted to the clip, `solver.
scene_fit`) and rho the soft-L1 loss with scale `SCALE` (5 mm): a frame whose foot hovers a few cm
while the detection still counts it pulls by its sign, not its size. The heel stays within `REACH` of
the published place; the toe site moves from the ball forward at most to the toe tip (the toe joint's
End Site) and within `REACH` in height: the figure's foot is rigid, and once the heel is up the
subject's foot pivots about its toes, ahead of the ball (their joint flexes). A site that is never
the lower one while its foot rests (a forefoot runner's heel) keeps its place. Scene and soles are fitted
in turn (`ROUNDS`): the floor is fitted through the lowest sites' rests, the soles to that floor.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solver.contacts import contact_mask
from solver.figure import Figure

#: the soft-L1 scale of the fit [m]: residuals beyond it count linearly (as the floor fit's, solver/scene_fit.py)
SCALE = 0.005
#: a site moves at most this far from its published place in height, and the heel forward or back [m]
REACH = 0.03
#: scene fit and sole fit alternate this many times
ROUNDS = 2
#: a foot resting fewer frames than this keeps its published sole (too little to measure)
MIN_FRAMES = 12


@dataclass(frozen=True)
class SoleFit:
    """The fitted contact sites.

    Attributes:
        sites: {site name: (3,) position in its foot body's frame [m]}.
        before, after: {foot: RMS [m] over the foot's resting frames of its lowest site's height above the
            surface under it, with the published and the fitted sites}.
        frames: {foot: the number of frames it rests}.
    """

    sites: dict
    before: dict
    after: dict
    frames: dict


def _foot_frames(model, qpos: np.ndarray, bodies: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """(n, b, 3) origins [m] and (n, b, 3, 3) rotations of the bodies over the motion (MuJoCo kinematics)."""
    import mujoco

    data = mujoco.MjData(model)
    org = np.empty((len(qpos), len(bodies), 3))
    rot = np.empty((len(qpos), len(bodies), 3, 3))
    for i, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        org[i] = data.xpos[bodies]
        rot[i] = data.xmat[bodies].reshape(-1, 3, 3)
    return org, rot


def _lowest(org, rot, heel, toe, surfaces) -> np.ndarray:
    """(m,) height [m] of the lower of two foot-frame points above the surfaces, per frame."""
    h = surfaces.height_above(np.stack([org + rot @ heel, org + rot @ toe], axis=1))
    return h.min(axis=1)


def _fit_foot(org, rot, heel, toe, forward, tip, surfaces) -> tuple[np.ndarray, np.ndarray]:
    """The foot's heel and toe site (foot frame) minimising the module docstring's objective, within the
    bounds around the published places `heel`, `toe`."""
    from scipy.optimize import least_squares

    up = np.array([0.0, 0.0, 1.0])

    def sites(p):
        return heel + p[0] * forward + p[1] * up, toe + p[2] * forward + p[3] * up

    def resid(p):
        return _lowest(org, rot, *sites(p), surfaces)

    reach = max(float((tip - toe) @ forward), 1e-6)
    lo, hi = [-REACH, -REACH, 0.0, -REACH], [REACH, REACH, reach, REACH]
    start = np.array([0.0, 0.0, 0.5 * reach, 0.0])  # inside the bounds: from a bound the first step can stall
    p = least_squares(resid, start, bounds=(lo, hi), loss="soft_l1", f_scale=SCALE, x_scale=REACH).x
    return sites(p)


def fit_soles(model, qpos: np.ndarray, frame_time: float, tips: dict) -> SoleFit:
    """Fit the figure's heel and toe sites to the motion's resting feet (module docstring).

    Args:
        model: the figure alone (no surfaces): a subject figure's MjModel. qpos: (n, nq) the clip
            retargeted onto it (root as captured). frame_time: [s].
        tips: {foot: (3,) the toe tip in the foot body's frame [m]} (the End Site of the toe joint).
    Returns:
        SoleFit.
    Raises:
        InputError: the figure lacks a contact site, or the feet never rest (nothing to fit a scene to).
    """
    from solver.scene_fit import fit_contacts, fit_scene

    figure = Figure.from_model(model)
    names = list(figure.contact_sites)
    published = {s: model.site_pos[model.site(s).id].copy() for s in names}
    local = dict(published)
    feet = {f: (h, t) for f, (h, t) in figure.feet.items()}
    body = {f: int(model.site_bodyid[model.site(h).id]) for f, (h, _) in feet.items()}
    org, rot = _foot_frames(model, qpos, list(body.values()))
    times = np.arange(len(qpos)) * frame_time
    before, after, frames = {}, {}, {}
    for _ in range(ROUNDS):
        pos = np.stack([org[:, list(body).index(f)] + rot[:, list(body).index(f)] @ local[s]
                        for f, pair in feet.items() for s in pair], axis=1)
        contacts = fit_contacts(times, pos, tuple(names))
        surfaces = fit_scene(times, pos, contacts, tuple(names)).surfaces()
        mask = contact_mask(contacts, names, times)
        for j, (f, (h, t)) in enumerate(feet.items()):
            rest = mask[:, [names.index(h), names.index(t)]].any(axis=1)
            frames[f] = int(rest.sum())
            o, r = org[rest, j], rot[rest, j]
            before.setdefault(f, _rms(_lowest(o, r, local[h], local[t], surfaces)))
            if frames[f] < MIN_FRAMES:
                after[f] = before[f]
                continue
            fwd = np.r_[local[t][:2] - local[h][:2], 0.0]
            local[h], local[t] = _fit_foot(o, r, published[h], published[t], fwd / np.linalg.norm(fwd), tips[f],
                                           surfaces)
            after[f] = _rms(_lowest(o, r, local[h], local[t], surfaces))
    return SoleFit(local, before, after, frames)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if len(x) else 0.0
