"""Foot contacts: which contact site rests on a surface, and when.

A contact is (site, surface, [start, end]) (docs/contacts.md "Contact schedules"). `detect_contacts` labels them from
a reference motion with height and speed thresholds, hysteresis and a minimum duration: threshold
heuristics alone flicker and are known to be unreliable against pressure-insole ground truth
(UnderPressure, Mourot et al. 2022; ../shared/METRICS.md "Contact labels"), so a site enters contact
only below the tighter pair of thresholds and leaves only above the looser pair; contacts shorter
than `min_duration` can be dropped. The animator overrides the result by writing contacts by hand.

Defaults (`solver.contact_thresholds`), chosen on the three CMU clips (127_33 run and step onto a
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
  judged against the capture's own stance (`runner.mocap.stance`, per foot, no minimum duration),
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

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from solver.contact_thresholds import (
    DETECT_HEIGHT_OFF,
    DETECT_HEIGHT_ON,
    DETECT_MIN_DURATION,
    DETECT_SPEED_OFF,
    DETECT_SPEED_ON,
    SCHEDULE_MIN_DURATION,
)
from solver.errors import InputError
from solver.layout import CONTACT_SITES, FEET

#: the shipped figure's contact sites, in the order of `site_pos` arrays (`solver.layout.CONTACT_SITES`,
#: the name kept for the callers of this module); another figure's: `Figure.from_model(model).contact_sites`.
SITES: tuple[str, ...] = CONTACT_SITES



@dataclass(frozen=True)
class Contact:
    """A contact site on a surface of the scene over [start, end] [s]."""
    site: str        # one of l_heel, l_toe, r_heel, r_toe
    start: float     # [s]
    end: float       # [s]
    surface: str = ""  # name of the StaticSurfaces surface ("" = whichever is under the site)

    @property
    def duration(self) -> float:
        """[s] end - start."""
        return self.end - self.start


def checked_intervals(entries, label: str) -> tuple[tuple[float, float], ...]:
    """Time intervals given as pairs of seconds (a keyframe file's "flights", `Clearance`'s `airborne`),
    checked and sorted.

    Args:
        entries: a sequence of (start, end) pairs [s]. label: what the pairs are called in an error
            (e.g. "k.json: flights").
    Returns:
        ((start, end), ...) [s] sorted by start.
    Raises:
        InputError: naming `label[i]` and its value: not two finite numbers (not strings or booleans)
            with start < end.
    """
    out = []
    for i, e in enumerate(entries):
        pair = list(e) if isinstance(e, (list, tuple, np.ndarray)) else None
        ok = pair is not None and len(pair) == 2 and all(
            isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) and np.isfinite(v)
            for v in pair)
        if not ok or not pair[0] < pair[1]:
            raise InputError(f"{label}[{i}] is {pair if pair is not None else e!r}; it must be [start, end] in "
                             "seconds with start < end")
        out.append((float(pair[0]), float(pair[1])))
    return tuple(sorted(out))


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
    sites: Sequence[str] = SITES,
    height_on: float = DETECT_HEIGHT_ON,
    height_off: float = DETECT_HEIGHT_OFF,
    speed_on: float = DETECT_SPEED_ON,
    speed_off: float = DETECT_SPEED_OFF,
    min_duration: float = DETECT_MIN_DURATION,
    feet: dict[str, tuple[str, ...]] | None = FEET,
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
        feet: {foot: its site names} (default the shipped figure's; sites of no foot enter alone).
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
    down with its lowest site (the capture's stance, `runner.mocap.stance`); a toe held still 2-3 cm
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


def contact_mask(contacts: Sequence[Contact], sites: Sequence[str], times: np.ndarray) -> np.ndarray:
    """(n, s) bool: site k is in some contact at times[i] (start <= t <= end, 1e-9 s tolerance).

    Args:
        contacts: the contacts. sites: the s site names (columns). times: (n,) [s].
    Raises:
        InputError: a contact names a site not in `sites`.
    """
    times = np.asarray(times, float)
    mask = np.zeros((len(times), len(sites)), bool)
    for c in contacts:
        if c.site not in sites:
            raise InputError(f"contact site {c.site!r} is not one of {', '.join(sites)}")
        k = list(sites).index(c.site)
        mask[:, k] |= (times >= c.start - 1e-9) & (times <= c.end + 1e-9)
    return mask


def foot_contacts(contacts: Sequence[Contact], feet: dict[str, tuple[str, ...]] = FEET) -> list[Contact]:
    """Contacts of whole feet: the union of the intervals of a foot's sites, site = the foot's name.

    Overlapping or touching intervals of the heel and the toe of one foot merge into one contact
    (a heel strike rolling onto the toe is one stance).
    """
    out = []
    for foot, members in feet.items():
        iv = sorted((c.start, c.end) for c in contacts if c.site in members)
        merged: list[list[float]] = []
        for a, b in iv:
            if merged and a <= merged[-1][1] + 1e-9:
                merged[-1][1] = max(merged[-1][1], b)
            else:
                merged.append([a, b])
        out += [Contact(foot, a, b) for a, b in merged]
    return sorted(out, key=lambda c: (c.start, c.site))


def touchdowns_liftoffs(contacts: Sequence[Contact], per_foot: bool = True
                        ) -> tuple[list[tuple[float, str]], list[tuple[float, str]]]:
    """Touch-down and lift-off events, sorted by time.

    Args:
        contacts: site contacts. per_foot: merge a foot's heel and toe first (`foot_contacts`), so an
            event is a foot landing or leaving; else one event per site contact.
    Returns:
        touchdowns: [(time [s], foot or site name)] at contact starts.
        liftoffs: [(time [s], foot or site name)] at contact ends.
    """
    cs = foot_contacts(contacts) if per_foot else list(contacts)
    return (sorted((c.start, c.site) for c in cs), sorted((c.end, c.site) for c in cs))


def site_positions(model, qpos: np.ndarray, sites: Sequence[str] = SITES) -> np.ndarray:
    """(n, s, 3) world positions [m] of the named sites for (n, nq) qpos (mj_kinematics, site_xpos).

    Raises:
        InputError: the model lacks a site.
    """
    import mujoco

    ids = []
    for s in sites:
        sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s)
        if sid < 0:
            raise InputError(f"the model has no site {s!r}; contact sites needed: {', '.join(sites)}")
        ids.append(sid)
    from solver.kinematics import mujoco_site_positions

    return mujoco_site_positions(model, mujoco.MjData(model), ids, np.atleast_2d(np.asarray(qpos, float)))


#: the MJCF annotation of a contact site's radius: ``<numeric name="figure:radius:SITE" data="R"/>``
RADIUS_PREFIX = "figure:radius:"


def contact_radii(model, sites: Sequence[str] = SITES) -> np.ndarray:
    """(s,) radius [m] of each contact site's sphere: 0 (a point) unless the figure's MJCF annotates it.

    A contact site may stand for a rounded part of the sole, a sphere centred on the site (a heel that
    rolls on its round back edge at heel strike, the forefoot rolling over the toes at push-off;
    docs/contacts.md, "Rounded contacts"): ``<custom><numeric name="figure:radius:l_heel"
    data="0.04"/></custom>``. The shipped figure has none (every site a point).

    Raises:
        InputError: a radius is not one finite number >= 0.
    """
    out = np.zeros(len(sites))
    for k, s in enumerate(sites):
        try:
            data = np.asarray(model.numeric(RADIUS_PREFIX + s).data, float)
        except KeyError:
            continue
        if data.shape != (1,) or not np.isfinite(data[0]) or data[0] < 0:
            raise InputError(f'<numeric name="{RADIUS_PREFIX}{s}" data="{" ".join(map(str, data))}">: give the '
                             'radius of the site\'s sphere, one number >= 0 in metres, e.g. data="0.04"')
        out[k] = data[0]
    return out


def lowest_points(site_pos: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """(..., s, 3) the lowest points [m] of the contact spheres centred on (..., s, 3) sites with (s,) radii [m].

    The point of a sphere of radius r nearest to a surface with upward unit normal n is c - r n,
    whatever the foot's orientation; this takes c - r z. Its height above the surface under it
    (`StaticSurfaces.height_above`, a vertical distance) is the centre's minus r, and differs from
    the height of c - r n by r (1/n_z - 1): 0.2 micrometres for r = 4 cm on a floor tilted by 1 degree.
    The speed of the point is the centre's (a constant shift). With radii 0 the sites themselves.
    """
    pos = np.array(site_pos, float)
    pos[..., 2] -= np.asarray(radii, float)
    return pos


def contact_points(model, qpos: np.ndarray, sites: Sequence[str] = SITES) -> np.ndarray:
    """(n, s, 3) the lowest points [m] of the named contact sites' spheres (`lowest_points` of
    `site_positions` with `contact_radii`): where heights above a surface are measured.

    Raises:
        InputError: the model lacks a site, or a radius annotation is malformed.
    """
    return lowest_points(site_positions(model, qpos, sites), contact_radii(model, sites))


def site_heights(model, site_pos: np.ndarray) -> np.ndarray:
    """(n, s) height [m] of each point above the surface under it in the model's scene (give the contact
    points, `contact_points`, for a figure whose sites are rounded)."""
    from solver.surfaces import StaticSurfaces

    return StaticSurfaces.from_model(model).height_above(site_pos)


def reference_contacts(model, qpos: np.ndarray, frame_time: float, **thresholds) -> list[Contact]:
    """The contact schedule of a motion in a scene: `detect_contacts` on its contact points and their
    heights (`contact_points`: MuJoCo kinematics, rounded sites' lowest points), keeping every contact (`min_duration` SCHEDULE_MIN_DURATION = 0 unless given:
    a hop's 10-40 ms touch-down is a contact, and dropping it would make its frames a flight).

    Args:
        model: the scene's MjModel (figure with the SITES, and static surfaces). qpos: (n, nq).
        frame_time: [s]. thresholds: keyword arguments of `detect_contacts`.
    """
    pos = contact_points(model, qpos)
    times = np.arange(len(pos)) * frame_time
    thresholds.setdefault("min_duration", SCHEDULE_MIN_DURATION)
    return detect_contacts(times, pos, site_heights(model, pos), **thresholds)


def airborne_intervals(times: np.ndarray, heights: np.ndarray, height: float = DETECT_HEIGHT_ON) -> tuple[tuple[float, float], ...]:
    """The intervals where a motion is airborne: every site higher than `height` (the flight metric's
    3 cm, `runner.motion_metrics.FLIGHT_HEIGHT`), a run of such frames i..j as (t_i - dt/2, t_j + dt/2)
    with dt the median frame spacing, so an interval lasts as long as the metric counts its frames.

    Args:
        times: (n,) increasing frame times [s], n >= 2. heights: (n, k) height of each site above the
            surface under it [m] (`solver.contacts.site_heights` of `contact_points`). height: [m].
    Returns:
        ((start, end), ...) [s], sorted and disjoint; () when no frame is airborne.
    Raises:
        InputError: shapes that disagree, fewer than two frames, times not increasing.
    """
    t, h = np.asarray(times, float), np.asarray(heights, float)
    if t.ndim != 1 or len(t) < 2 or h.ndim != 2 or len(h) != len(t):
        raise InputError(f"airborne_intervals: times {t.shape} and heights {h.shape} must be (n,) and (n, k), n >= 2")
    if not np.all(np.diff(t) > 0):
        raise InputError("airborne_intervals: frame times must increase")
    half = 0.5 * float(np.median(np.diff(t)))
    up = np.concatenate([[False], (h > height).all(axis=1), [False]]).astype(np.int8)
    starts, ends = np.flatnonzero(np.diff(up) == 1), np.flatnonzero(np.diff(up) == -1) - 1
    return tuple((float(t[i] - half), float(t[j] + half)) for i, j in zip(starts, ends, strict=True))
