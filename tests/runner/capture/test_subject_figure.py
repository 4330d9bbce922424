"""The subject's figure (made from a clip's HIERARCHY) and the lossless retargeting onto it, against the
clip's own forward kinematics (tests/runner/capture/bvh_fk.py: the text parsed here, scipy rotations)."""
from pathlib import Path

import mujoco
import numpy as np
import pytest
from bvh_edit import edit_bvh
from bvh_fk import parse, world

from runner.capture.bvh import read_bvh
from runner.capture.reference_motion import load_bvh_reference
from runner.capture.subject_figure import ANKLE_HEIGHT, FOOT_BREADTH, subject_figure_xml, subject_measures
from runner.cli import main
from runner.exit_codes import EXIT_INPUT
from solver.errors import InputError
from solver.figure import Figure, shipped_figure

REPO = Path(__file__).resolve().parents[3]
CLIPS = sorted((REPO / "models" / "cmu").glob("*.bvh"))  # the shipped CMU clips (models/cmu/README.md: source, licence)
SHIPPED_CLIP = REPO / "models" / "cmu" / "127_33.bvh"
#: figure point (body origin or site) -> the CMU joint at that place
LEG_POINTS = {"l_thigh": "LeftUpLeg", "l_shin": "LeftLeg", "l_foot": "LeftFoot", "l_ball": "LeftToeBase",
              "r_thigh": "RightUpLeg", "r_shin": "RightLeg", "r_foot": "RightFoot", "r_ball": "RightToeBase"}


def figure_model(clip):
    return mujoco.MjModel.from_xml_string(subject_figure_xml(read_bvh(clip)))


def point(model, data, name):
    """World position of a body origin or a site."""
    if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name) >= 0:
        return data.site(name).xpos.copy()
    return data.body(name).xpos.copy()


@pytest.mark.slow
@pytest.mark.parametrize("clip", CLIPS, ids=lambda p: p.stem)
def test_legs_relative_to_the_hips_are_the_captures(clip):
    """Hip, knee, ankle and toe joints relative to the hips within 5 mm of the clip's own forward
    kinematics at every frame but those of a repaired tracking glitch (74_05's right ankle, 16_23's right
    shoulder: runner.capture.glitches); on the figure alone (no surfaces to stand on) the root is the
    captured Hips path (no scale, no height change)."""
    model = figure_model(clip)
    ref = load_bvh_reference(clip, model)
    assert ref.captured_root and ref.root_scale == 1.0
    b = parse(clip)
    _, pw = world(b)
    pw = pw[1:]  # the T-pose frame is dropped
    hips = pw[:, b.index("Hips")]
    data = mujoco.MjData(model)
    worst = 0.0
    glitched = {i for g in ref.glitches for i in range(round(g.start / ref.frame_time), round(g.end / ref.frame_time) + 1)}
    for i in range(0, ref.count):
        data.qpos[:] = ref.qpos[i]
        mujoco.mj_kinematics(model, data)
        root = data.body("pelvis").xpos
        assert np.allclose(root, hips[i], atol=1e-6)
        if i in glitched:
            continue
        for name, joint in LEG_POINTS.items():
            err = np.linalg.norm((point(model, data, name) - root) - (pw[i, b.index(joint)] - hips[i]))
            worst = max(worst, err)
    assert worst < 0.005, f"{clip.name}: {1000 * worst:.2f} mm"


@pytest.mark.parametrize("clip", CLIPS, ids=lambda p: p.stem)
def test_on_a_fitted_scene_the_feet_stand_on_it(tmp_path, clip):
    """On the scene fitted to the clip (`clip_scene` "auto"), the reference's root is the captured Hips
    path in the scene's levelled frame plus a vertical correction c(t) of at most 25 mm (the capture's
    floor is not flat to the mm: 14-23 mm on the six shared clips), and no contact site of any frame is
    below the fitted floor or box (MuJoCo's site positions against the scene's geoms)."""
    from runner.capture.scene import clip_scene
    from runner.capture.subject_figure import write_subject_figure
    from solver.capture_frame import CaptureFrame
    from solver.surfaces import StaticSurfaces

    figure = write_subject_figure(read_bvh(clip), tmp_path / "c.figure.xml")
    cs = clip_scene(clip, "auto", figure, tmp_path / "c.scene.xml")
    b = parse(clip)
    _, pw = world(b)
    c = cs.reference.qpos[:, :3] - CaptureFrame.from_model(cs.model).points(pw[1:, b.index("Hips")])
    assert np.abs(c[:, :2]).max() < 1e-6 and 0.001 < np.abs(c[:, 2]).max() < 0.025
    model, data = cs.model, mujoco.MjData(cs.model)
    sites = Figure.from_model(model).contact_site_ids
    lowest = np.inf
    for q in cs.reference.qpos[::4]:
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        lowest = min(lowest, StaticSurfaces.from_model(model, data).height_above(data.site_xpos[sites]).min())
    assert lowest > 0.0015  # 2 mm clearance (runner.capture.root_height.CONTACT_CLEARANCE), within 0.5 mm


