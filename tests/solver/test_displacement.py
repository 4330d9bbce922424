"""The clean of a capture (solver.displacement): the capture plus the least displacement that meets the
constraints, on hand-made captures of the toy figure whose answers are known.

* A capture that meets every constraint (the figure swaying and swinging its legs above the floor) comes
  back exactly: the
  measure of change and every constraint are at their minimum on d = 0.
* The same capture with the pelvis dipped 2 cm (its feet 2 cm into the floor) over 0.3 s comes back with
  its feet out of the floor (penetration within the 1 mm tolerance, measured by MuJoCo's own kinematics),
  and unchanged (within 1 mm) far from the dip and from the clip's free ends (within 4 mm at them); pinned
  frames are the capture's exactly.
* The displacement has a frame at every capture frame, each a quadrature point: the cleaned clip between
  frames is c + d exactly.
* Phi's gradient with the capture as the base motion agrees with central finite differences.
"""
import mujoco
import numpy as np
import pytest

from solver.constraint_set import PENETRATION_TOLERANCE
from solver.constraints.base import RELATIVE_TOLERANCE
from solver.contacts import Contact
from solver.displacement import (
    CORRECTION_TIME,
    CUBIC_ERROR,
    MAX_PANELS,
    anchors,
    build_displacement,
    clean_solution,
    frame_panels,
    pin_frames,
    solve_displacement,
)
from solver.errors import InputError
from solver.feasibility import Raise
from solver.foot_bounds import CAPTURE_RESOLUTION, FLOAT_LIMIT
from solver.frames import FrameSet
from solver.layout import StateLayout
from solver.least_change import LeastChangeOptions
from solver.peak_bounds import filter_capture
from solver.quadrature import simpson_points
from solver.spline import interpolate
from solver.spline_basis import SplineBasis

from conftest import TOY_SCENE

#: [Hz] the hand-made capture's frame rate
FPS = 60.0
#: [s] its length
DURATION = 2.0
#: [m] the pelvis height to start from (the toy's sites are 0.95 m below it with straight legs)
STAND = 0.96
#: [s] the dip's centre and width, [m] its depth below the floor's contact height (sites 1 cm up: 3 cm
#: down puts them 2 cm in)
DIP_T, DIP_W, DIP = 1.0, 0.3, 0.03


def _capture(model, dip: float = 0.0, fps: float = FPS):
    """(times, qpos): the toy figure swaying 3 cm forward and back at 1 Hz (peak pelvis acceleration
    1.2 m/s^2) and swinging its legs (hips +-6 deg, knees bent 9 +- 3 deg, about their flexion axis), its
    pelvis at the height that holds its lowest site 1 cm above the floor, then lowered by a raised-cosine
    dip of `dip` [m]."""
    layout = StateLayout.from_model(model)
    t = np.arange(int(round(DURATION * fps)) + 1) / fps
    q = np.zeros((len(t), model.nq))
    q[:, 0] = 0.03 * np.sin(2 * np.pi * t)
    for slot in layout.quat_slots:
        q[:, slot[0]] = 1.0
    phase = 2 * np.pi * t
    for name, angle in (("l_hip", 0.1 * np.sin(phase)), ("r_hip", -0.1 * np.sin(phase)),
                        ("l_knee", 0.15 + 0.05 * np.sin(phase + 0.5)), ("r_knee", 0.15 - 0.05 * np.sin(phase + 0.5))):
        a = toy_joint_slot(model, name)
        q[:, a], q[:, a + 2] = np.cos(angle / 2), np.sin(angle / 2)  # about y, the flexion axis
    q[:, 2] = STAND
    q[:, 2] += 0.01 - _lowest_site(model, q)
    near = np.abs(t - DIP_T) < DIP_W / 2
    q[near, 2] -= dip * 0.5 * (1 + np.cos(2 * np.pi * (t[near] - DIP_T) / DIP_W))
    return t, q


def toy_joint_slot(model, name: str) -> int:
    """The qpos address of a ball joint's quaternion."""
    return int(model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)])


def _lowest_site(model, qpos) -> np.ndarray:
    """(n,) [m] the lowest contact site's height at each pose (MuJoCo's forward kinematics)."""
    data = mujoco.MjData(model)
    out = np.empty(len(qpos))
    for i, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        out[i] = data.site_xpos[:, 2].min()
    return out


