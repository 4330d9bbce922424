"""`solver.figure.Figure` against values read independently from MuJoCo (names, `mj_kinematics` at the
rest pose, subtree masses) and against the figure's documented proportions (models/humanoid39.xml)."""
import mujoco
import numpy as np
import pytest
from tree_models import scaled_figure_xml

from solver.errors import InputError
from solver.figure import FIGURE_FILE, MODELS_DIR, Figure, shipped_figure


@pytest.fixture(scope="module")
def model():
    return mujoco.MjModel.from_xml_path(str(FIGURE_FILE))


@pytest.fixture(scope="module")
def rest(model):
    d = mujoco.MjData(model)
    mujoco.mj_kinematics(model, d)
    return d


def test_bodies_and_joints_are_the_models(model):
    fig = Figure.from_model(model)
    assert fig.root == "pelvis" and len(fig.bodies) == model.nbody - 1  # all but the world
    for i, b in enumerate(fig.bodies[1:], start=1):
        assert fig.bodies[fig.parents[i]] == model.body(model.body(b).parentid[0]).name
    assert [j.name for j in fig.joints] == [model.joint(i).name for i in range(model.njnt)]
    knee = fig.joint("l_knee")
    assert (knee.kind, knee.qposadr, knee.nq, knee.dofadr) == ("ball", model.joint("l_knee").qposadr[0], 4,
                                                                 model.joint("l_knee").dofadr[0])
    assert fig.joint("root").kind == "free" and fig.joint_bodies["l_knee"] == ("l_thigh", "l_shin")
    assert fig.leg_joints == ("root", "l_hip", "l_knee", "l_ankle", "r_hip", "r_knee", "r_ankle")
    with pytest.raises(InputError, match="no joint 'neck'.*l_knee"):
        fig.joint("neck")
    with pytest.raises(ValueError, match="read-only"):  # a value: its arrays do not change
        fig.body_masses[0] = 1.0


def test_contact_sites_and_feet(model):
    fig = Figure.from_model(model)
    assert fig.feet == {"left": ("l_heel", "l_toe"), "right": ("r_heel", "r_toe")}
    assert fig.contact_sites == ("l_heel", "l_toe", "r_heel", "r_toe")
    assert fig.contact_site_ids.tolist() == [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s)
                                             for s in fig.contact_sites]


def test_sole_edges_are_held_with_the_contact_sites(model, rest):
    """The soles' edges (figure:sole:SIDE): inner and outer across the sole under the ball, on the sole's plane
    at the rest pose (the heel's height), the inner one toward the body's midline, 0.055 x 1.75 m apart."""
    fig = Figure.from_model(model)
    assert fig.sole_sites == ("l_sole_in", "l_sole_out", "r_sole_in", "r_sole_out")
    assert fig.surface_sites == fig.contact_sites + fig.sole_sites
    for side in "lr":
        inner, outer, heel = (rest.site(f"{side}_{s}").xpos for s in ("sole_in", "sole_out", "heel"))
        assert inner[2] == pytest.approx(heel[2], abs=1e-9) and outer[2] == pytest.approx(heel[2], abs=1e-9)
        assert abs(inner[1]) < abs(outer[1])
        assert np.linalg.norm(inner - outer) == pytest.approx(0.055 * 1.75, abs=5e-4)  # the MJCF's mm


def test_segments_from_kinematics_at_rest(model, rest):
    """Segment ends against world positions from mj_kinematics (every body frame is parallel to the
    world frame at the identity pose), and the documented joint heights (hip 0.91, knee 0.49, ankle
    0.07; shoulder 1.44, elbow 1.15, wrist 0.91 with the root at 1.0)."""
    fig = Figure.from_model(model)
    x = {model.body(i).name: rest.xpos[i] for i in range(1, model.nbody)}
    for parent, child in [("l_thigh", "l_shin"), ("l_shin", "l_foot"), ("r_upper_arm", "r_forearm")]:
        np.testing.assert_allclose(fig.segments[parent].end, x[child] - x[parent], atol=1e-12)
    np.testing.assert_allclose(fig.segments["l_foot"].end, rest.site_xpos[model.site("l_ball").id] - x["l_foot"],
                               atol=1e-12)
    heights = {"l_thigh": 0.91, "l_shin": 0.49, "l_foot": 0.07, "l_upper_arm": 1.44, "l_forearm": 1.15}
    for body, z in heights.items():
        assert x[body][2] == pytest.approx(z, abs=1e-12)
    assert x["l_forearm"][2] + fig.segments["l_forearm"].end[2] == pytest.approx(0.91, abs=1e-12)
    assert fig.segments["l_thigh"].length == pytest.approx(0.42, abs=1e-12)
    np.testing.assert_allclose(fig.segments["l_shin"].direction, [0, 0, -1], atol=1e-12)
    assert "pelvis" not in fig.segments


def test_flexion_axes_bend_knees_back_and_elbows_forward(model):
    """A positive rotation about the flexion axis moves the foot back (-x) and the hand forward (+x)."""
    fig = Figure.from_model(model)
    assert set(fig.flexion_axes) == {"l_knee", "r_knee", "l_elbow", "r_elbow"}
    for joint, tip, sign in [("l_knee", "l_foot", -1), ("r_knee", "r_foot", -1), ("l_elbow", "l_forearm", 0),
                             ("r_elbow", "r_forearm", 0)]:
        d = mujoco.MjData(model)
        a = np.radians(30) / 2
        adr = model.joint(joint).qposadr[0]
        d.qpos[adr:adr + 4] = np.r_[np.cos(a), np.sin(a) * fig.flexion_axes[joint]]
        mujoco.mj_kinematics(model, d)
        if sign:  # the ankle (foot origin) swings back
            assert d.xpos[model.body(tip).id][0] < -0.1
        else:  # the wrist swings forward
            assert (d.xmat[model.body(tip).id].reshape(3, 3) @ fig.segments[tip].end)[0] > 0.1


