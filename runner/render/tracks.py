"""Tracks (a label and dense qpos samples in time), the camera and its path, frame times, sizes."""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from solver.errors import InputError

VIDEO_SUFFIXES = (".mp4", ".mkv", ".mov")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


@dataclass(frozen=True, eq=False)
class Track:
    """One path to show as a panel: dense `qpos` samples in time, and a label.

    Attributes:
        label: panel caption, e.g. "plain spline" or "optimized".
        times: (n,) [s] strictly increasing sample times.
        qpos: (n, nq) MuJoCo `qpos` at those times (quaternions need not be unit).
        penetration: optional (n, s) [m] depth of each of `sites` inside a surface (>0 inside,
            <=0 outside), e.g. from the ground-penetration term (eq. 12). Where deeper than
            `PENETRATION_SHOWN` the site is circled in magenta and its body drawn magenta.
        sites: s site names, the columns of `penetration` (e.g. "l_heel", "l_toe", ...).
        planted: optional (n, s) bool: the contact schedule has site k planted at times[i];
            such a site is marked with a green dot while planted.

    Raises:
        InputError: shapes or values that do not fit (checked on construction; nq against the model
            in `render_tracks`).
    """

    label: str
    times: np.ndarray
    qpos: np.ndarray
    penetration: np.ndarray | None = None
    sites: tuple[str, ...] = ()
    planted: np.ndarray | None = None

    def __post_init__(self):
        times = np.asarray(self.times, dtype=float)
        qpos = np.asarray(self.qpos, dtype=float)
        name = f"track {self.label!r}"
        if times.ndim != 1 or times.size == 0:
            raise InputError(f"{name}: times must have shape (n,) with n >= 1; got shape {times.shape}")
        if qpos.ndim != 2 or qpos.shape[0] != times.size:
            raise InputError(
                f"{name}: qpos must have shape (n, nq) = ({times.size}, nq) to match times; "
                f"got shape {qpos.shape}")
        if not (np.all(np.isfinite(times)) and np.all(np.isfinite(qpos))):
            raise InputError(f"{name}: times and qpos must be finite (no NaN or inf)")
        if times.size > 1 and np.any(np.diff(times) <= 0):
            i = int(np.flatnonzero(np.diff(times) <= 0)[0])
            raise InputError(
                f"{name}: times must be strictly increasing; times[{i}] = {times[i]:g} s, "
                f"times[{i + 1}] = {times[i + 1]:g} s")
        sites = tuple(self.sites)
        penetration = self.penetration
        if penetration is not None:
            penetration = np.asarray(penetration, dtype=float)
            if penetration.ndim == 1:
                penetration = penetration[:, None]
            if penetration.shape != (times.size, len(sites)):
                raise InputError(
                    f"{name}: penetration must have shape (n, len(sites)) = ({times.size}, {len(sites)}); "
                    f"got shape {penetration.shape}")
        elif sites:
            raise InputError(f"{name}: sites are given but penetration is not")
        planted = self.planted
        if planted is not None:
            planted = np.asarray(planted, dtype=bool)
            if planted.shape != (times.size, len(sites)):
                raise InputError(f"{name}: planted must have shape (n, len(sites)) = ({times.size}, {len(sites)}); "
                                 f"got shape {planted.shape}")
            object.__setattr__(self, "planted", planted)
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "qpos", qpos)
        object.__setattr__(self, "penetration", penetration)
        object.__setattr__(self, "sites", sites)


@dataclass(frozen=True)
class Camera:
    """A free camera that follows the figure's root body (the pelvis), the same for every panel.

    Attributes:
        distance: [m] from the look-at point.
        azimuth: [deg] MuJoCo free-camera azimuth, relative to the direction of travel when `follow`
            (else to +x). -90 puts the camera on the left of the direction of travel (on +y for a
            figure running along +x), looking across it: a step is seen in profile and the figure moves
            from right to left on screen (+90: from its right, moving left to right).
        elevation: [deg], negative looks down.
        smoothing: [s] of motion time: the standard deviation of the Gaussian that smooths the
            root's path into the look-at path (removes the running bob). 0: no smoothing.
        height: [m] fixed look-at height; None follows the root's height (smoothed).
        follow: turn with the direction of travel: the heading of the root's horizontal velocity,
            smoothed over `HEADING_SMOOTHING` (a diagonal or curved run stays seen from its side).
            Where the root moves slower than `HEADING_MIN_SPEED` the heading is held; a path that
            never moves that fast takes the way the figure faces (its root body's mean x axis).
    """

    distance: float = 4.0
    azimuth: float = -90.0
    elevation: float = -12.0
    smoothing: float = 0.3
    height: float | None = None
    follow: bool = True