def test_a_capture_that_meets_every_constraint_comes_back_exactly(toy_model):
    t, q = _capture(toy_model)
    disp = build_displacement(toy_model, t, q)
    sol = solve_displacement(disp, LeastChangeOptions())
    clean = clean_solution(disp, sol)
    assert not sol.unmet
    np.testing.assert_allclose(clean.frames.values, q, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(clean.initial.values, q)


def test_a_capture_turning_fast_between_its_frames_comes_back_exactly(toy_model):
    """At 10 fps the left hip twists +-40 degrees about the vertical at 5 Hz, 80 degrees from one frame
    to the next (a tracking glitch's size: bvh_test1's elbow dips further): the spline through the
    capture's own unit quaternions dips to cos(20 deg) = 0.94 between them, beyond the unit-norm bound's
    0.03 and its tolerance. Only a change of the pose at the frames
    could lengthen that chord, and the clip is written at its frames, so the limit there is the capture's
    own: the capture meets every constraint and comes back exactly, nothing raised."""
    from solver.constraints.unit import UNIT_LIMIT

    t, q = _twisting(toy_model)
    a = toy_joint_slot(toy_model, "l_hip")
    between = interpolate(t, q, 0.5 * (t[:-1] + t[1:]), 0)[:, a:a + 4]
    assert np.abs(np.linalg.norm(between, axis=1) - 1).max() > UNIT_LIMIT + 0.02  # the premise: the bare bound broken
    disp = build_displacement(toy_model, t, q)
    sol = solve_displacement(disp, LeastChangeOptions())
    assert not sol.unmet and not sol.certificate
    np.testing.assert_allclose(clean_solution(disp, sol).frames.values, q, rtol=0, atol=1e-12)


def _twisting(model, fps: float = 10.0):
    """The toy capture at `fps` with its left hip twisting +-40 degrees about the vertical at 5 Hz (80 degrees from
    one frame to the next at 10 fps)."""
    t, q = _capture(model, fps=fps)
    a = toy_joint_slot(model, "l_hip")
    twist = np.radians(40.0) * np.cos(np.pi * 10.0 * t)
    q[:, a:a + 4] = np.c_[np.cos(twist / 2), np.zeros((len(t), 2)), np.sin(twist / 2)]  # about z
    return t, q


def _cubic_miss(model, t, q, points, per: int) -> np.ndarray:
    """(len(points) - 1,) [m] the most the cubic Hermite curve between consecutive `points` (each contact site's
    position and velocity there) misses the site's path at `per` times inside, by MuJoCo's kinematics on the
    natural spline through the frames (t, q), its quaternions made unit; velocities by central differences."""
    layout = StateLayout.from_model(model)

    def sites(times):
        Y = interpolate(t, q, times, 0)
        for slot in layout.quat_slots:
            Y[:, slot] /= np.linalg.norm(Y[:, slot], axis=1, keepdims=True)
        data, out = mujoco.MjData(model), np.empty((len(times), model.nsite, 3))
        for i, y in enumerate(Y):
            data.qpos[:] = y
            mujoco.mj_kinematics(model, data)
            out[i] = data.site_xpos
        return out

    step = 1e-6  # [s] central differences: truncation ~1e-12 relative, round-off ~1e-10 m/s
    p, v = sites(points), (sites(points + step) - sites(points - step)) / (2 * step)
    h = np.diff(points)[:, None, None, None]
    s = (np.arange(per) + 1.0) / (per + 1)  # inside each interval
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    cubic = (h00[:, None, None] * p[:-1, None] + h10[:, None, None] * h * v[:-1, None]
             + h01[:, None, None] * p[1:, None] + h11[:, None, None] * h * v[1:, None])
    inner = sites((points[:-1, None] + np.diff(points)[:, None] * s).ravel()).reshape(cubic.shape)
    return np.linalg.norm(cubic - inner, axis=-1).max(axis=(1, 2))


def test_the_quadrature_panels_bring_the_cubic_between_two_points_within_its_error(toy_model):
    """Where a site turns fast between capture frames (the left hip twisting 80 degrees from one 10 fps frame to the
    next), the cubic between two points of one Simpson panel misses the foot's path by centimetres; the panels
    (`frame_panels`) split those intervals until the cubic between any two points, measured by MuJoCo at nine times
    between them, is within CUBIC_ERROR of it (the Hermite error peaks at the midpoint where it checks, 5 % allowed
    for its higher-order terms). On the slow capture at 60 fps one panel each already is."""
    t, q = _twisting(toy_model)
    disp = build_displacement(toy_model, t, q)
    one, _ = simpson_points(t)
    assert _cubic_miss(toy_model, t, q, one, 9).max() > 10 * CUBIC_ERROR  # the premise: one panel misses the foot
    panels = frame_panels(t, q, disp.lc.al.tmap, disp.lc.al.engine)
    assert panels.max() > 1 and panels.max() <= MAX_PANELS
    points, _ = simpson_points(t, panels)
    np.testing.assert_array_equal(disp.lc.al.t, points)  # the clean's own points
    np.testing.assert_array_equal(disp.panels, panels)
    assert _cubic_miss(toy_model, t, q, points, 9).max() <= 1.05 * CUBIC_ERROR
    slow_t, slow_q = _capture(toy_model)
    slow = build_displacement(toy_model, slow_t, slow_q)
    np.testing.assert_array_equal(frame_panels(slow_t, slow_q, slow.lc.al.tmap, slow.lc.al.engine), 1)
    np.testing.assert_array_equal(slow.lc.al.t, simpson_points(slow_t)[0])


@pytest.fixture(scope="module")
def dipped(toy_model):
    t, q = _capture(toy_model, DIP)
    disp = build_displacement(toy_model, t, q, pins=(0.25, 1.75))
    sol = solve_displacement(disp, LeastChangeOptions())
    return t, q, disp, sol, clean_solution(disp, sol)


def test_a_clean_s_rounds_run_to_their_own_end(dipped):
    """`LeastChangeOptions.round_evals` caps the rounds of a solve whose frames are refined, not a clean's: its solve ends
    on a whole subproblem's progress, so the same clean under any cap is the same path (a clean's rounds: with
    `newton`, which runs them before any search)."""
    t, q, disp, sol, clean = dipped
    rounds = solve_displacement(disp, LeastChangeOptions(newton=True))
    capped = solve_displacement(disp, LeastChangeOptions(newton=True, round_evals=3))
    assert max(r.result.n_evals for r in rounds.rounds) > 3  # the cap would have bitten
    np.testing.assert_array_equal(capped.frames.values, rounds.frames.values)


def test_feet_pushed_into_the_floor_come_out_and_the_rest_stays(toy_model, dipped):
    t, q, disp, sol, clean = dipped
    assert _lowest_site(toy_model, q).min() < -0.019  # the capture: 2 cm in
    fine = np.linspace(t[0], t[-1], 1001)  # between the frames too
    low = _lowest_site(toy_model, clean.frames.path(fine))
    # penetration within its 0.9 mm tolerance as MuJoCo measures it at 1001 times: the constraint's cubic between two
    # points is micrometres from the path (10 um allowed), inside the clean's 1 mm bound by the capture's resolution
    assert low.min() >= -PENETRATION_TOLERANCE - 1e-5, low.min()
    far = np.abs(t - DIP_T) > DIP_W / 2 + 2 * CORRECTION_TIME  # two correction times beyond the dip's edges
    moved = np.linalg.norm(_bodies(toy_model, clean.frames.values) - _bodies(toy_model, q), axis=-1).max(axis=1)
    inside = far & (t > t[0] + CORRECTION_TIME) & (t < t[-1] - CORRECTION_TIME)
    assert moved[inside].max() <= 1e-3, moved[inside].max()  # within 1 mm, the penetration tolerance's scale
    # the clip's ends are not pinned: there only D's pose term holds the displacement (a ramp changes no
    # acceleration), and the subproblems, inexact, leave 1.8-2.2 mm at the first frame, by the BLAS kernel
    assert moved[far].max() <= 0.2 * (DIP - 0.01), moved[far].max()  # a fifth of the 2 cm correction, at most


def _bodies(model, qpos) -> np.ndarray:
    """(n, nbody, 3) [m] every body's origin at each pose."""
    data = mujoco.MjData(model)
    out = np.empty((len(qpos), model.nbody, 3))
    for i, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        out[i] = data.xpos
    return out


def test_the_displacement_lives_on_the_capture_frames(dipped):
    """Every capture frame is a frame of d and a quadrature point, so c + d is a cubic spline on the
    capture's knots: the cleaned clip's natural spline through its frames is c + d between them too (the
    two computed independently: c and d each interpolated on its own frames), and a bound on acceleration
    (linear between knots) met at the points holds between them."""
    t, q, disp, sol, clean = dipped
    np.testing.assert_array_equal(sol.frames.times, t)  # every capture frame, and no frame between them
    assert np.min(np.abs(disp.lc.al.t[None, :] - t[:, None]), axis=1).max() <= 1e-9
    fine = np.linspace(t[0], t[-1], 1001)
    direct = interpolate(t, q, fine, 0) + interpolate(t, sol.frames.values - disp.anchor, fine, 0)
    np.testing.assert_allclose(clean.frames.path(fine), direct, rtol=0, atol=1e-9)


@pytest.mark.slow
def test_a_clip_at_30_fps_is_cleaned_on_its_own_frames(toy_model):
    """At 30 fps a capture frame is 33 ms from the next, room for the least violation to split a segment
    (down to two 5 ms quadrature intervals): a frame of d between capture frames would be lost when the
    cleaned clip is written at the capture's frames, and the clip read back would no longer be the path
    solved (an AnimatedDrawings zombie at 30 fps: 476 frames added, its toe 1.25 mm in the floor and its
    pelvis accelerating 9 % past its limit in the written clip). The frames are the capture's, and the
    written clip meets the penetration bound between them (1000 Hz, MuJoCo's kinematics)."""
    t, q = _capture(toy_model, DIP, fps=30.0)
    disp = build_displacement(toy_model, t, q)
    sol = solve_displacement(disp, LeastChangeOptions())
    clean = clean_solution(disp, sol)
    np.testing.assert_array_equal(sol.frames.times, t)
    fine = np.linspace(t[0], t[-1], 1001)
    assert _lowest_site(toy_model, clean.frames.path(fine)).min() >= -1e-3 - 1e-4


def test_the_no_jolt_bound_is_the_filtered_capture_s_peak_by_central_differences(toy_model):
    """A clean's no-jolt bound on the pelvis is the 6 Hz capture's peak as the acceptance figures measure it
    (central differences at the frames, here numpy's second differences of the root position), not its
    spline's, which at 30 fps runs higher: a change within the bound at the frames then stays within that
    peak by the same measure (tests/solver/test_frame_derivatives.py)."""
    fps = 30.0
    t, q = _capture(toy_model, DIP, fps=fps)
    disp = build_displacement(toy_model, t, q)
    bound = next(c for c in disp.lc.al.constraints if c.name == "acceleration")
    root = int(np.flatnonzero((bound.dofs == [0, 1, 2]).all(axis=1))[0])  # the pelvis: the free joint's position
    A = bound.limits[root] / (1.0 - RELATIVE_TOLERANCE)
    x = filter_capture(t, q, StateLayout.from_model(toy_model))[:, :3]
    peak = np.linalg.norm(x[2:] - 2 * x[1:-1] + x[:-2], axis=1).max() * fps ** 2
    np.testing.assert_allclose(A, peak, rtol=1e-9)
    assert np.abs(interpolate(t, x, t, 2)).max() > 1.05 * peak  # the spline's peak, which the bound is not
    # its unit, as a certificate that raises it states it: the pelvis's linear acceleration, a ball joint's angular
    label = bound.labels[root]
    assert label.endswith("(linear)") and bound.column_unit(label) == "m/s^2"
    assert {bound.column_unit(x) for x in bound.labels if not x.endswith("(linear)")} == {"rad/s^2"}


def test_a_planted_foot_met_within_its_tolerance_is_within_the_clean_s_float_bound(toy_model):
    """A clean's float bound is 3 mm (docs/corpus.md "Cleaning the corpus"): every planted pair's limit plus its
    tolerance stays within it, so a path that meets the pair within tolerance meets the bound (a keyed path's
    2 mm tolerance would accept 4 mm)."""
    t, q = _capture(toy_model)
    disp = build_displacement(toy_model, t, q, contacts=[Contact("l_toe", 0.2, 0.8), Contact("r_heel", 1.1, 1.6)])
    planted = [c for c in disp.lc.al.constraints if c.name == "planted"]
    assert planted and all(c.size for c in planted)
    for c in planted:
        foot = np.isin(c.labels, ["left", "right"])  # a foot's pairs; the rest are each site's own (next test)
        assert foot.any() and np.all(np.asarray(c.limit)[foot] + c.tolerance <= 3e-3 + 1e-12), (c.limit, c.tolerance)


def test_each_site_in_contact_is_held_no_higher_than_captured(toy_model):
    """Each site the schedule has in contact has a planted pair of its own over its own contact
    (solver.foot_bounds): its mean height no more than the capture's there, FLOAT_LIMIT where the capture holds
    it lower. The limits against the capture's mean height over each contact's frames by MuJoCo's kinematics
    (the sites' radius is 0 and the floor z = 0: a site's height is its z)."""
    t, q = _capture(toy_model)
    contacts = [Contact("l_toe", 0.2, 0.8), Contact("l_heel", 0.5, 1.0), Contact("r_heel", 1.1, 1.6)]
    disp = build_displacement(toy_model, t, q, contacts=contacts)
    planted = next(c for c in disp.lc.al.constraints if c.name == "planted")
    own = ~np.isin(planted.labels, ["left", "right"])
    assert list(planted.labels[own]) == [c.site for c in contacts]
    h = _site_heights(toy_model, q, [c.site for c in contacts])
    expected = [h[(t >= c.start - 1e-9) & (t <= c.end + 1e-9), k].mean() for k, c in enumerate(contacts)]
    # the clean's mean is of the heights' positive part smoothed over CAPTURE_RESOLUTION e (Huber's: h - e/2 for
    # h > e, as every height here): the capture meets the limit exactly in the constraint's own measure
    np.testing.assert_allclose(planted.limit[own], np.maximum(FLOAT_LIMIT, np.array(expected) - CAPTURE_RESOLUTION / 2),
                               atol=1e-9)
    assert np.all(planted.limit[own] > FLOAT_LIMIT)  # the capture holds its sites 1 cm up and more


def _site_heights(model, qpos, sites) -> np.ndarray:
    """(n, k) [m] the named sites' heights above the floor (z = 0) at each pose (MuJoCo's forward kinematics)."""
    data = mujoco.MjData(model)
    ids = [model.site(s).id for s in sites]
    out = np.empty((len(qpos), len(ids)))
    for i, x in enumerate(qpos):
        data.qpos[:] = x
        mujoco.mj_kinematics(model, data)
        out[i] = data.site_xpos[ids, 2]
    return out


def test_pins_hold_the_capture_exactly(dipped):
    t, q, disp, sol, clean = dipped
    pinned = pin_frames(t, (0.25, 1.75))
    np.testing.assert_array_equal(t[pinned], [0.25, 1.75])
    np.testing.assert_allclose(clean.frames.values[pinned], q[pinned], rtol=0, atol=1e-15)


def test_a_pin_outside_the_clip_is_named():
    with pytest.raises(InputError, match="--pin 3: outside the clip's 0..2 s"):
        pin_frames(np.linspace(0.0, 2.0, 5), (3.0,))


def test_an_unknown_feet_mode_is_named(toy_model):
    t, q = _capture(toy_model)
    with pytest.raises(InputError, match="feet 'glued': not one of planted, captured"):
        build_displacement(toy_model, t, q, feet="glued")


def test_anchors_are_the_captured_orientations_and_zero_off_the_quaternions(toy_model):
    t, q = _capture(toy_model)
    layout = StateLayout.from_model(toy_model)
    e = anchors(2.0 * q, layout.quat_slots)  # a quaternion of any length: its orientation
    for slot in layout.quat_slots:
        np.testing.assert_allclose(e[:, slot], q[:, slot], rtol=0, atol=1e-12)
    lin = np.setdiff1d(np.arange(toy_model.nq), layout.quat_slots.ravel())
    np.testing.assert_array_equal(e[:, lin], 0.0)


def test_a_joint_turning_round_is_displaced_by_any_rotation_on_the_unit_sphere(toy_model):
    """The root turns through a full circle about the vertical over the clip (180 degrees from any one
    orientation somewhere). Each frame of d moves its quaternion on its sphere about that frame's captured
    orientation, so whatever rotation vectors d the variables hold, c + d at every capture frame is
    c (x) exp(d), a unit quaternion (Hamilton's product computed here, apart from the solver's manifold).
    Anchored at the clip's mean orientation, c + d left the unit sphere (norms 0.1 off on 05_09)."""
    from solver.manifold import FrameVariables

    t, q = _capture(toy_model)
    yaw = 2 * np.pi * t / t[-1]
    q[:, 3], q[:, 6] = np.cos(yaw / 2), np.sin(yaw / 2)  # the root's quaternion (w, x, y, z) about z
    disp = build_displacement(toy_model, t, q)
    var = FrameVariables(disp.lc.plain, StateLayout.from_model(toy_model).quat_slots)
    rng = np.random.default_rng(7)
    x = np.zeros(var.size)
    x[var.n_linear:] = rng.normal(scale=0.3, size=var.size - var.n_linear)  # rotation vectors [rad]
    cleaned = disp.qpos + var.values(x) - disp.anchor
    rows, slots = var.quaternion_frames()
    d = x[var.n_linear:].reshape(-1, 3)[slots == 0]  # the root's rotation vector at each of its frames
    angle = np.linalg.norm(d, axis=1)
    e = np.c_[np.cos(angle / 2), np.sin(angle / 2)[:, None] * d / angle[:, None]]  # exp(d), (w, x, y, z)
    c = q[rows[slots == 0], 3:7]
    want = np.c_[c[:, 0] * e[:, 0] - (c[:, 1:] * e[:, 1:]).sum(1),  # c (x) exp(d), Hamilton's product
                 c[:, :1] * e[:, 1:] + e[:, :1] * c[:, 1:] + np.cross(c[:, 1:], e[:, 1:])]
    np.testing.assert_allclose(cleaned[rows[slots == 0], 3:7], want, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(cleaned[:, 3:7], axis=1), 1.0, rtol=0, atol=1e-12)


@pytest.mark.parametrize("contacts", [(), (Contact("l_toe", 0.4, 0.9), Contact("r_heel", 1.1, 1.6))])
def test_gradient_with_the_capture_as_base_matches_finite_differences(toy_model, contacts):
    """With contacts, the planted means over the contact's frames (the ramp of the heights) and the slides
    measured per frame are among the terms."""
    t, q = _capture(toy_model, DIP)
    disp = build_displacement(toy_model, t, q, contacts=contacts, flights=())
    assert {"planted", "slide"} <= {c.name for c in disp.lc.al.constraints} or not contacts
    al, layout = disp.lc.al, disp.lc.layout
    frames = disp.lc.plain  # a frame of d at every capture frame, as the clean solves it
    rng = np.random.default_rng(3)
    P = frames.values.copy()
    free = ~frames.fixed
    P[free] += rng.normal(scale=2e-3, size=int(free.sum()))  # off d = 0: every constraint and D nonzero
    al.rho, al.lam = 10.0, [np.abs(rng.normal(size=c.size)) for c in al.constraints]
    basis = SplineBasis(frames.times, al.t)
    _, G, _ = al.evaluate(basis, P)
    for _ in range(6):
        V = np.where(free, rng.normal(size=P.shape), 0.0)
        h = 1e-6
        fd = (al.evaluate(basis, P + h * V, grad=False)[0] - al.evaluate(basis, P - h * V, grad=False)[0]) / (2 * h)
        assert abs(float((G * V).sum()) - fd) <= 1e-5 * max(1.0, abs(fd)), (float((G * V).sum()), fd)
    assert layout.quat_slots.size  # the toy has quaternions: their components are among the directions


@pytest.mark.parametrize("fps", [24.0, 30.0, 120.0])
def test_a_slide_met_within_its_tolerance_is_within_the_clean_s_skate_bound(toy_model, fps):
    """Every slide pair of a clean, met within its tolerance, lets its site slide at most 0.2 mm a frame on
    average (the clean's skate bound) at the clip's frame rate, on a contact of three frame steps and a long
    one: the fastest uniform slide its limit plus tolerance accepts (uniform: the Huber measure is convex,
    so for a given measure it covers the most distance, Jensen), inverted here from the Huber function's
    closed form, is within the bound."""
    t, q = _capture(toy_model, fps=fps)
    short = (3.0 / fps, 6.0 / fps)
    disp = build_displacement(toy_model, t, q, contacts=[Contact("l_toe", *short), Contact("r_heel", 0.5, 1.5)],
                              flights=())
    slide = next(c for c in disp.lc.al.constraints if c.name == "slide")
    b = slide.b
    m = (np.asarray(slide.limit) + slide.tolerance) / slide.span  # [m/s] the mean Huber measure accepted
    v = np.where(m <= b / 2, np.sqrt(2 * b * m), m + b / 2)  # huber_b(v) = m solved for v
    assert np.all(v / fps <= 2e-4 + 1e-12), v / fps


@pytest.mark.slow
def test_a_short_contact_at_30_fps_is_held_within_the_clean_s_skate_bound(toy_model):
    """A clean's skate bound is 0.2 mm a frame in contact (docs/corpus.md "Cleaning the corpus"), at the
    clip's own frame rate: its slide pairs are measured per frame (`solver.foot_bounds.CLEAN_SKATE`).
    At 30 fps a contact of four frames, where the swaying capture slides the toe 1-6 mm a frame: the cleaned
    toe, by MuJoCo's kinematics at the capture's frames, slides at most 0.2 mm a frame on average over it (a
    keyed path's tolerance, 2 mm over the contact, left 0.38 mm a frame). The capture is lowered to hold its
    lowest site 0.5 mm above the floor, the contact's site the lowest there."""
    t, q = _capture(toy_model, fps=30.0)
    q[:, 2] -= 0.0095
    on = (t >= 0.2 - 1e-9) & (t <= 0.3 + 1e-9)
    assert on.sum() == 4
    heights = {name: _site(toy_model, q[on], name)[:, 2] for name in ("l_heel", "l_toe", "r_heel", "r_toe")}
    site = min(heights, key=lambda name: heights[name].max())
    disp = build_displacement(toy_model, t, q, contacts=[Contact(site, 0.2, 0.3)], flights=())
    sol = solve_displacement(disp, LeastChangeOptions())
    assert not sol.certificate

    def skate(qpos):  # [m/frame] the site's mean horizontal step between the contact's frames
        xy = _site(toy_model, qpos[on], site)[:, :2]
        return float(np.linalg.norm(np.diff(xy, axis=0), axis=1).mean())

    assert skate(q) > 2e-3  # the premise: the capture slides
    assert skate(clean_solution(disp, sol).frames.values) <= 2e-4


def _site(model, qpos, name: str) -> np.ndarray:
    """(n, 3) [m] a site's position at each pose (MuJoCo's forward kinematics)."""
    data = mujoco.MjData(model)
    k = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)
    out = np.empty((len(qpos), 3))
    for i, x in enumerate(qpos):
        data.qpos[:] = x
        mujoco.mj_kinematics(model, data)
        out[i] = data.site_xpos[k]
    return out