def test_masses_and_height(model, rest):
    fig = Figure.from_model(model)
    assert fig.total_mass == pytest.approx(model.body_subtreemass[model.body("pelvis").id], rel=1e-12)
    assert fig.total_mass == pytest.approx(70.0, rel=1e-9)
    assert fig.body_masses[fig.bodies.index("l_thigh")] == pytest.approx(9.8, rel=1e-12)
    # top of the head: the head ellipsoid's centre plus its z semi-axis; the soles at z = 0
    head = model.geom("head").id
    assert fig.standing_height == pytest.approx(rest.geom_xpos[head, 2] + model.geom_size[head, 2], abs=1e-12)
    assert fig.standing_height == pytest.approx(1.75, abs=1e-9)
    assert fig.neck.body == "torso"
    top = rest.site_xpos[model.site("head").id]
    assert top[2] == pytest.approx(1.75, abs=1e-12)
    np.testing.assert_allclose(fig.neck.skull[2] - fig.neck.neck[2], 2 * model.geom_size[model.geom("neck").id, 1])


def test_a_scene_has_the_same_figure(model):
    scene = mujoco.MjModel.from_xml_path(str(MODELS_DIR / "run_and_step.xml"))
    a, b = Figure.from_model(scene), shipped_figure()
    assert a.bodies == b.bodies and a.contact_sites == b.contact_sites
    assert a.standing_height == pytest.approx(b.standing_height, abs=1e-12)


def _edit(old, new):
    text = FIGURE_FILE.read_text()
    assert old in text
    return mujoco.MjModel.from_xml_string(text.replace(old, new))


@pytest.mark.parametrize("old,new,message", [
    ('<text name="figure:foot:left" data="l_heel l_toe"/>', '<text name="figure:foot:left" data="l_heel l_tip"/>',
     r"figure:foot:left.*site 'l_tip'"),
    ('<text name="figure:foot:left" data="l_heel l_toe"/>', '<text name="figure:foot:left" data="l_heel"/>',
     "two site names"),
    ('<numeric name="figure:flexion:l_knee" data="0 1 0"/>', '<numeric name="figure:flexion:l_knie" data="0 1 0"/>',
     "no ball joint 'l_knie'"),
    ('<numeric name="figure:flexion:l_knee" data="0 1 0"/>', '<numeric name="figure:flexion:l_knee" data="0 0 0"/>',
     "give an axis"),
    ('<text name="figure:end:l_foot" data="l_ball"/>', '<text name="figure:end:l_foot" data="r_ball"/>',
     "not on the body 'l_foot'"),
    ('data="l_sole_in l_sole_out"', 'data="l_sole_in l_edge"', r"figure:sole:left.*site 'l_edge'"),
])
def test_bad_annotations_name_the_element_and_the_fix(old, new, message):
    with pytest.raises(InputError, match=message):
        Figure.from_model(_edit(old, new))


def test_a_leaf_without_an_end_has_no_segment():
    """Without its ``figure:end`` site the foot has no segment; the retargeting, which needs it, says so."""
    from runner.capture.retarget import check_figure

    fig = Figure.from_model(_edit('<text name="figure:end:l_foot" data="l_ball"/>', ""))
    assert "l_foot" not in fig.segments and "r_foot" in fig.segments
    with pytest.raises(InputError, match='l_foot have no segment end.*figure:end:l_foot'):
        check_figure(fig)
    check_figure(shipped_figure())


def test_no_feet_and_no_root_are_refused():
    text = FIGURE_FILE.read_text()
    start, end = text.index("\n  <custom>"), text.index("</custom>") + len("</custom>")  # the element, not a comment
    with pytest.raises(InputError, match="has no feet.*figure:foot:left"):
        Figure.from_model(mujoco.MjModel.from_xml_string(text[:start] + text[end:]))
    with pytest.raises(InputError, match="0 free joints"):
        Figure.from_model(mujoco.MjModel.from_xml_string("<mujoco><worldbody><body><geom size='1'/></body>"
                                                         "</worldbody></mujoco>"))


def test_a_second_figure_is_another_mjcf_and_nothing_else():
    """A figure 10 % larger: its height, segment lengths and mass come from its file; the names, axes
    and feet are its annotations' (nothing in the code knows the shipped figure's sizes)."""
    big = Figure.from_model(mujoco.MjModel.from_xml_string(scaled_figure_xml(1.1)))
    ref = shipped_figure()
    assert big.standing_height == pytest.approx(1.1 * ref.standing_height, rel=1e-12)
    for body, seg in ref.segments.items():
        np.testing.assert_allclose(big.segments[body].end, 1.1 * seg.end, rtol=1e-12, atol=1e-15)
    assert big.total_mass == pytest.approx(ref.total_mass, rel=1e-12)  # masses are given, not densities
    assert big.contact_sites == ref.contact_sites and big.feet == ref.feet
    assert all(np.array_equal(big.flexion_axes[j], ref.flexion_axes[j]) for j in ref.flexion_axes)
    np.testing.assert_allclose(big.neck.top, 1.1 * ref.neck.top, rtol=1e-12)
