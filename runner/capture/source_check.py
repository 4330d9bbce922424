"""The way back checked on the file: a BVH written onto a clip's own skeleton (runner/capture/source_export.py)
read back and compared with the clip at the path's keyframes.

At a keyframe the path is the capture as the figure has it, so there the written file is the source's own
pose (docs/mocap.md, "Back onto the source skeleton") but where the import corrected the capture (the knee
and elbow hyperextension clamp, the footplant, the repair of tracking glitches) or a partial key leaves
joints to the path. The figures `export` prints and `mocap` prints and records are read from the written
file: parsed by bvhio (`runner.capture.bvh.read_bvh`), every joint's world position by the BVH forward
kinematics (`runner.capture.bvh_kinematics.file_world`), against the clip's, frame for frame. What the import
changed at each key (`corrections_at`) is what may move it; a key moved where it changed nothing is the way
back off there.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from runner.capture.bvh import BvhClip, read_bvh
from runner.capture.bvh_kinematics import file_world
from solver.errors import InputError

__all__ = ["ON_SOURCE", "ON_FRAME", "KeysOnSource", "corrections_at", "corrections_text", "keys_on_source"]

#: [m] a written joint this near the clip's own place at a keyframe is the clip's: far above what the file's
#: rounding moves a joint (6 decimals of a degree, 1.7e-8 rad: 3.5e-5 mm at 2 m from the root) and far
#: below an optical capture's marker jitter (1-5 mm), so a key beyond it was moved by a correction
ON_SOURCE = 1e-4
#: [frames] a time this near a frame's time is that frame's: saved times are rounded to a microsecond
#: (1.2e-4 of a 120 fps frame)
ON_FRAME = 1e-3


@dataclass(frozen=True)
class KeysOnSource:
    """How far every joint of a written file is from the source clip's own place at the keyframes.

    Attributes:
        times: (K,) [s] the keyframe times the file has a frame at (0 at the clip's first frame after its
            rest frames). distance: (K, J) [m] each joint's distance from its place in the clip.
        joints: the J joint names. missed: keyframes the file has no frame at (written at another rate).
        free: (K,) bool, a clean's keyframes that are the clip's free ends (the clean's to move, not held to
            the source: `lines`), or None (a keyed path: every keyframe held).
    """

    times: np.ndarray
    distance: np.ndarray
    joints: tuple[str, ...]
    missed: int = 0
    free: np.ndarray | None = None

    @property
    def moved(self) -> np.ndarray:
        """(K,) bool: the keys with a joint beyond `ON_SOURCE`."""
        return self.distance.max(axis=1, initial=0.0) > ON_SOURCE

    def worst(self) -> tuple[int, int]:
        """(key, joint) indices of the largest distance."""
        k, j = np.unravel_index(int(np.argmax(self.distance)), self.distance.shape)
        return int(k), int(j)

    def max_mm(self) -> float:
        """[mm] the largest distance (0 without keys)."""
        return 1000.0 * float(self.distance.max(initial=0.0))

    def summary(self, noun: str = "keys") -> str:
        """e.g. "every joint within 0.1 mm of the clip's at 6 of 12 keys; most RightLeg, 14.9 mm at 2.48 s"
        (`noun`: what the times are, "keys" or "pins")."""
        n = len(self.times)
        missed = f" ({self.missed} {noun} between the file's frames not checked)" if self.missed else ""
        if not n:
            return f"no {noun[:-1]} at a frame of the file{missed}"
        if not self.moved.any():
            every = f"all {n} {noun}" if n > 1 else f"the {noun[:-1]}"
            return f"every joint within {self.max_mm():.3f} mm of the clip's at {every}{missed}"
        k, j = self.worst()
        return (f"every joint within {1000 * ON_SOURCE:g} mm of the clip's at {n - int(self.moved.sum())} of {n} "
                f"{noun}; most {self.joints[j]}, {self.max_mm():.1f} mm at {self.times[k]:.2f} s{missed}")

    def lines(self) -> list[tuple[str, str]]:
        """The check as (what, figures) lines to print: a keyed path's keyframes (`summary`); a clean's pins,
        held to the source, and apart from them the clip's free ends, which the clean moves unless
        --pin-ends."""
        if self.free is None:
            return [("keyframes", self.summary())]
        out = [("pins", self.held().summary("pins"))] if (~self.free).any() else []
        ends = self.ends()
        if ends is not None and len(ends.times):
            k, j = ends.worst()
            out.append(("the clip's free ends", (
                f"moved by the clean, up to {ends.max_mm():.1f} mm ({ends.joints[j]} at {ends.times[k]:.2f} s); "
                "--pin-ends keeps them as captured") if ends.moved.any() else
                f"within {ends.max_mm():.3f} mm of the clip's"))
        return out

    def held(self) -> KeysOnSource:
        """The check at the keyframes held to the source alone (a clean's pins; every key of a keyed path)."""
        return self if self.free is None else self.at(~self.free)

    def ends(self) -> KeysOnSource | None:
        """The check at a clean's free ends alone (None for a keyed path)."""
        return None if self.free is None else self.at(self.free)

    def at(self, rows: np.ndarray) -> KeysOnSource:
        """The check at the keyframes `rows` ((K,) bool) alone (those between the file's frames counted with them)."""
        return KeysOnSource(self.times[rows], self.distance[rows], self.joints, self.missed if rows.any() else 0)


def keys_on_source(source: BvhClip, written: str | Path, rest: int, unit: float, key_times, start: float = 0.0,
                   fps: float | None = None, held=None) -> KeysOnSource:
    """Read a file written onto `source`'s skeleton back and measure it at the keyframes (module docstring).

    Args:
        source: the source clip. written: the file (the source's HIERARCHY, its `rest` leading rest frames,
            then frame rest + k at t = start + k / fps). unit: [m per file unit] (the recognised skeleton's).
        key_times: (K,) [s] keyframe times, 0 at the source's frame `rest`.
        start: [s] the time of the file's first frame after its rest frames. fps: [Hz] the file's rate
            (None: 1 / its frame time). held: a clean's pins [s], the keyframes held to the source (its other
            keyframes are the clip's free ends: `KeysOnSource.free`); None for a keyed path (every key held).
    Returns:
        KeysOnSource over the keys that fall on a frame of both files.
    Raises:
        InputError: the file cannot be read (`read_bvh`), or has other joints than the source.
    """
    out = read_bvh(written)
    if out.names != source.names:
        raise InputError(f"{written}: its joints are not those of {source.source}; it was not written onto that "
                         "clip's skeleton")
    fps = 1.0 / out.frame_time if fps is None else float(fps)
    t = np.asarray(key_times, float)
    f_src, f_out = t / source.frame_time, (t - start) * fps
    k_src, k_out = np.rint(f_src).astype(int), np.rint(f_out).astype(int)
    n_src, n_out = len(source.local_quat) - rest, len(out.local_quat) - rest
    ok = ((np.abs(f_src - k_src) < ON_FRAME) & (np.abs(f_out - k_out) < ON_FRAME) & (k_src >= 0) & (k_out >= 0)
          & (k_src < n_src) & (k_out < n_out))
    _, p_src = file_world(source)
    _, p_out = file_world(out)
    d = np.linalg.norm(p_out[rest + k_out[ok]] - p_src[rest + k_src[ok]], axis=-1) * unit
    free = None if held is None else ~np.isclose(  # [s] within a microsecond: saved times' rounding (`ON_FRAME`)
        t[ok][:, None], np.asarray(held, float).reshape(1, -1), rtol=0, atol=1e-6).any(axis=1)
    return KeysOnSource(t[ok], d, tuple(source.names), int((~ok).sum()), free)


def corrections_at(ref, keyframes, t: float) -> tuple[dict, dict, list, bool]:
    """What the import changed at the key at `t` [s] of a run's `Reference` (runner.capture.retarget) and its
    `Keyframes`: (clamped {knee or elbow: [deg] hyperextension removed},
    planted {foot or "root": [mm] lowered, `FootPlant.moved_at`}, the joints whose tracking glitch was repaired
    there, whether the key is partial); all empty and False where the key is the capture."""
    frame = int(np.clip(np.rint(t / ref.frame_time), 0, ref.count - 1))
    clamped = {name: round(float(a[frame]), 2) for name, a in (ref.clamped or {}).items() if a[frame] > 0}
    planted = {} if ref.plant is None else ref.plant.moved_at(frame)
    half = 0.5 * ref.frame_time  # a key's time is its frame's to the keyframe file's decimals (1.35 s for 1.3499946)
    glitched = [g.joint for g in ref.glitches if g.start - half <= t <= g.end + half]
    key = int(np.argmin(np.abs(keyframes.times - t)))
    return clamped, planted, glitched, bool(keyframes.is_partial[key])


def corrections_text(clamped: dict, planted: dict, glitched: list, partial: bool) -> str:
    """The import's corrections at a key, in words: `clamped` {joint: [deg]}, `planted` {foot or "root": [mm]
    lowered} (`runner.capture.foot_plant.FootPlant.moved_at`), the joints whose glitch was repaired there and
    whether the key is partial; "none at that key" without any."""
    feet = [f"{foot} foot lowered {mm:.1f} mm" for foot, mm in planted.items() if foot != "root"]
    root = [f"root lowered {planted['root']:.2f} mm by the footplant"] if "root" in planted else []
    return ", ".join([f"{n} {a:.1f} deg" for n, a in clamped.items()] + feet + root + [f"{g} glitch repaired" for g in glitched]
                     + (["a partial key"] if partial else [])) or "none at that key"
