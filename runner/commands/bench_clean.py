"""`dynsplines bench clean [CLIP.bvh ...]`: `dynsplines clean` and its peer, per-frame IK footskate cleanup
(`runner.bench.clean_peer`, mink), on the same clips, retargeted captures, contacts and scenes, measured by the
same code: penetration (1000 Hz), the soles' edges beyond the capture's depth, float and skate in contact (`runner.motion_metrics`), deviation from the
capture (body positions [cm], joint angles [deg]: mean / max) and the change's peak accelerations against the 6 Hz capture's (`runner.clean_metrics`), CPU
(`runner.bench.clean_measure`)."""
from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from runner.paths import MODELS

#: the clips `bench clean` runs without arguments: three shipped CMU walks and runs
DEFAULT_CLIPS = ("16_23", "127_33", "35_17")


def register(bsub) -> None:
    """Add `clean` to `dynsplines bench`."""
    p = bsub.add_parser("clean", help="dynsplines clean against per-frame IK footskate cleanup (mink) on the same clips")
    p.add_argument("clips", nargs="*", type=Path, help=f"BVH clips [models/cmu/{{{','.join(DEFAULT_CLIPS)}}}.bvh]")
    p.set_defaults(func=bench_clean)


def bench_clean(args) -> int:
    """Run both cleanups on each clip and print one row per clip and method. Returns 0."""
    from runner.bench.clean_measure import clean_figures_of, saved_capture
    from runner.bench.clean_peer import ik_clean
    from runner.clean import CleanOptions, process_clean

    clips = args.clips or [MODELS / "cmu" / f"{c}.bvh" for c in DEFAULT_CLIPS]
    head = (f"{'clip':10s} {'method':11s} {'pen mm':>7s} {'sole mm':>7s} {'float mm':>8s} {'skate mm/fr':>11s} {'dev mean cm':>11s} "
            f"{'dev max cm':>10s} {'angle deg':>11s} {'pelvis chg':>10s} {'joint chg':>9s} {'6 Hz peaks':>14s} {'CPU s':>6s}")
    print(head)
    with tempfile.TemporaryDirectory(prefix="dynsplines-bench-clean-") as tmp:
        for clip in clips:
            out = Path(tmp) / Path(clip).stem
            res = process_clean(clip, out, CleanOptions(render=False, quiet=True, summary=False), say=lambda *_: None)
            npz = Path(res["outputs"]["save_path"])
            z = np.load(npz)
            peer, peer_cpu = ik_clean(*saved_capture(npz))
            for name, qpos, cpu in (("capture", z["reference_qpos"], 0.0), ("dynsplines", z["path_qpos"], res["solve_cpu_s"]),
                                    ("IK (mink)", peer, peer_cpu)):
                f = clean_figures_of(npz, qpos)
                print(f"{Path(clip).stem:10s} {name:11s} {f['penetration_mm']:7.2f} {f['sole_mm']:7.2f} {f['float_mm']:8.2f} {f['skate_mm']:11.2f} "
                      f"{f['deviation_mean_cm']:11.2f} {f['deviation_max_cm']:10.2f} "
                      f"{f['angle_mean_deg']:5.2f}/{f['angle_max_deg']:<5.1f} {f['change_pelvis_m_s2']:10.2f} "
                      f"{f['change_joint_rad_s2']:9.1f} {f['capture_pelvis_m_s2']:6.1f}/{f['capture_joint_rad_s2']:<7.0f} {cpu:6.2f}")
    return 0
