"""Clips of kinds the defaults were not tuned on, against the checks of their kind:

* 143_17 (models/cmu/README.md): a walk up two steps onto a platform. The fitted scene has the floor
  and one box per level, none inside another, each within 1 cm of the feet that rest on it (measured
  in the capture's own coordinates, before the root correction); every contact names the surface
  under its site, the step included; the reference's root correction stays within its bound and
  changes by at most 30 mm between 120 Hz frames; the resting feet are within 15 mm of the surfaces
  or within the capture's own disagreement (its forward kinematics).
* 83_65: a jump with a full turn, keyed every 0.25 s: the plain spline keeps the capture's heading
  within 30 deg at every frame.

The independent references are the clip's own forward kinematics (`runner.capture.skeleton.skeleton_world`,
`runner.capture.source_export.root_correction`) and MuJoCo's kinematics of the reference.
"""
from pathlib import Path

import numpy as np
import pytest

from runner.capture.bvh import read_bvh
from runner.capture.root_height import (
    CONTACT_CLEARANCE,
    ROOT_CORRECTION_MAX,
    check_root_correction,
    feet_disagreement,
    worst_contact_distance,
)
from runner.capture.source_export import root_correction
from runner.capture.stance import capture_rest
from runner.pipeline import ClipKeys, write_clip_keyframes
from solver.contacts import contact_points
from solver.errors import InputError
from solver.surfaces import StaticSurfaces

CMU = Path(__file__).resolve().parents[3] / "models" / "cmu"


def _keyed(clip, tmp_path, every=0.25):
    out = tmp_path / f"{clip}.keyframes.json"
    return write_clip_keyframes(CMU / f"{clip}.bvh", out, ClipKeys(every=every), tmp_path / f"{clip}.scene.xml")


@pytest.fixture(scope="module")
def platform(tmp_path_factory):
    return _keyed("143_17", tmp_path_factory.mktemp("platform"))


def _correction(cs):
    """(n,) [m] the reference's root correction: its root minus the clip's own hips, taken back to the capture
    (its vertical: file axes and units to MuJoCo's, z up)."""
    ref, skel = cs.reference, cs.reference.skeleton
    c = root_correction(read_bvh(ref.source), skel, cs.model, (ref.times, ref.qpos), ref.times)
    return (c @ skel.axes.T)[:, 2] * skel.unit


def _runs(mask):
    """[(start, stop)] of the runs of True in a (n,) bool mask."""
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(int), 0]))
    return list(zip(edges[::2], edges[1::2]))


def test_two_steps_onto_a_platform_are_boxes_where_the_feet_rest(platform):
    cs, contacts, _ = platform
    boxes = cs.fitted.boxes
    assert len(boxes) == 2
    (ca, ha), (cb, hb) = boxes
    assert not np.all(np.abs(ca - cb) < ha + hb - 1e-9)     # no box inside another, nor overlapping
    assert abs((ca[2] + ha[2]) - (cb[2] + hb[2])) > 0.1       # two levels, a step apart
    ref, model = cs.reference, cs.model
    rest, low = capture_rest(model, ref.qpos, ref.frame_time)
    raw = low - _correction(cs)[:, None]                      # heights with the capture's own root
    for foot in range(2):
        for a, b in _runs(rest[:, foot]):
            assert abs(np.median(raw[a:b, foot])) <= 0.010, (foot, a, b, np.median(raw[a:b, foot]))
    surfaces = StaticSurfaces.from_model(model)
    for c in contacts:                                       # each contact on the surface under its site
        i = int(round((c.start + c.end) / 2 / ref.frame_time))
        p = contact_points(model, ref.qpos[i:i + 1], (c.site,))[0, 0]
        top = surfaces.box_tops_below(p)
        under = surfaces.names[1 + int(np.argmax(top))] if np.isfinite(top).any() else "floor"
        assert c.surface == under, (c, under)
    assert {c.surface for c in contacts} == {"floor", "box0", "box1"}


def test_the_platform_walks_root_correction_is_small_and_continuous(platform):
    cs, _, _ = platform
    c = _correction(cs)
    assert np.abs(c).max() <= ROOT_CORRECTION_MAX
    per_120hz = np.abs(np.diff(c)) / (120.0 * cs.reference.frame_time)
    assert per_120hz.max() <= 0.030
    d = feet_disagreement(cs.reference, cs.model)
    worst = worst_contact_distance(cs.reference, cs.model)
    print(f"root correction {1000 * c.min():.1f}..{1000 * c.max():.1f} mm, step {1000 * per_120hz.max():.1f} mm "
          f"per 1/120 s; resting feet {1000 * worst:.1f} mm, the capture's disagreement {1000 * d:.1f} mm")
    assert worst <= max(0.015, d + CONTACT_CLEARANCE + 0.001)   # 1 mm: the correction's smoothing


def test_feet_disagreement_from_the_source_is_the_references_own(platform):
    """The disagreement by the BVH's forward kinematics equals the one read off the reference (MuJoCo),
    where the root correction cancels between the two feet."""
    cs, _, _ = platform
    ref, model = cs.reference, cs.model
    rest, low = capture_rest(model, ref.qpos, ref.frame_time)
    gap = np.where(rest, low - low.min(axis=1, keepdims=True), 0.0)
    assert feet_disagreement(ref, model) == pytest.approx(gap.max(), abs=1e-6)


def test_a_full_turn_keyed_every_quarter_second_keeps_the_heading(tmp_path):
    from runner.capture.keyframe_selection import CaptureError

    cs, _, keyframes = _keyed("83_65", tmp_path)
    ref = cs.reference
    keys = np.rint(keyframes.times / ref.frame_time).astype(int)
    plain = CaptureError(cs.model, ref.times, ref.qpos).plain(keys)

    def heading(q):  # yaw of the pelvis' forward axis
        w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
        return np.arctan2(2 * (x * y + w * z), 1 - 2 * (y * y + z * z))

    turned = np.unwrap(heading(ref.qpos[:, 3:7]))
    assert np.degrees(turned[-1] - turned[0]) < -300      # the capture turns a full turn (clockwise)
    off = np.angle(np.exp(1j * (heading(plain[:, 3:7]) - heading(ref.qpos[:, 3:7]))))
    assert np.degrees(np.abs(off)).max() < 30.0


def test_a_root_correction_too_large_or_too_sudden_is_refused():
    check_root_correction(np.full(10, 0.02), 1 / 120, "clip.bvh")
    with pytest.raises(InputError, match=r"clip\.bvh: .*\+40 mm at t = 0\.025 s.*--scene"):
        check_root_correction(np.r_[0.0, 0.01, 0.01, 0.04, 0.01], 1 / 120, "clip.bvh")
    with pytest.raises(InputError, match=r"jumps 40 mm in 1/120 s at t = 0\.008 s"):
        check_root_correction(np.r_[-0.02, -0.02, 0.02, 0.02], 1 / 120, "clip.bvh")
    check_root_correction(np.r_[-0.02, 0.0, 0.02], 1 / 60, "clip.bvh")  # 20 mm per 1/60 s: 10 per 1/120 s