def test_a_clean_s_planted_mean_is_over_its_contact_s_frames_of_the_positive_height(toy_model):
    """A clean's planted pair is the mean over the contact's capture frames (the float figure's frames, not
    the midpoint rule's) of the support site's height's positive part: on the capture, whose sites are 1 cm
    up, it is that mean less half the ramp's width, the heights by MuJoCo's kinematics (the toy's sites
    have no radius, its floor is z = 0); with the capture dipped 3 cm, the frames whose site is in the
    floor count as 0."""

    for dip in (0.0, DIP):
        t, q = _capture(toy_model, dip)
        contact = Contact("l_toe", 0.9, 1.2)
        disp = build_displacement(toy_model, t, q, contacts=[contact], flights=())
        al = disp.lc.al
        planted = next(c for c in al.constraints if c.name == "planted")
        value = planted.measure(al.state(SplineBasis(t, al.t), disp.lc.plain.values))
        on = (t >= contact.start - 1e-9) & (t <= contact.end + 1e-9)
        h = _site(toy_model, q[on], "l_toe")[:, 2]
        e = CAPTURE_RESOLUTION
        want = np.where(h <= 0, 0.0, np.where(h < e, h * h / (2 * e), h - e / 2)).mean()
        np.testing.assert_allclose(value, [want, want], rtol=0, atol=1e-9)  # the foot's pair and the site's own
    assert h.min() < 0  # the dipped capture: some frames in the floor, counted as 0


