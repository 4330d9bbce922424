"""The subject's soles, measured on the clip: where the figure's heel and toe contact sites sit in the foot.

The skeleton's OFFSETs give the ankle and the ball of the foot (the toe joint), not the sole: how far
below the ankle the heel rests, and where the forefoot touches the floor once the heel is up, are not in
the HIERARCHY. The published ratios (`runner.capture.subject_figure`: the sole 0.039 x stature below the
ankle, the heel 0.24 x foot length behind it, the toe site under the ball) place them for an average
foot in the skeleton's rest pose, which is not the foot's pose when it stands flat: on the shared clips
the heel site of a flat, still foot rests 3 to 30 mm above or below its toe site, and the two feet
1-2 cm apart.

`fit_soles` measures them on the clip itself (docs/mocap.md, "The soles"). A foot that rests on a
surface touches it with its lowest point; with a rigid foot whose sole is the segment from the heel
site to the toe site, in every frame the foot rests the lower of its two sites is on the surface. The
fit moves each site in the foot's sagittal plane (forward and along the foot's vertical axis; its
lateral position is kept) to minimise, over the frames each foot rests, of both feet at once,

    sum_i rho( min(h_heel,i, h_toe,i) )

where h is a site's height above the surface under it (the scene fitted to the clip, `solver.
scene_fit`) and rho the soft-L1 loss with scale `SCALE` (5 mm): a frame whose foot hovers a few cm
while the detection still counts it pulls by its sign, not its size. The heel stays within `REACH` of
the published place; the toe site moves from the ball forward at most to the toe tip (the toe joint's
End Site) and within `REACH` in height: the figure's foot is rigid, and once the heel is up the
subject's foot pivots about its toes, ahead of the ball (their joint flexes). The two feet are mirror
images: they share one sole (the same moves from each foot's published places, the toe the same
fraction of the way to its tip), and only their heights may differ, by up to `REACH` (the capture's
joint centres of the two feet sit differently above their soles). Fitted apart, each foot followed its
own few rests (07_04: a 4.4 cm heel sphere on the left, a point on the right), and a foot resting too
briefly kept the published sole.

The heel is rounded: a walker's heel lands with the foot 20-35 degrees toes-up and rolls on the round
back edge of the heel bone and its pad onto the flat foot, which one point fixed in the foot cannot
follow (a point behind and below the ankle dips as the foot pitches up). The heel contact is a sphere
(the site is its centre, its radius r an annotation of the figure, `solver.contacts.contact_radii`)
whose lowest point, centre - r z, is what touches a surface whatever the foot's pitch; h_heel above is
that point's height. The fit takes r from 0 (a point) to `HEEL_RADIUS` times the ankle's height above
the sole (the centre stays below the ankle), with the centre r above the heel's sole point so that a
flat foot rests where it did. The toe stays a point: a sphere about the ball (the toes rolling under
it at push-off) made the flat-foot fit of the forefoot worse on the shared clips (docs/mocap.md, "The
soles"). A site that is never
the lower one while its foot rests (a forefoot runner's heel) keeps its place. Scene and soles are fitted
in turn (`ROUNDS`): the floor is fitted through the lowest sites' rests, the soles to that floor. A
direction the rests leave undetermined (a flat foot's heel slid along the sole, a heel radius traded
against its centre's height) is fixed by a small pull of the offsets towards their start (Tikhonov
regularization, `REGULARIZE`), so that two files of one motion (another convention, the numbers rounded
otherwise) give the same soles, not wherever the solver happened to stop. One sole for both feet still
leaves such directions: without the pull the sites of 09_03, 35_17, 83_65 and 127_33 end 11-19 mm
elsewhere on the same rests.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solver.contacts import contact_mask, lowest_points
from solver.figure import Figure

#: the soft-L1 scale of the fit [m]: residuals beyond it count linearly (as the floor fit's, runner/capture/scene_fit.py)
SCALE = 0.005
#: a site moves at most this far from its published place in height, and the heel forward or back [m]
REACH = 0.03
#: scene fit and sole fit alternate this many times
ROUNDS = 2
#: the largest radius of the heel's sphere, as a fraction of the ankle's height above the (published) sole:
#: its centre stays below the ankle
HEEL_RADIUS = 1.0
#: [s] the feet resting less than this in all keep their published soles (too little to measure; 12 frames at
#: 120 Hz), and the height difference between the two feet is fitted only when each rests that long
MIN_REST_S = 0.1
#: [1] the weight of the pull of the fitted offsets [m] towards their starting values: a 1 cm offset costs
#: 0.1 mm of residual, far below one resting frame's (the capture's noise, a few mm), so it decides only
#: directions the rests leave undetermined
REGULARIZE = 0.01


@dataclass(frozen=True)
class SoleFit:
    """The fitted contact sites.

    Attributes:
        sites: {site name: (3,) position in its foot body's frame [m]: the centre of its sphere}.
        radii: {site name: the sphere's radius [m]} (0: a point).
        before, after: {foot: RMS [m] over the foot's resting frames of its lowest site's height above the
            surface under it, with the published and the fitted sites}.
        frames: {foot: the number of frames it rests}.
    """

    sites: dict
    radii: dict
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


def _lowest(org, rot, heel, toe, radii, surfaces) -> np.ndarray:
    """(m,) height [m] above the surfaces of the lower of two foot-frame spheres (centres `heel`, `toe`,
    radii (2,)), per frame: each sphere's lowest point is its centre minus its radius, vertically."""
    centres = np.stack([org + rot @ heel, org + rot @ toe], axis=1)
    return (surfaces.height_above(centres) - np.asarray(radii, float)).min(axis=1)


def _fit_feet(feet: list, rmax: float, both: bool) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Both feet's heel spheres and toe points (centres in each foot's frame, radii (2,), the toe's 0)
    minimising the module docstring's objective over the resting frames of both feet at once, with
    one sole for the two feet: the same offsets from each foot's published places (a subject's feet are
    mirror images), and, with `both` (each foot rests long enough), one height difference between them
    (half up on the left, half down on the right: the capture's joint centres of the two feet can sit
    at different heights above their soles).

    Args:
        feet: per foot (org (m, 3), rot (m, 3, 3) of its resting frames, heel, toe (3,) published places
            on the sole, forward (3,) unit, tip (3,) the toe tip, surfaces, side +1 left / -1 right).
        rmax: [m] the largest heel radius (0: a point heel). both: fit the height difference.
    """
    from scipy.optimize import least_squares

    up = np.array([0.0, 0.0, 1.0])
    reach = [max(float((tip - toe) @ fwd), 1e-6) for _, _, _, toe, fwd, tip, _, _ in feet]

    def spheres(p, k):
        _, _, heel, toe, fwd, _, _, side = feet[k]
        lift = side * p[5] / 2
        return (heel + p[0] * fwd + (p[1] + p[2] + lift) * up, toe + p[3] * reach[k] * fwd + (p[4] + lift) * up,
                np.array([p[2], 0.0]))

    # heel forward, heel up, heel radius, toe from the ball to the tip (fraction), toe up, left-right height
    lo = np.array([-REACH, -REACH, 0.0, 0.0, -REACH, -REACH])
    hi = np.array([REACH, REACH, max(rmax, 1e-9), 1.0, REACH, REACH])
    start = np.array([0.0, 0.0, 0.5 * rmax, 0.5, 0.0, 0.0])  # inside the bounds: from a bound a step can stall
    free = np.array([True, True, rmax > 0, True, True, both])

    def full(x):
        p = start.copy()
        p[free] = x
        return p

    # [m] per unit of each offset: the toe's is a fraction of the way from the ball to the tip
    metres = np.array([1.0, 1.0, 1.0, float(np.mean(reach)), 1.0, 1.0])[free]

    def resid(x):
        # the rests' heights, and a small pull towards the start (Tikhonov): a direction the rests leave
        # free (a flat foot's heel slid along the sole) is fixed there, not wherever the solver stops
        p = full(x)
        return np.concatenate([_lowest(f[0], f[1], *spheres(p, k), f[6]) for k, f in enumerate(feet)]
                              + [REGULARIZE * metres * (x - start[free])])

    scale = np.array([REACH, REACH, REACH, 0.5, REACH, REACH])[free]
    x = least_squares(resid, start[free], bounds=(lo[free], hi[free]), loss="soft_l1", f_scale=SCALE, x_scale=scale).x
    return [spheres(full(x), k) for k in range(len(feet))]


def fit_soles(model, qpos: np.ndarray, frame_time: float, tips: dict, rounded: bool = True) -> SoleFit:
    """Fit the figure's heel and toe sites (and with `rounded` the heel sphere's radius) to the motion's
    resting feet (module docstring): one sole for both feet, and the height difference between them.

    Args:
        model: the figure alone (no surfaces): a subject figure's MjModel. qpos: (n, nq) the clip
            retargeted onto it (root as captured). frame_time: [s].
        tips: {foot: (3,) the toe tip in the foot body's frame [m]} (the End Site of the toe joint).
        rounded: fit the heel as a sphere (radius from 0 to the ankle's height above the sole); False:
            a point (radius 0). The toe is a point.
    Returns:
        SoleFit.
    Raises:
        InputError: the figure lacks a contact site, or the feet never rest (nothing to fit a scene to).
    """
    from runner.capture.scene_fit import fit_contacts, fit_scene

    figure = Figure.from_model(model)
    names = list(figure.contact_sites)
    published = {s: model.site_pos[model.site(s).id].copy() for s in names}
    local = dict(published)
    radius = dict.fromkeys(names, 0.0)
    feet = {f: (h, t) for f, (h, t) in figure.feet.items()}
    body = {f: int(model.site_bodyid[model.site(h).id]) for f, (h, _) in feet.items()}
    org, rot = _foot_frames(model, qpos, list(body.values()))
    times = np.arange(len(qpos)) * frame_time
    least = int(np.ceil(MIN_REST_S / frame_time - 1e-9))
    before, after, frames = {}, {}, {}
    for _ in range(ROUNDS):
        pos = lowest_points(np.stack([org[:, list(body).index(f)] + rot[:, list(body).index(f)] @ local[s]
                                      for f, pair in feet.items() for s in pair], axis=1),
                            [radius[s] for s in names])
        contacts = fit_contacts(times, pos, feet)
        surfaces = fit_scene(times, pos, contacts, feet).surfaces()
        mask = contact_mask(contacts, names, times)
        data = []
        for j, (f, (h, t)) in enumerate(feet.items()):
            rest = mask[:, [names.index(h), names.index(t)]].any(axis=1)
            frames[f] = int(rest.sum())
            o, r = org[rest, j], rot[rest, j]
            before.setdefault(f, _rms(_lowest(o, r, published[h], published[t], (0.0, 0.0), surfaces)))
            fwd = np.r_[published[t][:2] - published[h][:2], 0.0]
            data.append((o, r, published[h], published[t], fwd / np.linalg.norm(fwd), tips[f], surfaces,
                         1.0 if h.startswith("l") else -1.0))
        if sum(frames.values()) >= least:
            rmax = HEEL_RADIUS * -float(np.mean([published[h][2] for h, _ in feet.values()])) if rounded else 0.0
            fitted = _fit_feet(data, rmax, both=min(frames.values()) >= least)
            for (h, t), (heel, toe, radii) in zip(feet.values(), fitted, strict=True):
                local[h], local[t], (radius[h], radius[t]) = heel, toe, radii
        for (f, (h, t)), d in zip(feet.items(), data, strict=True):
            after[f] = _rms(_lowest(d[0], d[1], local[h], local[t], (radius[h], radius[t]), surfaces))
    return SoleFit(local, radius, before, after, frames)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if len(x) else 0.0
