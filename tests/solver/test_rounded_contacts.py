"""solver.contacts: rounded contact sites (`contact_radii`, `contact_points`) on a hand-built motion - the
shipped figure on its floor scene rolling, without slipping, on a sphere of known radius centred on its
heel sites: the spheres' lowest points stay on the floor at every pitch, where the site points do not;
and the runner's measures (stance, the resting feet's distance to the floor) see the same."""
from types import SimpleNamespace

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from shipped_sites import SITES as CONTACT_SITES

from runner.capture.root_height import worst_contact_distance
from solver.contacts import RADIUS_PREFIX, contact_points, contact_radii, lowest_points, site_heights, site_positions
from solver.errors import InputError
from solver.figure import FIGURE_FILE, Figure

FPS = 120.0
RADIUS = 0.035  # [m] the heel's sphere
PITCH = np.radians(30.0)  # toes up at heel strike


def _scene(radii: dict):
    """The shipped figure with a floor plane at z = 0, its heel sites moved RADIUS up (the sphere's centre,
    so that the flat foot still rests on z = 0) and the given radius annotations."""
    spec = mujoco.MjSpec.from_file(str(FIGURE_FILE))
    spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[5, 5, 0.1])
    for site, r in radii.items():
        spec.site(site).pos = spec.site(site).pos + [0.0, 0.0, r]
        spec.add_numeric(name=RADIUS_PREFIX + site, data=[r])
    return spec.compile()