def test_ramp_is_the_smoothed_positive_part_and_its_slope():
    """`ramp`: 0 below 0, within e/2 of max(0, h), its slope the derivative (central differences)."""
    from solver.constraints.sites import ramp

    e = 1e-4
    h = np.linspace(-3e-4, 3e-4, 601)
    value, slope = ramp(h, e)
    assert np.all(value[h <= 0] == 0.0)
    assert np.all(np.abs(value - np.maximum(0.0, h)) <= e / 2 + 1e-18)
    step = 1e-9
    fd = (ramp(h + step, e)[0] - ramp(h - step, e)[0]) / (2 * step)
    np.testing.assert_allclose(slope, fd, rtol=0, atol=1e-4)


def test_the_soles_edges_are_held_no_deeper_than_the_capture_holds_them():
    """The soles' edge sites (``figure:sole:SIDE``, `Figure.soles`) of the toy figure, 1 cm below its heel and toe, in
    the dipped capture: 2 cm into the floor in the dip, out elsewhere. The sole constraint's limit on each interval
    between quadrature points is the capture's own deepest point there (brute force: MuJoCo's kinematics on the
    capture's spline at 20 samples an interval), 0 where it is out; the clean, which lifts the heel and toe out
    of the floor, leaves no edge deeper than the capture's (1001 times) within the penetration tolerance."""
    from solver.constraints.penetration import SoleEdges
    from solver.spline import interpolate as spline

    scene = TOY_SCENE.replace("<custom>", '<custom><text name="figure:sole:left" data="l_sole_in l_sole_out"/>'
                                          '<text name="figure:sole:right" data="r_sole_in r_sole_out"/>')
    for s in "lr":  # the edges across the sole under the ball, 1 cm below the heel and toe
        toe = f'<site name="{s}_toe" pos=".15 0 -.45"/>'
        scene = scene.replace(toe, toe + f'<site name="{s}_sole_in" pos=".1 .05 -.46"/><site name="{s}_sole_out" pos=".1 -.05 -.46"/>')
    model = mujoco.MjModel.from_xml_string(scene)
    edges = [f"{s}_sole_{e}" for s in "lr" for e in ("in", "out")]
    t, q = _capture(model, DIP)  # its lowest site, an edge, 1 cm up, then 2 cm down in the dip
    disp = build_displacement(model, t, q)
    (sole,) = [c for c in disp.lc.al.constraints if isinstance(c, SoleEdges)]
    pts = disp.lc.al.t
    u = np.linspace(0.0, 1.0, 21)
    fine = (pts[:-1, None] + np.diff(pts)[:, None] * u).ravel()
    depth = -_site_heights(model, spline(t, q, fine), edges).reshape(len(pts) - 1, len(u), len(edges)).min(axis=1)
    expected = np.maximum(0.0, depth)[..., None]  # (interval, edge, surface): the floor's; the step is out of reach
    expected = np.concatenate([expected, np.zeros_like(expected)], axis=-1).ravel()
    assert expected.max() > 0.019  # the premise: 2 cm in the dip
    np.testing.assert_allclose(sole.limit, expected, rtol=0, atol=2e-5)  # the cubic between points: microns
    clean = clean_solution(disp, solve_displacement(disp, LeastChangeOptions()))
    times = np.linspace(t[0], t[-1], 1001)
    captured = np.maximum(0.0, -_site_heights(model, spline(t, q, times), edges))
    cleaned = -_site_heights(model, clean.frames.path(times), edges)
    assert (cleaned <= captured + PENETRATION_TOLERANCE + 1e-5).all(), (cleaned - captured).max()