HEADING_SMOOTHING = 0.5
"""[s] of motion time: standard deviation of the Gaussian that smooths the root's horizontal velocity
before its heading turns the camera (a running stride sways the pelvis sideways every step)."""
HEADING_MIN_SPEED = 0.3
"""[m/s] below this (smoothed) horizontal root speed the direction of travel is not defined: held."""


@dataclass(frozen=True)
class RenderInfo:
    """What `render_tracks` wrote.

    Attributes:
        path: the video file.
        n_frames: number of video frames.
        video_time_s: [s] length of the video (n_frames / fps).
        wall_time_s: [s] time the call took.
        ms_per_panel: [ms] mean time to pose, render and read back one panel (excludes encoding).
        size: (width, height) [px] of the video.
        cpu_time_s: [s] CPU time of the call: this process (all its threads, the software
            renderer's included) and the ffmpeg encoder (NaN if unknown).
        threads: threads that drew the frames (`runner.render.parallel`).
    """

    path: Path
    n_frames: int
    video_time_s: float
    wall_time_s: float
    ms_per_panel: float
    size: tuple[int, int]
    cpu_time_s: float = math.nan
    threads: int = 1

    @property
    def fps(self) -> float:
        """[1/s] video frames rendered and encoded per second of wall time."""
        return self.n_frames / self.wall_time_s if self.wall_time_s > 0 else math.inf

    def summary(self) -> str:
        """One line for the command's output, e.g. "103 frames in 3.1 s, 33 fps, CPU 5.0 s"."""
        cpu = f", CPU {self.cpu_time_s:.1f} s" if math.isfinite(self.cpu_time_s) else ""
        return f"{self.n_frames} frames in {self.wall_time_s:.1f} s, {self.fps:.0f} fps{cpu}"


def parse_size(size) -> tuple[int, int]:
    """Read an image size: a "WxH" string (e.g. "960x540") or a (width, height) pair.

    Returns:
        (width, height) [px], positive integers.

    Raises:
        InputError: anything else, naming what was received.
    """
    if isinstance(size, str):
        parts = size.lower().replace("×", "x").split("x")
        try:
            if len(parts) != 2:
                raise ValueError
            w, h = (int(p.strip()) for p in parts)
        except ValueError:
            raise InputError(f"size must be WIDTHxHEIGHT in pixels, e.g. 960x540; got {size!r}") from None
    else:
        try:
            w, h = size
        except (TypeError, ValueError):
            raise InputError(
                f"size must be (width, height) in pixels, e.g. (960, 540); got {size!r}") from None
        if not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in (w, h)):
            raise InputError(f"size must be two integers (width, height) in pixels; got {size!r}")
        w, h = int(w), int(h)
    if w <= 0 or h <= 0:
        raise InputError(f"size must be positive, e.g. 960x540; got {w}x{h}")
    return w, h


def frame_times(t0: float, t1: float, fps: float, speed: float) -> np.ndarray:
    """Motion times of the video frames: from t0 to t1 in steps of speed / fps, the last one at t1.

    Args:
        t0, t1: [s] first and last motion time, t1 >= t0.
        fps: [1/s] video frame rate, > 0.
        speed: playback speed (motion seconds per video second), > 0; 0.5 is half speed.

    Returns:
        (n_frames,) [s]; n_frames = ceil((t1 - t0) * fps / speed) + 1.
    """
    dt = speed / fps
    n = int(math.ceil((t1 - t0) / dt - 1e-9)) + 1
    return np.minimum(t0 + dt * np.arange(n), t1)


def sample_track(track: Track, times: np.ndarray) -> np.ndarray:
    """The track's `qpos` at `times`, linearly interpolated between samples, held outside its range.

    Args:
        track: the path.
        times: (k,) [s].

    Returns:
        (k, nq) qpos (quaternions not renormalized; MuJoCo normalizes them in the kinematics).
    """
    return interpolate_samples(track.times, track.qpos, np.asarray(times, dtype=float))


