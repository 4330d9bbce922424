"""Contact detection on a motion capture: which contact site rests on a surface, and when.

A contact is (site, surface, [start, end]) (docs/contacts.md "Contact schedules"). `detect_contacts` labels them from
a reference motion with height and speed thresholds, hysteresis and a minimum duration: threshold
heuristics alone flicker and are known to be unreliable against pressure-insole ground truth
(UnderPressure, Mourot et al. 2022; ../shared/METRICS.md "Contact labels"), so a site enters contact
only below the tighter pair of thresholds and leaves only above the looser pair; contacts shorter
than `min_duration` can be dropped. The animator overrides the result by writing contacts by hand.

Defaults (below), chosen on the three CMU clips (127_33 run and step onto a
box, 16_23 walk, 35_17 run; 120 fps, retargeted by `runner/bvh_import.py`, heights above the surface
under each site):

- DETECT_HEIGHT_ON = 0.03 m, DETECT_HEIGHT_OFF = 0.05 m. After the retargeting's root-height
  correction a planted site sits 2 mm above its surface. A forefoot runner's heel hovers 5-10 cm up while the toe is
  planted (127_33 frames 3-18: l_heel 8-10 cm, still at 0.2 m/s), so the entry height must stay
  under ~5 cm or that heel would count as planted; 3 cm takes the walker's heel at heel strike
  (16_23: 0.2-2.3 cm). Leaving at 5 cm is the GMD foot-contact height (../shared/METRICS.md).
- DETECT_SPEED_ON = 0.5 m/s, DETECT_SPEED_OFF = 1.0 m/s (3-D speed, central differences). Planted
  sites move at 0.18-0.34 m/s (median over contact frames), 0.6-0.9 m/s at the 95th percentile (the foot rolling
  over the toe at push-off, marker noise); swinging feet move at 2-10 m/s. Entering at 0.5 m/s (the
  GMD skating speed) means a site enters contact not skating by their measure; leaving at 1 m/s
  keeps a rolling toe planted through push-off.
- No minimum duration for a reference's schedule (`reference_contacts`: SCHEDULE_MIN_DURATION = 0):
  judged against the capture's own stance (`runner.capture.stance`, per foot, no minimum duration),
  the 0.05 s minimum dropped real touch-downs (75_03: the right toe's 4-frame touch at take-off, so
  the schedule's flight began early) and kept nothing the stance rejects on the tuning clips; the
  hysteresis alone keeps a swinging foot from flickering (below). `detect_contacts` still takes a
  `min_duration` (DETECT_MIN_DURATION = 0.05 s, 6 frames at 120 fps) for callers that want resting
  feet only (the scene fit).

Why hysteresis: with single thresholds (3 cm / 0.5 m/s, or GMD's 5 cm / 0.5 m/s) and no minimum
duration the walk 16_23 breaks into 29-32 site contacts (19 foot stances) instead of 12 (6 stances),
the run 35_17 into 11-14 (9 stances) instead of 6 (4); hysteresis alone already gives 12 (6).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from solver.contact_thresholds import FLIGHT_HEIGHT
from solver.contacts import Contact, contact_points, site_heights
from solver.errors import InputError
from solver.figure import foot_sites

__all__ = ["DETECT_HEIGHT_OFF", "DETECT_HEIGHT_ON", "DETECT_MIN_DURATION", "DETECT_SPEED_OFF", "DETECT_SPEED_ON",
           "detect_contacts", "reference_contacts", "site_speeds"]

# -- detecting contact from a motion, with hysteresis: a reference's contact schedule
#    (`detect_contacts`, values measured in its docstring) and the capture's own stance
#    per foot (`runner.capture.stance.capture_stance`, on the foot's lowest site). Speeds after the
#    kinematic gait-event rules validated against pressure insoles (Ghoussayni et al. 2004, Gait & Posture
#    20:266, 0.5 m/s; Bonci et al. 2022, Front. Bioeng. Biotechnol. 10:868928: 3-D heel or forefoot speed
#    under 0.5 m/s at initial contact, forefoot speed over 1.0 m/s at final contact).
#: a site enters contact below this height [m]: the flight height, so a contact never begins in a frame
#: the flight metric counts as airborne ...
DETECT_HEIGHT_ON = FLIGHT_HEIGHT
#: ... and leaves above this one [m] (Guided Motion Diffusion's foot-contact height, ../shared/METRICS.md).
DETECT_HEIGHT_OFF = 0.05
#: a site enters contact below this speed [m/s] ...
DETECT_SPEED_ON = 0.5
#: ... and leaves above this one [m/s].
DETECT_SPEED_OFF = 1.0
#: detected contacts shorter than this are dropped [s] by `detect_contacts` when asked
#: (`min_duration`; the scene fit's resting feet). The contact schedule of a reference keeps every
#: contact (`SCHEDULE_MIN_DURATION`): a hop's or a hopscotch's 10-40 ms touch-down is a real one.
DETECT_MIN_DURATION = 0.05
#: the contact schedule of a reference (`reference_contacts`): no contact is dropped [s].
SCHEDULE_MIN_DURATION = 0.0


def site_speeds(times: np.ndarray, site_pos: np.ndarray) -> np.ndarray:
    """(n, s) 3-D speed [m/s] of each site by central differences (one-sided at the ends).

    Args:
        times: (n,) [s], increasing. site_pos: (n, s, 3) [m].
    """
    if len(times) < 2:
        return np.zeros(site_pos.shape[:2])
    vel = np.gradient(site_pos, times, axis=0)
    return np.linalg.norm(vel, axis=-1)


def _check(times, site_pos, heights, sites):
    times = np.asarray(times, float)
    site_pos = np.asarray(site_pos, float)
    heights = np.asarray(heights, float)
    n = len(times)
    if times.ndim != 1 or n < 1:
        raise InputError(f"times must be a non-empty (n,) array; got shape {times.shape}")
    if n > 1 and not np.all(np.diff(times) > 0):
        raise InputError("times must be strictly increasing")
    s = len(sites)
    if site_pos.shape != (n, s, 3):
        raise InputError(f"site_pos must have shape (n, s, 3) = ({n}, {s}, 3); got {site_pos.shape}")
    if heights.shape != (n, s):
        raise InputError(f"heights must have shape (n, s) = ({n}, {s}); got {heights.shape}")
    return times, site_pos, heights


def detect_contacts(
    times: np.ndarray,
    site_pos: np.ndarray,
    heights: np.ndarray,
    sites: Sequence[str],
    height_on: float = DETECT_HEIGHT_ON,
    height_off: float = DETECT_HEIGHT_OFF,
    speed_on: float = DETECT_SPEED_ON,
    speed_off: float = DETECT_SPEED_OFF,
    min_duration: float = DETECT_MIN_DURATION,
    feet: Mapping[str, Sequence[str]] | None = None,
) -> list[Contact]:
    """Contacts of each site from its height above the surface and its speed, with hysteresis.

    Per site, frame by frame: out of contact, the site enters when height < height_on and
    speed < speed_on, and so does the lowest site of its foot (`feet`; None: sites alone); in
    contact, it stays while height <= height_off and speed <= speed_off.
    A contact runs from its first to its last frame (times of those frames; a one-frame contact
    half a frame either side, within `times`); contacts with end - start < min_duration are dropped
    (0: none). Speeds are 3-D, central differences of `site_pos`.

    Args:
        times: (n,) frame times [s], strictly increasing.
        site_pos: (n, s, 3) site positions [m] (world, z up).
        heights: (n, s) height [m] of each site above the surface under it (negative: below).
        sites: the s site names, in the order of the second axis.
        height_on, height_off: [m], height_on <= height_off. speed_on, speed_off: [m/s],
            speed_on <= speed_off. min_duration: [s] >= 0.
        feet: {foot: its site names} (the figure's, `Figure.feet`); None, and sites of no foot: each site
            enters alone.
    Returns:
        contacts sorted by start time, then site order; surface "" (whichever is under the site).
    Raises:
        InputError: shapes disagree, times not increasing, thresholds out of order.
    """
    times, site_pos, heights = _check(times, site_pos, heights, sites)
    if not (height_on <= height_off and speed_on <= speed_off and min_duration >= 0):
        raise InputError(
            f"thresholds need height_on <= height_off, speed_on <= speed_off, min_duration >= 0; got "
            f"height {height_on}/{height_off} m, speed {speed_on}/{speed_off} m/s, min {min_duration} s"
        )
    speed = site_speeds(times, site_pos)
    enter = _foot_entry((heights < height_on) & (speed < speed_on), heights, sites, feet)
    stay = (heights <= height_off) & (speed <= speed_off)
    out: list[tuple[float, int, Contact]] = []
    for k, name in enumerate(sites):
        on = False
        first = 0
        for i in range(len(times) + 1):
            if on and (i == len(times) or not stay[i, k]):
                on = False
                c = _contact(name, times, first, i - 1)
                if c is not None and c.duration >= min_duration - 1e-9:
                    out.append((c.start, k, c))
            if i < len(times) and not on and enter[i, k]:
                on, first = True, i
    out.sort(key=lambda t: (t[0], t[1]))
    return [c for _, _, c in out]


def _foot_entry(enter: np.ndarray, heights: np.ndarray, sites: Sequence[str], feet) -> np.ndarray:
    """(n, s) `enter` where a site may also enter only while its foot's lowest site may: a foot touches
    down with its lowest site (the capture's stance, `runner.capture.stance`); a toe held still 2-3 cm
    up while the heel under it still sweeps in at 0.5-1.2 m/s is not yet on the floor."""
    out = enter.copy()
    rows = np.arange(len(enter))
    for members in (feet or {}).values():
        ks = [list(sites).index(m) for m in members if m in sites]
        if len(ks) > 1:
            low = np.asarray(ks)[np.argmin(heights[:, ks], axis=1)]
            out[:, ks] &= enter[rows, low][:, None]
    return out


def _contact(site: str, times: np.ndarray, first: int, last: int) -> Contact | None:
    """The contact of `site` over frames first..last: from the first frame's time to the last's; a
    one-frame contact spans half a frame either side (within the motion), so that it is an interval;
    None for the one frame of a one-frame motion."""
    if last > first:
        return Contact(site, float(times[first]), float(times[last]))
    start = (times[first - 1] + times[first]) / 2 if first > 0 else times[first]
    end = (times[last] + times[last + 1]) / 2 if last + 1 < len(times) else times[last]
    return Contact(site, float(start), float(end)) if end > start else None


def reference_contacts(model, qpos: np.ndarray, frame_time: float, **thresholds) -> list[Contact]:
    """The contact schedule of a motion in a scene: `detect_contacts` on its contact points and their
    heights (`contact_points`: MuJoCo kinematics, rounded sites' lowest points), keeping every contact (`min_duration` SCHEDULE_MIN_DURATION = 0 unless given:
    a hop's 10-40 ms touch-down is a contact, and dropping it would make its frames a flight).

    Args:
        model: the scene's MjModel (the figure with its feet annotated, `solver.figure.Figure`, and static
            surfaces). qpos: (n, nq). frame_time: [s]. thresholds: keyword arguments of `detect_contacts`.
    """
    from solver.figure import model_feet

    feet = model_feet(model)
    sites = foot_sites(feet)
    pos = contact_points(model, qpos, sites)
    times = np.arange(len(pos)) * frame_time
    thresholds.setdefault("min_duration", SCHEDULE_MIN_DURATION)
    thresholds.setdefault("feet", feet)
    return detect_contacts(times, pos, site_heights(model, pos), sites, **thresholds)
