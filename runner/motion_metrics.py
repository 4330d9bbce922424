"""Metrics of a sampled motion against the reference it was made from (../shared/METRICS.md).

`motion_metrics(model, qpos, fps, reference_qpos, reference_contacts)` evaluates a path sampled at the
reference's frame rate. Positions come from MuJoCo kinematics (`mj_kinematics`: `site_xpos` of the
contact sites, `xquat` of the bodies), not from the objective's code, so the numbers check the solver
rather than repeat it. Heights are above the highest static surface under each site
(`StaticSurfaces.height_above`: floor planes and box tops of the scene model; a contact's
`surface` name is not used). Every plausibility
figure is computed for the reference too: capture is not perfect either (real data scores about
0.05 on the GMD skating ratio; guided-motion-diffusion issue #8).

Definitions (n frames at fps; sites l_heel, l_toe, r_heel, r_toe; h = height above the surface):

Accuracy against the reference
- joint_orientation_deg: per ball joint (and the root's free-joint quaternion, "root"), the
  geodesic angle 2 acos |<q, q_ref>| between the unit local quaternions, mean and max over frames.
- body_orientation_deg: the same for the bodies' world orientations (`xquat`), in the spirit of the
  LAFAN1 L2Q (global quaternions; we report an angle, not the L2 norm of the quaternion difference).
- root_position_cm: |root position - reference|, mean and max.
- site_position_cm: per contact site, |site position - reference|, mean and max.
- accel_error_m_s2: mean |second difference of positions - reference's| * fps^2, root and sites
  (WHAM's acceleration error, METRICS.md "Smoothness").
- flight_extra_s / flight_missed_s (`flight_mismatch`, ours): frames where the path is in flight and
  the reference is not / where the reference is and the path is not (flight as in flight_time_s),
  times 1/fps. Their difference is the difference of the two flight times; their sum is the flight
  phase error, which cannot cancel: a path whose flights are each too long but whose last one is
  missing can match the reference's flight time (35_17 keyed every 0.25 s: 0.358 s against 0.367 s,
  with 0.075 s extra and 0.083 s missed; docs/contacts.md "Motion metrics").

Plausibility (PhysDiff, Yuan et al. 2023, after UHC `smpl_eval.py`; on the four contact sites rather
than mesh vertices)
- penetration_mm: per frame max(0, -min over sites of h), mean over all frames and max. No 5 mm
  tolerance (the original has one); a retargeted reference holds planted sites 2 mm up.
- float_contact_mm: per foot and frame where the REFERENCE has a site of that foot in contact, the
  foot's lowest site height max(0, h) (what an animator calls a floating foot), mean over those
  (foot, frame) pairs. float_physdiff_mm: PhysDiff's all-frame variant, per frame the lowest site's
  h counted when above 5 mm (else 0), mean over all frames.
- float_stance_mm / float_stance_max_mm (with a `stance` mask): the same as float_contact_mm over
  the (foot, frame) pairs of the CAPTURE's own stance (`runner.capture.stance.capture_stance`: the
  foot's lowest site near its surface and nearly still, no minimum duration), mean and max: a
  foot the schedule leaves out of contact (a gap it counts as a flight) is still judged where the
  capture stood on it. flight_in_stance_s: frames in which the path is in flight (every site above
  FLIGHT_HEIGHT) while the capture has a foot in stance, times 1/fps (0 for the capture itself,
  whose stance never begins above FLIGHT_HEIGHT).
- skate_mm / skate_speed_m_s: PhysDiff skate: mean horizontal displacement between consecutive
  frames of sites on the ground (h <= SKATE_HEIGHT = 0.02 m) in both frames; as a speed (* fps).
  skate_contact_mm / skate_contact_speed_m_s: the same over the sites the REFERENCE has in contact in
  both frames (a planted site sliding).
- phys_err_mm: penetration mean + float_physdiff + skate (PhysDiff's Phys-Err).
- skating_ratio: Guided Motion Diffusion (`data_loaders/humanml/utils/metrics.py`): positions
  subsampled to about GMD_RATE = 20 fps (every round(fps / 20)-th frame; the rate used is reported as
  skating_ratio_rate_hz); a site is in contact in a step when h < 0.05 m at both ends; it skates
  when its horizontal speed over the step exceeds 0.5 m/s; the ratio is the fraction of steps in
  which any site skates (GMD uses the two foot joints and a 5-frame moving average; we use the four
  sites and no average). skating_ratio_full_rate: the same at fps. Caveat: the sites are on the
  sole, and a walking foot's toe clears the ground by only 1-3 cm in swing, so the 5 cm test counts
  swinging feet as "in contact" (16_23 scores 0.7); skating_ratio_contacts replaces the height test
  by the REFERENCE's contacts (a site planted at both ends of a step at fps moving > 0.5 m/s).
- flight_time_s: frames in which every site is clear (h > FLIGHT_HEIGHT = 0.03 m, the contact entry
  height `solver.contact_thresholds.FLIGHT_HEIGHT`) times 1/fps. Thresholds: below.
- jerk_root_m_s3 / jerk_sites_m_s3: third finite difference of positions * fps^3, mean norm (root
  position; all contact sites), METRICS.md "Smoothness".

Anatomy (`anatomy_figures`; the decomposition and the table: `solver.terms.anatomy_table`, docs/anatomy.md)
- off_hinge_deg: per knee and elbow, the largest rotation off its hinge over the frames (the swing angle
  of the joint quaternion about its flexion axis); off_hinge_knee_deg / off_hinge_elbow_deg: the larger
  of the two knees' / elbows'. The figure's elbow also carries the forearm's pronation and supination
  (the capture's elbows show tens of degrees off the hinge).
- rom_excess_deg: the largest angle by which any joint motion leaves the published range of motion
  (AAOS 1965, not widened to the keyframes as the rom term's is), and rom_excess_motion: which
  ("l_ankle dorsiflexion / plantarflexion"; "" when none does); rom_excess_deg_by_joint per joint.

Jolts (`runner.jolts.jolt_figures`: finite differences at fps, torques by `mj_inverse`)
- peak_pelvis_acceleration_m_s2, peak_angular_acceleration_rad_s2 (per ball joint; the largest:
  peak_angular_acceleration_max_rad_s2), rms_joint_torque_Nm, with the times of the peaks. The
  reference's are of the motion given as `capture_filtered` (the capture low-pass filtered at 6 Hz before
  it is differentiated, `runner.jolts.filter_capture`), else of the reference as given.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from solver.contact_thresholds import FLIGHT_HEIGHT
from solver.contacts import Contact, contact_mask, contact_radii, figure_sites, lowest_points
from solver.errors import InputError
from solver.figure import foot_sites
from solver.quaternion import angle_between

# -- the published metrics' own thresholds, as they define them (../shared/METRICS.md)
#: PhysDiff skate: a site is on the ground at most this high [m].
SKATE_HEIGHT = 0.02
#: PhysDiff float: the lowest site counts as floating above this height [m].
FLOAT_TOL = 0.005
#: Guided Motion Diffusion's skating ratio: a site is in contact below this height [m].
GMD_HEIGHT = 0.05
#: GMD skating speed [m/s] and frame rate [Hz].
GMD_SPEED = 0.5
GMD_RATE = 20.0


def _kinematics(model, qpos, sites):
    import mujoco

    data = mujoco.MjData(model)
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s) for s in sites]
    missing = [s for s, i in zip(sites, ids) if i < 0]
    if missing:
        raise InputError(f"the model has no site {missing[0]!r}; contact sites needed: {', '.join(sites)}")
    pos = np.empty((len(qpos), len(sites), 3))
    xquat = np.empty((len(qpos), model.nbody, 4))
    for i, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        pos[i] = data.site_xpos[ids]
        xquat[i] = data.xquat
    return pos, xquat


def _angle_deg(a, b):
    return np.degrees(angle_between(a, b))


def _stats(x, scale=1.0):
    x = np.asarray(x, float) * scale
    if x.size == 0:
        return {"mean": 0.0, "max": 0.0}
    return {"mean": float(x.mean()), "max": float(x.max())}


def _mean(x, scale=1.0):
    x = np.asarray(x, float)
    return float(x.mean() * scale) if x.size else 0.0


def _jerk(p, fps):
    if len(p) < 4:
        return 0.0
    j = np.diff(p, n=3, axis=0) * fps**3
    return float(np.linalg.norm(j, axis=-1).mean())


def _skating_ratio(pos, h, stride, rate):
    p, hh = pos[::stride], h[::stride]
    if len(p) < 2:
        return 0.0
    on = (hh[1:] < GMD_HEIGHT) & (hh[:-1] < GMD_HEIGHT)
    speed = np.linalg.norm(np.diff(p[..., :2], axis=0), axis=-1) * rate
    return float(((speed > GMD_SPEED) & on).any(axis=1).mean())


def flight_mismatch(h: np.ndarray, reference_h: np.ndarray, fps: float) -> tuple[float, float]:
    """(extra, missed) [s]: time the path is in flight while the reference is not, and the reverse.

    A frame is in flight when every site is above FLIGHT_HEIGHT (as `flight_time_s`).

    Args:
        h, reference_h: (n, s) site heights above the surface [m] of the path and of the reference, at
            the same n frames. fps: [Hz] > 0.
    Returns:
        (extra, missed), each frames / fps [s].
    Raises:
        InputError: the shapes differ.
    """
    h, reference_h = np.asarray(h, float), np.asarray(reference_h, float)
    if h.shape != reference_h.shape or h.ndim != 2:
        raise InputError(f"heights {h.shape} and reference heights {reference_h.shape} must both be (n, sites)")
    path, ref = (h > FLIGHT_HEIGHT).all(axis=1), (reference_h > FLIGHT_HEIGHT).all(axis=1)
    return float((path & ~ref).sum() / fps), float((ref & ~path).sum() / fps)


def _foot_columns(feet: Mapping[str, Sequence[str]]) -> list[list[int]]:
    """Per foot, the columns of its sites in `foot_sites(feet)` (the figure's sites, foot by foot)."""
    sizes = np.cumsum([0] + [len(members) for members in feet.values()])
    return [list(range(a, b)) for a, b in zip(sizes[:-1], sizes[1:])]


def _foot_floats(h: np.ndarray, on: np.ndarray, feet: Mapping[str, Sequence[str]]) -> np.ndarray:
    """max(0, lowest site height) [m] of each foot (`feet`, the columns of `h` their sites) in the frames
    where on[:, f] holds, all feet's values concatenated. on: (n, feet) bool."""
    floats = [np.maximum(0.0, h[on[:, f]][:, ks].min(axis=1)) for f, ks in enumerate(_foot_columns(feet))]
    return np.concatenate(floats) if floats else np.zeros(0)


def _feet_mask(ref_mask: np.ndarray, feet: Mapping[str, Sequence[str]]) -> np.ndarray:
    """(n, feet) bool: a foot in contact when any of its sites is (ref_mask (n, s), columns `foot_sites(feet)`)."""
    return np.stack([ref_mask[:, ks].any(axis=1) for ks in _foot_columns(feet)], axis=1)


def plausibility(pos: np.ndarray, h: np.ndarray, fps: float, root: np.ndarray, ref_mask: np.ndarray,
                 feet: Mapping[str, Sequence[str]], stance: np.ndarray | None = None) -> dict:
    """The plausibility figures of the module docstring for one motion.

    Args:
        pos: (n, s, 3) site positions [m]. h: (n, s) heights above the surface [m]. fps: [Hz].
        root: (n, 3) root positions [m]. ref_mask: (n, s) bool, the reference's contacts.
        feet: {foot: its sites}, the figure's (`Figure.feet`); the s columns are their sites, foot by foot.
        stance: (n, feet) bool, the capture's stance per foot in `feet` order (left, right);
            None: no float_stance / flight_in_stance figures.
    Returns:
        a dict of floats (JSON-serializable).
    """
    n = len(pos)
    lowest = h.min(axis=1)
    pen = np.maximum(0.0, -lowest)
    float_contact = _foot_floats(h, _feet_mask(ref_mask, feet), feet)
    float_all = np.where(lowest > FLOAT_TOL, lowest, 0.0)
    disp = np.linalg.norm(np.diff(pos[..., :2], axis=0), axis=-1)  # (n-1, s)
    ground = (h[1:] <= SKATE_HEIGHT) & (h[:-1] <= SKATE_HEIGHT)
    planted = ref_mask[1:] & ref_mask[:-1]
    stride = max(1, int(round(fps / GMD_RATE)))
    out = {
        "penetration_mm": _stats(pen, 1e3),
        "float_contact_mm": _mean(float_contact, 1e3),
        "float_physdiff_mm": _mean(float_all, 1e3),
        "skate_mm": _mean(disp[ground], 1e3),
        "skate_speed_m_s": _mean(disp[ground], fps),
        "skate_contact_mm": _mean(disp[planted], 1e3),
        "skate_contact_speed_m_s": _mean(disp[planted], fps),
        "skating_ratio": _skating_ratio(pos, h, stride, fps / stride),
        "skating_ratio_rate_hz": fps / stride,
        "skating_ratio_full_rate": _skating_ratio(pos, h, 1, fps),
        "skating_ratio_contacts": float(((disp * fps > GMD_SPEED) & planted).any(axis=1).mean()) if n > 1 else 0.0,
        "flight_time_s": float((h > FLIGHT_HEIGHT).all(axis=1).sum() / fps) if n else 0.0,
        "jerk_root_m_s3": _jerk(root, fps),
        "jerk_sites_m_s3": float(np.mean([_jerk(pos[:, k], fps) for k in range(pos.shape[1])])),
    }
    if stance is not None:
        stance = np.asarray(stance, bool)
        float_stance = _foot_floats(h, stance, feet)
        out["float_stance_mm"] = _mean(float_stance, 1e3)
        out["float_stance_max_mm"] = float(float_stance.max() * 1e3) if float_stance.size else 0.0
        out["flight_in_stance_s"] = float(((h > FLIGHT_HEIGHT).all(axis=1) & stance.any(axis=1)).sum() / fps)
    out["phys_err_mm"] = out["penetration_mm"]["mean"] + out["float_physdiff_mm"] + out["skate_mm"]
    return out


def anatomy_figures(model, qpos: np.ndarray) -> dict:
    """The anatomy figures of the module docstring for one motion.

    Args:
        model: an MjModel with the figure (its flexion axes, `Figure.flexion_axes`). qpos: (n, nq) the
            motion (quaternions of any norm: the angles are scale-invariant).
    Returns:
        a dict of floats and strings (JSON-serializable); the knee / elbow figure is NaN for a figure
        without flexion axes on joints of that kind.
    """
    from solver.figure import Figure
    from solver.layout import StateLayout
    from solver.terms.anatomy_table import FIGURE_JOINTS, motion_angles, off_hinge_angles, range_of_motion

    qpos = np.atleast_2d(np.asarray(qpos, float))
    figure, layout = Figure.from_model(model), StateLayout.from_model(model)
    names = list(figure.flexion_axes)
    idx = np.array([layout.joint(n).quat_index for n in names], int).reshape(-1, 4)
    off = np.degrees(off_hinge_angles(qpos, idx, np.array([figure.flexion_axes[n] for n in names]).reshape(-1, 3)))
    off = off.max(axis=0) if len(qpos) else np.zeros(len(names))
    out = {"off_hinge_deg": {n: float(v) for n, v in zip(names, off)}}
    for kind in ("knee", "elbow"):
        vals = [v for n, v in zip(names, off) if FIGURE_JOINTS.get(n, ("", 0))[0] == kind]
        out[f"off_hinge_{kind}_deg"] = float(max(vals)) if vals else float("nan")
    motions = range_of_motion(figure)
    midx = np.array([layout.joint(m.joint).quat_index for m in motions], int).reshape(-1, 4)
    x = motion_angles(qpos, midx, motions)
    lo, hi = np.array([m.lo for m in motions]), np.array([m.hi for m in motions])
    excess = np.degrees(np.abs(x - np.clip(x, lo, hi))).max(axis=0) if len(qpos) else np.zeros(len(motions))
    k = int(np.argmax(excess)) if len(motions) else -1
    out["rom_excess_deg"] = float(excess[k]) if k >= 0 else 0.0
    out["rom_excess_motion"] = f"{motions[k].joint} {motions[k].motion}" if k >= 0 and excess[k] > 0 else ""
    out["rom_excess_deg_by_joint"] = {m.joint: float(max(e for mm, e in zip(motions, excess) if mm.joint == m.joint))
                                      for m in motions}
    return out


def _orientation_errors(model, qpos, ref, xq, rxq) -> dict:
    """{"joint_orientation_deg": per ball or free joint, "body_orientation_deg": per body}: the `_stats` of
    the angle [deg] between the path's and the reference's rotation at every frame (`motion_metrics`).

    Args:
        model: MjModel. qpos, ref: (n, nq) the path and the reference. xq, rxq: (n, nbody, 4) their
            bodies' world quaternions (`_kinematics`).
    """
    import mujoco

    joints = {}
    for j in range(model.njnt):
        t = int(model.jnt_type[j])
        if t not in (int(mujoco.mjtJoint.mjJNT_BALL), int(mujoco.mjtJoint.mjJNT_FREE)):
            continue
        a = int(model.jnt_qposadr[j]) + (3 if t == int(mujoco.mjtJoint.mjJNT_FREE) else 0)
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) or f"joint{j}"
        joints[name] = _stats(_angle_deg(qpos[:, a:a + 4], ref[:, a:a + 4]))
    bodies = {}
    for b in range(1, model.nbody):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}"
        bodies[name] = _stats(_angle_deg(xq[:, b], rxq[:, b]))
    return {"joint_orientation_deg": joints, "body_orientation_deg": bodies}