def test_figure_proportions_masses_and_soles():
    """Segment lengths are the subject's bones; masses the shipped figure's fractions of the body mass;
    the identity pose stands on its published soles (soles=False) at z = 0, the ankle ANKLE_HEIGHT x
    stature above them."""
    clip = read_bvh(SHIPPED_CLIP)
    m = subject_measures(clip)
    model = mujoco.MjModel.from_xml_string(subject_figure_xml(clip, soles=False))
    fig, shipped = Figure.from_model(model), shipped_figure()
    assert fig.bodies == shipped.bodies and fig.contact_sites == shipped.contact_sites
    assert [j.name for j in fig.joints] == [j.name for j in shipped.joints]
    b = parse(SHIPPED_CLIP)
    for body, joint in (("l_thigh", "LeftLeg"), ("l_shin", "LeftFoot"), ("r_thigh", "RightLeg"),
                        ("r_shin", "RightFoot"), ("l_upper_arm", "LeftForeArm"), ("l_forearm", "LeftHand")):
        bone = np.linalg.norm(b.offsets[b.index(joint)]) * 0.0254 / 0.45
        assert fig.segments[body].length == pytest.approx(bone, rel=2e-5)  # MJCF numbers: 6 digits
    assert fig.total_mass == pytest.approx(m.mass, rel=2e-5)
    assert fig.body_masses / fig.total_mass == pytest.approx(shipped.body_masses / shipped.total_mass, rel=2e-5)
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    soles = data.site_xpos[fig.contact_site_ids, 2]
    assert np.abs(soles).max() < 0.01  # the two legs differ by a few mm; the mean stands on z = 0
    for side in ("l", "r"):
        foot = data.body(f"{side}_foot").xpos
        heel, toe = data.site(f"{side}_heel").xpos, data.site(f"{side}_toe").xpos
        assert foot[2] - heel[2] == pytest.approx(ANKLE_HEIGHT * m.stature, abs=2e-5)
        assert heel[2] == pytest.approx(toe[2], abs=2e-5)
        inner, outer = data.site(f"{side}_sole_in").xpos, data.site(f"{side}_sole_out").xpos  # across the sole
        assert inner[2] == pytest.approx(toe[2], abs=2e-5) and outer[2] == pytest.approx(toe[2], abs=2e-5)
        assert np.linalg.norm(inner - outer) == pytest.approx(FOOT_BREADTH * m.stature, abs=2e-5)
        assert (inner - outer) @ (toe - heel) == pytest.approx(0.0, abs=1e-9) and abs(inner[1]) < abs(outer[1])
    assert fig.sole_sites == shipped.sole_sites
    assert fig.standing_height == pytest.approx(m.stature, rel=0.01)
    assert 1.5 < m.stature < 1.95  # an adult


def test_mass_option_and_degenerate_offsets(tmp_path, capsys):
    clip = read_bvh(SHIPPED_CLIP)
    assert subject_measures(clip, mass=80.0).mass == 80.0
    with pytest.raises(InputError, match="--mass"):
        subject_measures(clip, mass=-1.0)
    # a zero-length shin: refused naming the file and the joint, one line, exit 2
    text = SHIPPED_CLIP.read_text().splitlines()
    at = next(i for i, ln in enumerate(text) if ln.split() == ["JOINT", "LeftFoot"])
    text[at + 2] = text[at + 2][: text[at + 2].index("OFFSET")] + "OFFSET 0 0 0"
    bad = tmp_path / "flat.bvh"
    bad.write_text("\n".join(text) + "\n")
    with pytest.raises(InputError, match=r"flat\.bvh.*LeftFoot.*zero-length"):
        subject_figure_xml(read_bvh(bad))
    rc = main(["keyframes-from-bvh", str(bad), "--out", str(tmp_path / "k.keyframes.json"), "--quiet"])
    err = capsys.readouterr().err
    assert rc == EXIT_INPUT and err.count("\n") == 1 and "LeftFoot" in err and "flat.bvh" in err


def test_keyframe_file_names_the_figure_and_animate_finds_it(tmp_path, capsys):
    """keyframes-from-bvh writes <name>.figure.xml beside the file and names it; the scene includes it;
    the reference read back through the keyframe file is the lossless one."""
    from runner.problem_file import find_reference, load_problem

    clip = edit_bvh(SHIPPED_CLIP, tmp_path / "run.bvh", seconds=0.5)
    out = tmp_path / "k" / "run.keyframes.json"
    out.parent.mkdir()
    assert main(["keyframes-from-bvh", str(clip), "--out", str(out), "--quiet"]) == 0
    figure = out.parent / "run.figure.xml"
    assert figure.is_file() and (out.parent / "run.scene.xml").is_file()
    keyframes, info, model, _, _ = load_problem(out, None)
    assert info.model == figure.resolve()
    fig = Figure.from_model(model)
    assert fig.segments["l_thigh"].length != pytest.approx(shipped_figure().segments["l_thigh"].length, rel=1e-3)
    ref = find_reference(info, model, quiet=True)
    assert ref.captured_root
    # --figure default: the shipped figure, the root path scaled as before
    out2 = tmp_path / "d.keyframes.json"
    assert main(["keyframes-from-bvh", str(clip), "--out", str(out2), "--figure", "default", "--quiet"]) == 0
    _, info2, model2, _, _ = load_problem(out2, None)
    assert model2.nq == model.nq and not (tmp_path / "d.figure.xml").exists()
    assert Figure.from_model(model2).segments["l_thigh"].length == pytest.approx(0.42)
    assert not find_reference(info2, model2, quiet=True).captured_root