def _rolling(model, centre: np.ndarray, radius: float) -> np.ndarray:
    """(n, nq) qpos: the figure pitched toes-up by PITCH, rolling without slipping on the sphere of
    `radius` centred at the world point `centre` (at the flat pose) down to flat over 0.5 s, then held
    flat 0.25 s. Rolling: a rotation by a about y about the centre, the centre moved forward by radius * a
    (the sphere's lowest point does not move)."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    root0 = data.qpos[:3].copy()
    angles = list(-PITCH * (1.0 - np.linspace(0.0, 1.0, int(0.5 * FPS)))) + [0.0] * int(0.25 * FPS)
    qpos = np.tile(model.qpos0, (len(angles), 1))
    for i, a in enumerate(angles):
        rot = Rotation.from_rotvec([0.0, a, 0.0])
        qpos[i, :3] = centre + [-radius * a, 0.0, 0.0] + rot.apply(root0 - centre)
        w = np.roll(rot.as_quat(), 1)
        qpos[i, 3:7] = w * np.sign(w[0])
    return qpos


def _heel_centre(model) -> np.ndarray:
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    return data.site_xpos[model.site("l_heel").id].copy()


def test_a_heel_rolling_on_its_sphere_stays_on_the_floor():
    """The lowest point of the heel's sphere is on the floor (within 1e-9 m) at every pitch from 30 degrees
    toes-up to flat, while the heel site itself, a point fixed in the foot, rises and falls by up to
    RADIUS (1 - cos 30) ~ 4.7 mm relative to it (the rolling foot's centre stays RADIUS up; a point heel
    rolling instead of the sphere would be RADIUS * (1 - cos a) off)."""
    radii = {"l_heel": RADIUS, "r_heel": RADIUS}
    model = _scene(radii)
    sites = Figure.from_model(model).contact_sites
    np.testing.assert_allclose(contact_radii(model, sites), [RADIUS, 0.0, RADIUS, 0.0])
    centre = _heel_centre(model)
    assert centre[2] == pytest.approx(RADIUS, abs=1e-9)  # the flat foot's heel sphere touches z = 0
    qpos = _rolling(model, centre, RADIUS)
    h = site_heights(model, contact_points(model, qpos, sites))
    heels = [sites.index("l_heel"), sites.index("r_heel")]
    np.testing.assert_allclose(h[:, heels], 0.0, atol=1e-9)
    # the sphere's bottom point fixed in the foot (what a point heel would be) leaves the floor as it pitches
    data = mujoco.MjData(model)
    bottom = []
    for q in qpos[:5]:
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        R = data.xmat[model.body("l_foot").id].reshape(3, 3)
        bottom.append(data.site_xpos[model.site("l_heel").id] - R @ [0, 0, RADIUS])
    assert bottom[0][2] == pytest.approx(RADIUS * (1 - np.cos(PITCH)), rel=1e-6)


def test_resting_heel_measured_at_the_sphere_not_the_centre():
    """The acceptance measure (`worst_contact_distance`: resting feet's lowest points) is 0 within 1e-9 m
    for the rolling sphere heel; with the annotation removed (the same sites read as points) it is
    centimetres."""
    model = _scene({"l_heel": RADIUS, "r_heel": RADIUS})
    qpos = _rolling(model, _heel_centre(model), RADIUS)
    reference = SimpleNamespace(qpos=qpos, frame_time=1.0 / FPS)  # what the measure reads of a Reference
    assert worst_contact_distance(reference, model) < 1e-9
    spec = mujoco.MjSpec.from_file(str(FIGURE_FILE))  # the same sites, without the radius annotation
    spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[5, 5, 0.1])
    for s in ("l_heel", "r_heel"):
        spec.site(s).pos = spec.site(s).pos + [0.0, 0.0, RADIUS]
    point = spec.compile()
    # read as points, the rolling foot's lowest site is off the floor: the heel centre RADIUS up, or the
    # toe coming down, counted from the frame it is below the stance's 3 cm
    assert 0.025 < worst_contact_distance(reference, point) <= RADIUS + 1e-9


def test_lowest_points_and_malformed_radius():
    """`lowest_points` lowers each site by its radius (z only); a negative or non-scalar radius is one
    line naming the annotation and the fix."""
    pos = np.array([[[0.1, 0.2, 0.3], [0.0, 0.0, 0.05]]])
    np.testing.assert_allclose(lowest_points(pos, [0.04, 0.0]), [[[0.1, 0.2, 0.26], [0.0, 0.0, 0.05]]])
    for data in ([-0.01], [0.01, 0.02]):
        spec = mujoco.MjSpec.from_file(str(FIGURE_FILE))
        spec.add_numeric(name=RADIUS_PREFIX + "l_heel", data=data)
        with pytest.raises(InputError, match=r'figure:radius:l_heel.*one number >= 0') as e:
            contact_radii(spec.compile(), ("l_heel",))
        assert "\n" not in str(e.value)
    shipped = mujoco.MjModel.from_xml_path(str(FIGURE_FILE))
    assert not contact_radii(shipped, Figure.from_model(shipped).contact_sites).any()  # the shipped figure: points
    np.testing.assert_allclose(contact_points(shipped, shipped.qpos0[None]), site_positions(shipped, shipped.qpos0[None]))


def test_penetration_term_measures_the_sphere():
    """The penetration term's true depth of the heel sphere lowered 1 cm into the floor is 1 cm (its
    centre, RADIUS - 1 cm up, is outside: the point site would read 0), and 0 where the sphere just
    touches; the shipped figure's point sites read their own depth."""
    from solver.terms.penetration import Penetration

    model = _scene({"l_heel": RADIUS, "r_heel": RADIUS})
    q = model.qpos0.copy()
    term = Penetration(model)
    assert term.depths(q[None], margin=0.0).max() < 1e-9
    q[2] -= 0.01
    heel = list(CONTACT_SITES).index("l_heel")
    np.testing.assert_allclose(term.depths(q[None], margin=0.0)[0, heel], 0.01, rtol=1e-6)
    spec = mujoco.MjSpec.from_file(str(FIGURE_FILE))
    spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[5, 5, 0.1])
    shipped = spec.compile()
    p = shipped.qpos0.copy()
    p[2] -= 0.01
    np.testing.assert_allclose(Penetration(shipped).depths(p[None], margin=0.0).max(), 0.01, rtol=1e-6)