def motion_metrics(model, qpos: np.ndarray, fps: float, reference_qpos: np.ndarray,
                   reference_contacts: Sequence[Contact], stance: np.ndarray | None = None, capture_filtered: np.ndarray | None = None) -> dict:
    """Accuracy of a path against the reference, and the plausibility of both (module docstring).

    Args:
        model: the scene's MjModel (figure with the contact sites, static surfaces).
        qpos: (n, nq) the path sampled at the reference's frames (times i / fps).
        fps: [Hz] frame rate, > 0. reference_qpos: (n, nq) the reference motion.
        reference_contacts: the reference's contacts (times in [s] from frame 0).
        stance: (n, 2) bool, the reference's own stance per foot (left, right; e.g.
            `runner.capture.stance.capture_stance`); None: no stance figures.
        capture_filtered: (n, nq) the reference low-pass filtered (`runner.jolts.filter_capture`, over the
            whole clip and cut to these frames), the motion of the reference's jolt figures; None: the
            reference as given.
    Returns:
        JSON-serializable dict: {"fps", "frames", "sites", "error": {...}, "path": {...},
        "reference": {...}}; "path" and "reference" hold `plausibility`, `anatomy_figures` and
        `runner.jolts.jolt_figures` figures (no jolt figures for fewer than 3 frames).
    Raises:
        InputError: shapes disagree, fps not positive, a site missing in the model, no floor plane.
    """
    from solver.figure import model_feet
    from solver.surfaces import StaticSurfaces

    feet = model_feet(model)  # the figure's contact sites, foot by foot
    sites = foot_sites(feet)
    qpos = np.atleast_2d(np.asarray(qpos, float))
    ref = np.atleast_2d(np.asarray(reference_qpos, float))
    if qpos.shape != ref.shape or qpos.shape[1] != model.nq:
        raise InputError(f"qpos {qpos.shape} and reference_qpos {ref.shape} must both be (n, nq={model.nq})")
    if not (fps > 0):
        raise InputError(f"fps must be positive; got {fps!r}")
    n = len(qpos)
    times = np.arange(n) / fps
    surfaces = StaticSurfaces.from_model(model)
    if not np.any(np.abs(surfaces.plane_normal[:, 2]) > 1e-6):
        raise InputError("the model has no floor plane; motion metrics measure heights above the scene's "
                         "surfaces (add a plane, e.g. scene_fit.scene_mjcf)")
    pos, xq = _kinematics(model, qpos, sites)
    rpos, rxq = _kinematics(model, ref, sites)
    radii = contact_radii(model, sites)  # a rounded site is measured at its sphere's bottom
    pos, rpos = lowest_points(pos, radii), lowest_points(rpos, radii)
    h = surfaces.height_above(pos)
    rh = surfaces.height_above(rpos)
    mask = contact_mask(reference_contacts, sites, times)
    smooth = ref if capture_filtered is None else np.atleast_2d(np.asarray(capture_filtered, float))
    if smooth.shape != ref.shape:
        raise InputError(f"capture_filtered {smooth.shape} must be shaped as reference_qpos {ref.shape}")
    if stance is not None and np.shape(stance) != (n, len(feet)):
        raise InputError(f"stance has shape {np.shape(stance)}; give one column per foot, (n, {len(feet)}) "
                         f"with n = {n} frames")

    def acc(p):
        return np.diff(p, n=2, axis=0) * fps**2 if len(p) >= 3 else np.zeros((0,) + p.shape[1:])

    error = {
        **_orientation_errors(model, qpos, ref, xq, rxq),
        "root_position_cm": _stats(np.linalg.norm(qpos[:, :3] - ref[:, :3], axis=1), 100.0),
        "site_position_cm": {s: _stats(np.linalg.norm(pos[:, k] - rpos[:, k], axis=1), 100.0)
                             for k, s in enumerate(sites)},
        "accel_error_root_m_s2": _mean(np.linalg.norm(acc(qpos[:, :3]) - acc(ref[:, :3]), axis=-1)),
        "accel_error_sites_m_s2": _mean(np.linalg.norm(acc(pos) - acc(rpos), axis=-1)),
    }
    error["flight_extra_s"], error["flight_missed_s"] = flight_mismatch(h, rh, fps)
    return {
        "fps": float(fps),
        "frames": int(n),
        "sites": list(sites),
        "error": error,
        "path": {**plausibility(pos, h, fps, qpos[:, :3], mask, feet, stance), **anatomy_figures(model, qpos),
                 **_jolts(model, qpos, fps)},
        "reference": {**plausibility(rpos, rh, fps, ref[:, :3], mask, feet, stance), **anatomy_figures(model, ref),
                      **_jolts(model, smooth, fps)},
    }