@pytest.mark.parametrize("extra, words", [(["--figure", "default", "--mass", "70"], ["--mass", "--figure subject"]),
                                          (["--figure", "nope.xml"], ["--figure nope.xml", "no such file"])])
def test_bad_figure_options_are_one_line(tmp_path, capsys, extra, words):
    out = tmp_path / "k.keyframes.json"
    rc = main(["keyframes-from-bvh", str(SHIPPED_CLIP), "--out", str(out), "--quiet", *extra])
    err = capsys.readouterr().err
    assert rc == EXIT_INPUT and err.count("\n") == 1 and all(w in err for w in words), err
    assert not out.exists()


def test_a_scene_holding_its_figure_inline_cannot_take_the_subjects(tmp_path, capsys):
    """A scene with the figure written inline (no include to replace): one line with the fix."""
    text = (REPO / "models" / "humanoid39.xml").read_text()
    inline = text.replace("</worldbody>", '<geom name="floor" type="plane" size="0 0 0.05"/></worldbody>')
    scene = tmp_path / "inline.xml"
    scene.write_text(inline)
    rc = main(["keyframes-from-bvh", str(SHIPPED_CLIP), "--out", str(tmp_path / "k.json"), "--scene", str(scene),
               "--quiet"])
    err = capsys.readouterr().err
    assert rc == EXIT_INPUT and err.count("\n") == 1 and "inline" in err and "--figure default" in err, err


def test_a_foot_the_skeleton_gives_no_length_points_where_it_stands_at_rest(tmp_path):
    """127_33 with its toes cut off, each foot's End Site at its ankle (a toeless export): the foot's direction is the
    rest pose's forward, square to the hips and level, in place of the ball's. Its frame is the toed clip's turned about
    the vertical by no more than CMU's toes turn out from straight ahead in the rest pose (their OFFSETs, by hand:
    atan(0.207 / 2.203) = 5.4 degrees left, atan(0.267 / 2.208) = 6.9 right), 1 degree allowed for the flat frames'
    scatter; the subject's figure has its toe site on the sole `BALL_AHEAD` of the foot length straight ahead, the heel
    `HEEL_BACK` of it behind; the clean of the clip ends with its exit code 0."""
    from runner.capture.body_frames import body_frames
    from runner.capture.skeleton import recognise
    from runner.capture.subject_figure import BALL_AHEAD, HEEL_BACK
    from solver.quaternion import conj, mul

    clip = SHIPPED_CLIP
    toeless = read_bvh(edit_bvh(clip, tmp_path / "toeless.bvh", seconds=1.0, toeless=("LeftToeBase", "RightToeBase")))
    toed = read_bvh(edit_bvh(clip, tmp_path / "toed.bvh", seconds=1.0))
    a, b = (body_frames(c, recognise(c), shipped_figure()) for c in (toeless, toed))
    for side, (out, ahead) in (("l", (0.20718, 2.20259)), ("r", (0.26704, 2.20815))):
        r = mul(conj(a.offsets[f"{side}_foot"]), b.offsets[f"{side}_foot"])
        assert np.linalg.norm(r[1:3]) < 1e-9  # about the vertical alone: the up direction is the flat frames' in both
        angle = np.degrees(2 * np.arccos(min(1.0, abs(float(r[0])))))
        assert angle <= np.degrees(np.arctan2(out, ahead)) + 1.0, (side, angle)
    model = mujoco.MjModel.from_xml_string(subject_figure_xml(toeless, soles=False))
    m = subject_measures(toeless)
    for side in "lr":
        heel, toe = model.site(f"{side}_heel").pos, model.site(f"{side}_toe").pos
        assert toe[0] == pytest.approx(BALL_AHEAD * m.foot_length, abs=2e-5) and abs(toe[1]) < 1e-9
        assert heel[0] == pytest.approx(-HEEL_BACK * m.foot_length, abs=2e-5) and heel[2] == pytest.approx(toe[2], abs=2e-5)
    assert main(["clean", str(tmp_path / "toeless.bvh"), "--no-render", "--no-summary", "--quiet",
                 "--out-dir", str(tmp_path / "out")]) == 0
