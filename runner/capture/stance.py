"""The capture's own stance: when each foot of a motion rests on a surface, judged on the motion itself.

A contact schedule (`runner.capture.contact_detection.reference_contacts`, or the contacts of a keyframe file) is a
labelling with its own purposes (per site, for the planted and clearance terms). The stance here is
what it is judged against (docs/contacts.md "Contact schedules"):

    a foot rests on a surface in frame i while its lowest contact site (heel or toe, the one nearest
    the surface under it, `solver.surfaces.StaticSurfaces.height_above`; of a rounded site the lowest
    point of its sphere, `solver.contacts.contact_points`) is near that surface and nearly still;

with hysteresis, per foot: the foot enters stance when the lowest site is below DETECT_HEIGHT_ON
(3 cm, the flight height: a stance never begins in a frame the flight metric counts as airborne) and
moves slower than DETECT_SPEED_ON (0.5 m/s, 3-D speed by central differences); it stays while the
lowest site is at most DETECT_HEIGHT_OFF (5 cm, Guided Motion Diffusion's foot-contact height) and
at most DETECT_SPEED_OFF (1.0 m/s) fast. The speeds are the kinematic gait-event rules validated
against pressure insoles (Ghoussayni et al. 2004, Gait & Posture 20:266-272; Bonci et al. 2022,
Front. Bioeng. Biotechnol. 10:868928: 3-D heel or forefoot speed under 0.5 m/s at initial contact,
forefoot speed over 1.0 m/s at final contact). There is NO minimum duration: a 10-40 ms touch-down
of a hop is a stance. Heights are above the scene's surfaces (a fitted scene for `--scene auto`):
where the fitted surface is off the captured floor by more than a few cm, the stance is judged
against the fitted surface as it is.

`stance_agreement` scores a schedule against it: recall (the capture's stance frames the schedule
has in contact) and precision (the schedule's contact frames that are stance frames), per foot and
over both feet.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from runner.capture.contact_detection import DETECT_HEIGHT_OFF, DETECT_HEIGHT_ON, DETECT_SPEED_OFF, DETECT_SPEED_ON, site_speeds
from solver.contacts import contact_mask, contact_points, site_heights
from solver.errors import InputError
from solver.figure import foot_sites


def _hysteresis(enter: np.ndarray, stay: np.ndarray) -> np.ndarray:
    """(n,) bool: on from a frame where `enter` holds through the frames where `stay` holds."""
    out = np.zeros(len(enter), bool)
    on = False
    for i in range(len(enter)):
        on = bool(stay[i]) if on else bool(enter[i])
        out[i] = on
    return out


def _columns(feet: Mapping[str, Sequence[str]], sites: Sequence[str]) -> list[list[int]]:
    sites = list(sites)
    out = []
    for foot, members in feet.items():
        missing = [s for s in members if s not in sites]
        if missing or not members:
            raise InputError(f"foot {foot!r}: site {missing[0] if missing else None!r} is not one of the "
                             f"contact sites {', '.join(sites)}; give each foot's sites from that list")
        out.append([sites.index(s) for s in members])
    return out


def stance_mask(times: np.ndarray, site_pos: np.ndarray, heights: np.ndarray,
                feet: Mapping[str, Sequence[str]], sites: Sequence[str],
                height_on: float = DETECT_HEIGHT_ON, height_off: float = DETECT_HEIGHT_OFF,
                speed_on: float = DETECT_SPEED_ON, speed_off: float = DETECT_SPEED_OFF) -> np.ndarray:
    """Per frame and foot, whether the foot rests on a surface (the module docstring's definition).

    Args:
        times: (n,) frame times [s], strictly increasing.
        site_pos: (n, s, 3) contact-site positions [m] (world, z up).
        heights: (n, s) height [m] of each site above the surface under it (negative: below).
        feet: {foot: its site names}, in column order of the result (the figure's, `Figure.feet`).
        sites: the s site names of the second axis.
        height_on <= height_off [m], speed_on <= speed_off [m/s]: the hysteresis thresholds.
    Returns:
        (n, f) bool, f = len(feet).
    Raises:
        InputError: shapes disagree, times not increasing, thresholds out of order, a foot names a
            site not in `sites`.
    """
    times, site_pos, heights = (np.asarray(a, float) for a in (times, site_pos, heights))
    n = len(times)
    if times.ndim != 1 or n < 1 or (n > 1 and not np.all(np.diff(times) > 0)):
        raise InputError(f"times must be a non-empty, strictly increasing (n,) array; got shape {times.shape}")
    if site_pos.shape != (n, len(sites), 3) or heights.shape != (n, len(sites)):
        raise InputError(f"site_pos {site_pos.shape} and heights {heights.shape} must be (n, s, 3) and (n, s) "
                         f"with n = {n} frames, s = {len(sites)} sites")
    if not (height_on <= height_off and speed_on <= speed_off):
        raise InputError(f"stance thresholds need height_on <= height_off and speed_on <= speed_off; got "
                         f"height {height_on}/{height_off} m, speed {speed_on}/{speed_off} m/s")
    h, v = lowest_sites(times, site_pos, heights, feet, sites)
    out = np.zeros(h.shape, bool)
    for f in range(h.shape[1]):
        out[:, f] = _hysteresis((h[:, f] < height_on) & (v[:, f] < speed_on), (h[:, f] <= height_off) & (v[:, f] <= speed_off))
    return out


def lowest_sites(times: np.ndarray, site_pos: np.ndarray, heights: np.ndarray,
                 feet: Mapping[str, Sequence[str]], sites: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Per frame and foot, the height [m] above the surface under it and the 3-D speed [m/s] (central
    differences) of the foot's lowest contact site: (n, f) and (n, f), arguments as `stance_mask`."""
    speed = site_speeds(times, site_pos)
    rows = np.arange(len(times))
    h, v = np.empty((len(times), len(feet))), np.empty((len(times), len(feet)))
    for f, ks in enumerate(_columns(feet, sites)):
        low = np.argmin(heights[:, ks], axis=1)  # the foot's lowest site in each frame
        h[:, f], v[:, f] = heights[:, ks][rows, low], speed[:, ks][rows, low]
    return h, v


def resting(stance: np.ndarray, lowest: np.ndarray, speed: np.ndarray, height_on: float = DETECT_HEIGHT_ON,
            speed_on: float = DETECT_SPEED_ON) -> np.ndarray:
    """The frames of a stance in which the foot rests by the stance's own entry condition: (n, f) bool.

    The hysteresis of `stance_mask` keeps a foot in stance while it rolls off its toes and lifts (up to
    DETECT_HEIGHT_OFF, 5 cm, and DETECT_SPEED_OFF, 1 m/s), so that a detection does not flicker; those
    frames are the stance's way out, not a foot resting. A foot rests in a frame of its stance where its
    lowest site is below `height_on` [m] and slower than `speed_on` [m/s], the condition a stance begins
    with (module docstring). `lowest`, `speed`: (n, f) from `lowest_sites`.
    """
    return np.asarray(stance, bool) & (lowest < height_on) & (speed < speed_on)


def _foot_motion(model, qpos, frame_time: float):
    """(figure, times (n,) [s], contact points (n, k, 3) [m], their heights above the surfaces (n, k)
    [m]) of a motion sampled every frame_time; raises InputError when frame_time is not > 0."""
    from solver.figure import Figure

    if not (np.isfinite(frame_time) and frame_time > 0):
        raise InputError(f"frame_time is {frame_time!r}; give the time between frames in seconds (> 0)")
    figure = Figure.from_model(model)
    qpos = np.atleast_2d(np.asarray(qpos, float))
    pos = contact_points(model, qpos, figure.contact_sites)
    times = np.arange(len(qpos)) * float(frame_time)
    return figure, times, pos, site_heights(model, pos)


def capture_stance(model, qpos: np.ndarray, frame_time: float, **thresholds) -> np.ndarray:
    """The stance of a motion in its scene (`stance_mask`; sites and feet of the model's figure).

    Args:
        model: the scene's MjModel (the figure with its feet annotated, and static surfaces).
        qpos: (n, nq) the motion (e.g. a retargeted capture, `Reference.qpos`), one row per frame.
        frame_time: [s] > 0 between frames.
        thresholds: height_on, height_off [m], speed_on, speed_off [m/s] of `stance_mask`.
    Returns:
        (n, f) bool, the feet in the order of `Figure.from_model(model).feet` (left, right).
    Raises:
        InputError: the figure has no feet or lacks a site, frame_time not > 0, bad thresholds.
    """
    figure, times, pos, heights = _foot_motion(model, qpos, frame_time)
    return stance_mask(times, pos, heights, figure.feet, figure.contact_sites, **thresholds)


def capture_rest(model, qpos: np.ndarray, frame_time: float) -> tuple[np.ndarray, np.ndarray]:
    """The frames in which each foot of a motion rests on a surface (`resting` within `capture_stance`),
    and the height of its lowest contact site above the surface under it.

    Args: as `capture_stance` (default thresholds).
    Returns:
        rest: (n, f) bool. lowest: (n, f) [m] (negative: below the surface). Feet as `capture_stance`.
    Raises:
        InputError: as `capture_stance`.
    """
    figure, times, pos, heights = _foot_motion(model, qpos, frame_time)
    stance = stance_mask(times, pos, heights, figure.feet, figure.contact_sites)
    low, speed = lowest_sites(times, pos, heights, figure.feet, figure.contact_sites)
    return resting(stance, low, speed), low


def schedule_stance(contacts, times: np.ndarray, feet: Mapping[str, Sequence[str]]) -> np.ndarray:
    """Per frame and foot, whether a contact schedule has the foot on a surface (any of its sites in a
    contact, closed intervals: `solver.contacts.contact_mask`).

    Args:
        contacts: `Contact`s or a `ContactSchedule`. times: (n,) [s] frame times.
        feet: {foot: its site names}, the columns of the result.
    Returns:
        (n, f) bool.
    Raises:
        InputError: a contact names a site no foot has.
    """
    sites = foot_sites(feet)
    mask = contact_mask(list(contacts), sites, np.asarray(times, float))
    return np.stack([mask[:, ks].any(axis=1) for ks in _columns(feet, sites)], axis=1)


@dataclass(frozen=True)
class StanceAgreement:
    """How a schedule's contact frames agree with the capture's stance frames.

    Attributes:
        recall: stance frames (foot, frame pairs) the schedule has in contact / all stance frames
            (1.0 when the capture has none).
        precision: the schedule's contact frames that are stance frames / all its contact frames (1.0
            when the schedule has none).
        feet: per foot (columns of the masks), (recall, precision).
        stance_frames, schedule_frames: the (foot, frame) pairs in stance / in contact.
    """

    recall: float
    precision: float
    feet: tuple[tuple[float, float], ...]
    stance_frames: int
    schedule_frames: int


def _ratio(hit: int, total: int) -> float:
    return float(hit) / total if total else 1.0


def stance_agreement(schedule_mask: np.ndarray, capture_mask: np.ndarray) -> StanceAgreement:
    """Recall and precision of a schedule's contact frames against the capture's stance frames.

    Args:
        schedule_mask: (n,) or (n, f) bool, e.g. `schedule_stance(contacts, times)`.
        capture_mask: the same shape, e.g. `capture_stance(model, qpos, frame_time)`.
    Returns:
        StanceAgreement (overall over all (foot, frame) pairs, and per foot).
    Raises:
        InputError: the shapes differ.
    """
    s, c = np.asarray(schedule_mask, bool), np.asarray(capture_mask, bool)
    if s.shape != c.shape or s.ndim not in (1, 2):
        raise InputError(f"schedule mask {s.shape} and capture mask {c.shape} must have the same (n,) or (n, feet) shape")
    s, c = s.reshape(len(s), -1), c.reshape(len(c), -1)
    both = s & c
    feet = tuple((_ratio(both[:, f].sum(), c[:, f].sum()), _ratio(both[:, f].sum(), s[:, f].sum()))
                 for f in range(s.shape[1]))
    return StanceAgreement(_ratio(both.sum(), c.sum()), _ratio(both.sum(), s.sum()), feet, int(c.sum()), int(s.sum()))


def schedule_agreement(model, qpos: np.ndarray, frame_time: float, contacts) -> StanceAgreement:
    """A contact schedule judged against the stance of the motion it was made for: `stance_agreement` of
    `schedule_stance(contacts, frame times)` and `capture_stance(model, qpos, frame_time)`.

    Args:
        model: the scene's MjModel. qpos: (n, nq) the motion (a reference), frame i at i * frame_time [s].
        contacts: `Contact`s or a `ContactSchedule` on the same time axis.
    Returns:
        StanceAgreement.
    Raises:
        InputError: as `capture_stance`, or a contact names a site no foot has.
    """
    from solver.figure import Figure

    stance = capture_stance(model, qpos, frame_time)
    times = np.arange(len(stance)) * float(frame_time)
    return stance_agreement(schedule_stance(contacts, times, Figure.from_model(model).feet), stance)