def _jolts(model, qpos: np.ndarray, fps: float) -> dict:
    """`runner.jolts.jolt_figures` of (n, nq) frames, {} for fewer than 3."""
    from runner.jolts import jolt_figures

    return jolt_figures(model, qpos, fps) if len(qpos) >= 3 else {}


def forced_skate_mm(model, key_times: np.ndarray, key_qpos: np.ndarray, fps: float, contacts: Sequence[Contact],
                    frames: int, sites: Sequence[str] | None = None) -> float:
    """[mm/frame] A lower bound on `skate_contact_mm` that every path through the keyframes has.

    `skate_contact_mm` is the mean, over the (frame step, site) pairs in contact at both ends, of the
    site's horizontal displacement in the step. Inside one run of such steps the site passes through its
    positions at the keyframes that fall on the run's frames, so by the triangle inequality its summed
    displacement is at least the summed horizontal distance between consecutive keyed positions; the
    bound is that sum over every site and run, over the number of (step, site) pairs in contact. It
    holds for any path, optimized or not: a skate limit below it cannot be met without moving a keyframe.

    Args:
        model: MjModel with the contact sites. key_times: (k,) [s] on the metrics' clock (frame i at
            i / fps). key_qpos: (k, nq) the keyframes, every component fixed (pass only full keyframes:
            a partial one does not fix its sites). fps: [Hz] the metrics' frame rate, > 0.
        contacts: the contacts the skate figure is measured on (times [s] on the same clock).
        frames: n, the metrics' frame count. sites: contact site names (default the model's figure's,
            `solver.contacts.figure_sites`).
    Returns:
        the bound [mm per frame]; 0 when no step is in contact or no two keys share a run. Keys more
        than 1e-4 s from a frame time are left out (a subset of the keys still gives a lower bound).
    Raises:
        InputError: a contact or site the model does not have.
    """
    sites = figure_sites(model, sites)
    times = np.arange(int(frames)) / float(fps)
    mask = contact_mask(contacts, sites, times)
    planted = mask[1:] & mask[:-1]  # (n-1, s)
    if not planted.any() or len(key_times) < 2:
        return 0.0
    idx = np.rint(np.asarray(key_times, float) * fps).astype(int)
    on = (np.abs(idx / fps - key_times) < 1e-4) & (idx >= 0) & (idx < len(times))
    pos = _kinematics(model, np.asarray(key_qpos, float)[on], sites)[0][..., :2]  # (k', s, 2)
    idx = idx[on]
    order = np.argsort(idx, kind="stable")
    idx, pos = idx[order], pos[order]
    # run r of site k: a maximal block of contact steps; its frames a..b share one label
    step = np.vstack([np.zeros((1, len(sites)), bool), planted])  # step[i]: step i-1 -> i in contact
    run = np.cumsum(~step, axis=0)  # frames a..b of one run share a label; a frame outside runs has its own
    lab = run[idx]  # (k', s)
    same = lab[1:] == lab[:-1]  # consecutive keys in one run of the site
    return 1e3 * float(np.linalg.norm(np.diff(pos, axis=0), axis=-1)[same].sum()) / planted.sum()