def test_a_clean_searches_first_and_a_search_that_raises_nothing_ends_it(toy_model, dipped):
    """A clean seeks the least violation from the capture before any round; it can meet every limit of the dip, so it
    raises nothing and the clean ends on its path, with no round at all, which MuJoCo finds out of the floor within the
    penetration tolerance at 1001 times; with one round a frame set (per_level=1) the same."""
    t, q, disp, sol, _ = dipped
    for s in (sol, solve_displacement(disp, LeastChangeOptions(per_level=1))):
        assert s.estimate_kind == "search" and s.converged_to_tol and not s.certificate
        assert len(s.rounds) == 0 and s.n_evals > 0  # the search's evaluations, no round's
        assert max(s.integrals_final.values()) <= 1.0, s.integrals_final  # every c/tol, met at <= 1
        fine = np.linspace(t[0], t[-1], 1001)
        low = _lowest_site(toy_model, clean_solution(disp, s).frames.path(fine))
        assert low.min() >= -PENETRATION_TOLERANCE - 1e-5, low.min()


def test_a_clean_returns_the_least_change_among_the_paths_that_met_every_limit(dipped):
    """`kept_path` on a grid: of the last path and the best (least D) one that met every limit, the one of lower D;
    off a grid, or with a limit raised, the last, which met them. Both paths here are the dipped clean's (met), the
    best's D given either side of the last's."""
    from solver.least_change_end import kept_path

    _, _, disp, sol, _ = dipped
    al = disp.lc.al
    basis = SplineBasis(sol.frames.times, al.t)
    D = al.evaluate(basis, sol.frames.values, grad=False)[2]
    f = sol.frames
    other = FrameSet(f.times, f.values.copy(), f.fixed, f.is_keyframe)
    limits = [c.limit.copy() for c in al.constraints]
    kept, _, message, _ = kept_path(al, sol.frames, basis, (0.5 * D, other), "done", [], limits, grid=True)
    assert kept is other and "least change" in message
    kept, _, message, _ = kept_path(al, sol.frames, basis, (2.0 * D, other), "done", [], limits, grid=True)
    assert kept is sol.frames and message == "done"
    kept, _, message, _ = kept_path(al, sol.frames, basis, (0.5 * D, other), "done", [], limits, grid=False)
    assert kept is sol.frames and message == "done"
    # with a limit raised, the rounds that brought its pairs toward their least violation are kept (their D aside)
    raised = [Raise("penetration", "", 1e-3, 1.0, 1.0, 1.0, 1, "mm", 1e-3)]
    kept, _, message, _ = kept_path(al, sol.frames, basis, (0.5 * D, other), "done", raised, limits, grid=True)
    assert kept is sol.frames and message == "done"
