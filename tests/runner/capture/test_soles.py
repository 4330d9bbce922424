"""runner.capture.soles: the heel and toe sites fitted to a hand-built motion whose true sole points are
known - the shipped figure rocking on a level floor about a heel point, standing flat, then rocking about
a toe point, both points placed off the figure's published sites by known amounts."""
import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from runner.capture.soles import REACH, fit_soles
from solver.figure import FIGURE_FILE, Figure

FPS = 120.0
#: the true sole points: offsets from the published sites [m] along the foot's forward axis and up
HEEL_SHIFT, TOE_SHIFT = (0.015, -0.01), (0.03, -0.01)


def _rocking(model, heel_true, toe_true):
    """(n, nq) qpos: the whole figure pitched about the world point of heel_true (foot flat -> toes up 15
    degrees -> flat), held flat, then about toe_true (flat -> heel up 25 degrees -> flat); the true points
    lie on z = 0 whenever they are the pivot. heel_true, toe_true: (3,) world positions at the flat pose."""
    data = mujoco.MjData(model)
    data.qpos[:] = model.qpos0
    mujoco.mj_kinematics(model, data)
    root0 = data.qpos[:3].copy()
    angles = [(-np.radians(15) * np.sin(np.pi * s), heel_true) for s in np.linspace(0, 1, 61)]
    angles += [(0.0, heel_true)] * 40
    angles += [(np.radians(25) * np.sin(np.pi * s), toe_true) for s in np.linspace(0, 1, 81)]
    qpos = np.tile(model.qpos0, (len(angles), 1))
    for i, (a, pivot) in enumerate(angles):
        rot = Rotation.from_rotvec([0.0, a, 0.0])
        qpos[i, :3] = pivot + rot.apply(root0 - pivot)
        qpos[i, 3:7] = np.roll(rot.as_quat(), 1) * np.sign(np.roll(rot.as_quat(), 1)[0] or 1.0)
    return qpos


def test_sole_points_are_found_where_the_foot_rocks():
    """Each foot's fitted heel and toe sites are the true pivot points within 3 mm (forward, and height up
    to the one shift the floor fit leaves free), from published sites 1-3 cm off; the root is lowered so
    the true points stand on z = 0."""
    model = mujoco.MjModel.from_xml_path(str(FIGURE_FILE))
    figure = Figure.from_model(model)
    published = {s: model.site_pos[model.site(s).id].copy() for s in figure.contact_sites}
    truth, tips = {}, {}
    for foot, (heel, toe) in figure.feet.items():
        fwd = np.r_[published[toe][:2] - published[heel][:2], 0.0]
        fwd /= np.linalg.norm(fwd)
        truth[heel] = published[heel] + HEEL_SHIFT[0] * fwd + [0, 0, HEEL_SHIFT[1]]
        truth[toe] = published[toe] + TOE_SHIFT[0] * fwd + [0, 0, TOE_SHIFT[1]]
        tips[foot] = published[toe] + 0.06 * fwd
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    world = {s: data.xpos[model.site_bodyid[model.site(s).id]] + data.xmat[model.site_bodyid[model.site(s).id]]
             .reshape(3, 3) @ p for s, p in truth.items()}
    drop = np.mean([world[s][2] for s in world])  # put the true points on z = 0
    model.qpos0[2] -= drop
    world = {s: p - [0, 0, drop] for s, p in world.items()}
    assert max(abs(p[2]) for p in world.values()) < 1e-6  # both feet's true points level
    l_heel, l_toe = figure.feet["left"]
    qpos = _rocking(model, world[l_heel], world[l_toe])
    fit = fit_soles(model, qpos, 1.0 / FPS, tips)
    # the floor is fitted to the sites, so a common height of all four is not measured: heights are
    # compared up to one shift (the mean), positions along the foot as they are
    shift = np.mean([fit.sites[s][2] - p[2] for s, p in truth.items()])
    for site, p in truth.items():
        assert abs(fit.sites[site][0] - p[0]) < 0.003, (site, fit.sites[site], p)
        assert abs(fit.sites[site][2] - shift - p[2]) < 0.003, (site, fit.sites[site], p, shift)
    for foot in figure.feet:
        assert fit.after[foot] < 0.5 * fit.before[foot]
    assert max(abs(v) for v in HEEL_SHIFT + TOE_SHIFT[1:]) <= REACH  # the truth is within the fit's reach


def test_a_rolling_heel_is_fitted_as_its_sphere():
    """The figure rolls without slipping on a heel sphere of known radius (centre RADIUS above the heel's
    sole point, 1 cm ahead of the published heel), from 25 degrees toes-up to flat, stands, then rocks about
    a toe point: the fitted heel radius is the sphere's within 2 mm, its centre within 3 mm along the
    foot (heights up to the one shift the floor fit leaves free), and with `rounded=False` (a point heel)
    the resting feet are fitted at least twice as far from the floor (RMS)."""
    radius = 0.03
    model = mujoco.MjModel.from_xml_path(str(FIGURE_FILE))
    figure = Figure.from_model(model)
    published = {s: model.site_pos[model.site(s).id].copy() for s in figure.contact_sites}
    l_heel, l_toe = figure.feet["left"]
    fwd = np.r_[published[l_toe][:2] - published[l_heel][:2], 0.0]
    fwd /= np.linalg.norm(fwd)
    centre_local = published[l_heel] + 0.01 * fwd + [0, 0, radius]
    tips = {foot: published[toe] + 0.06 * fwd for foot, (_, toe) in figure.feet.items()}
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    body = model.site_bodyid[model.site(l_heel).id]
    centre = data.xpos[body] + data.xmat[body].reshape(3, 3) @ centre_local
    toe = data.xpos[body] + data.xmat[body].reshape(3, 3) @ published[l_toe]
    model.qpos0[2] -= centre[2] - radius  # the sphere on z = 0 (the toe point then too: same sole height)
    centre, toe = centre - [0, 0, centre[2] - radius], toe - [0, 0, centre[2] - radius]
    root0 = model.qpos0[:3].copy()
    poses = [(a, "roll") for a in -np.radians(25) * (1 - np.linspace(0, 1, 61))] + [(0.0, "roll")] * 40
    poses += [(a, "toe") for a in np.radians(25) * np.sin(np.pi * np.linspace(0, 1, 81))]
    qpos = np.tile(model.qpos0, (len(poses), 1))
    for i, (a, how) in enumerate(poses):
        rot = Rotation.from_rotvec([0.0, a, 0.0])
        pivot, slide = (centre, [-radius * a, 0, 0]) if how == "roll" else (toe, [0, 0, 0])
        qpos[i, :3] = pivot + slide + rot.apply(root0 - pivot)
        w = np.roll(rot.as_quat(), 1)
        qpos[i, 3:7] = w * np.sign(w[0])
    fit = fit_soles(model, qpos, 1.0 / FPS, tips)
    point = fit_soles(model, qpos, 1.0 / FPS, tips, rounded=False)
    shift = fit.sites[l_toe][2] - published[l_toe][2]  # the toe point's height is the sole's (truth: published)
    assert abs(fit.radii[l_heel] - radius) < 0.002, fit.radii
    assert abs(fit.sites[l_heel][0] - centre_local[0]) < 0.003, (fit.sites[l_heel], centre_local)
    assert abs(fit.sites[l_heel][2] - shift - centre_local[2]) < 0.005, (fit.sites[l_heel], centre_local, shift)
    assert fit.radii[l_toe] == 0.0 and point.radii[l_heel] == 0.0
    assert point.after["left"] > 2 * fit.after["left"], (point.after, fit.after)