def interpolate_samples(t: np.ndarray, y: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Piecewise-linear interpolation of rows y (n, d) given at t (n,) at times (k,), clamped ends."""
    if t.size == 1:
        return np.repeat(y, times.size, axis=0)
    tc = np.clip(times, t[0], t[-1])
    i = np.clip(np.searchsorted(t, tc, side="right") - 1, 0, t.size - 2)
    w = ((tc - t[i]) / (t[i + 1] - t[i]))[:, None]
    return (1.0 - w) * y[i] + w * y[i + 1]


def _smooth(x: np.ndarray, dt: float, sigma: float) -> np.ndarray:
    """Gaussian smoothing of a path x (n, 3) sampled every dt [s], sigma [s].

    The ends are padded by linear extrapolation (velocity averaged over about sigma), so a figure
    moving at constant speed stays centred at the start and end instead of the camera lagging.
    """
    n = x.shape[0]
    if sigma <= 0 or n < 3:
        return x.copy()
    r = int(math.ceil(3.0 * sigma / dt))
    m = max(1, min(n - 1, int(round(sigma / dt))))
    v0 = (x[m] - x[0]) / m
    v1 = (x[-1] - x[-1 - m]) / m
    steps = np.arange(1, r + 1)[:, None]
    padded = np.concatenate([x[0] - v0 * steps[::-1], x, x[-1] + v1 * steps])
    k = np.exp(-0.5 * (np.arange(-r, r + 1) * dt / sigma) ** 2)
    k /= k.sum()
    return np.stack([np.convolve(padded[:, j], k, mode="valid") for j in range(x.shape[1])], axis=1)


def root_body(model) -> int:
    """The body the camera follows: the one with the free joint (the pelvis), else the first body."""
    free = np.flatnonzero(model.jnt_type == mujoco.mjtJoint.mjJNT_FREE)
    if free.size:
        return int(model.jnt_bodyid[free[0]])
    return 1 if model.nbody > 1 else 0


def forward_direction(model, data, qpos) -> None:
    """Pose `data` at qpos: kinematics, centres of mass, cameras and lights (no collision, no dynamics)."""
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    mujoco.mj_camlight(model, data)


def root_positions(model, data, qposes: Sequence[np.ndarray]) -> np.ndarray:
    """(n, 3) [m] the root body's position averaged over the tracks, per frame (unsmoothed)."""
    return root_poses(model, data, qposes)[0]


def root_poses(model, data, qposes: Sequence[np.ndarray]) -> tuple[np.ndarray, float]:
    """The root body's path and the way the figure faces.

    Returns:
        positions: (n, 3) [m] the root body's position averaged over the tracks, per frame (unsmoothed).
        facing: [deg] from +x towards +y: the direction of the mean over all frames and tracks of the
            root body's x axis (the figure's forward axis) on the floor; 0 if that mean vanishes.
    """
    root = root_body(model)
    pos = np.zeros((qposes[0].shape[0], 3))
    forward = np.zeros(2)
    for q in qposes:
        for i in range(q.shape[0]):
            data.qpos[:] = q[i]
            mujoco.mj_kinematics(model, data)
            pos[i] += data.xpos[root]
            forward += data.xmat[root].reshape(3, 3)[:2, 0]
    facing = math.degrees(math.atan2(forward[1], forward[0])) if np.linalg.norm(forward) > 1e-9 else 0.0
    return pos / len(qposes), facing


def lookat_path(model, data, qposes: Sequence[np.ndarray], dt: float, camera: Camera,
                positions: np.ndarray | None = None) -> np.ndarray:
    """(n, 3) [m] look-at points: the root body's position averaged over the tracks, smoothed.

    Args:
        positions: `root_positions` if already computed."""
    pos = root_positions(model, data, qposes) if positions is None else positions
    pos = _smooth(pos, dt, camera.smoothing)
    if camera.height is not None:
        pos[:, 2] = camera.height
    return pos


def heading_path(positions: np.ndarray, dt: float, facing: float = 0.0) -> np.ndarray:
    """(n,) [deg] the direction of travel: the heading of the smoothed horizontal root velocity.

    Args:
        positions: (n, 3) [m] root positions per video frame. dt: [s] of motion time between frames.
        facing: [deg] the way the figure faces (`root_poses`), used when it never travels.
    Returns:
        degrees from +x towards +y, unwrapped (continuous); held where the smoothed speed is below
        HEADING_MIN_SPEED (the first valid heading before it; `facing` if the root never moves that
        fast: a sidestep or a jump in place is seen from the figure's own sides).
    """
    n = positions.shape[0]
    if n < 2:
        return np.full(n, float(facing))
    # the velocity of the smoothed path: its ends are padded along the mean velocity of the last
    # HEADING_SMOOTHING (`_smooth`), where padding the velocity itself would extrapolate a stride's sway
    v = np.gradient(_smooth(positions[:, :2], dt, HEADING_SMOOTHING), dt, axis=0)
    speed = np.linalg.norm(v, axis=1)
    valid = speed >= HEADING_MIN_SPEED
    if not valid.any():
        return np.full(n, float(facing))
    psi = np.unwrap(np.arctan2(v[:, 1], v[:, 0]))
    idx = np.where(valid, np.arange(n), -1)
    idx = np.maximum.accumulate(idx)  # the last valid sample at or before each frame
    idx[idx < 0] = int(np.flatnonzero(valid)[0])
    return np.degrees(psi[idx])


def azimuth_path(positions: np.ndarray, dt: float, camera: Camera, facing: float = 0.0) -> np.ndarray:
    """(n,) [deg] the camera azimuth per frame: `camera.azimuth`, relative to the direction of travel
    (`heading_path`, with the figure's `facing` [deg] for a figure that never travels) when
    `camera.follow`."""
    n = positions.shape[0]
    if not camera.follow:
        return np.full(n, float(camera.azimuth))
    return heading_path(positions, dt, facing) + camera.azimuth
