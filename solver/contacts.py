"""Foot contacts: which contact site rests on a surface, and when.

A contact is (site, surface, [start, end]) (docs/contacts.md "Contact schedules"): given by hand in a
keyframe file, or detected from a motion capture (`runner.capture.contact_detection`). This module holds
what the method reads of them: the intervals, masks and whole-foot merges, and the contact sites' positions,
radii and heights above the scene's surfaces.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from solver.contact_thresholds import FLIGHT_HEIGHT
from solver.errors import InputError


@dataclass(frozen=True)
class Contact:
    """A contact site on a surface of the scene over [start, end] [s]."""
    site: str        # one of the figure's contact sites (`Figure.contact_sites`), e.g. l_heel
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


def foot_contacts(contacts: Sequence[Contact], feet: Mapping[str, Sequence[str]]) -> list[Contact]:
    """Contacts of whole feet: the union of the intervals of a foot's sites, site = the foot's name.

    Overlapping or touching intervals of the heel and the toe of one foot merge into one contact
    (a heel strike rolling onto the toe is one stance). feet: {foot: its sites}, the figure's
    (`Figure.feet`).
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


def touchdowns_liftoffs(contacts: Sequence[Contact], feet: Mapping[str, Sequence[str]] | None
                        ) -> tuple[list[tuple[float, str]], list[tuple[float, str]]]:
    """Touch-down and lift-off events, sorted by time.

    Args:
        contacts: site contacts. feet: {foot: its sites} (`Figure.feet`): merge a foot's heel and toe
            first (`foot_contacts`), so an event is a foot landing or leaving; None: one event per site
            contact.
    Returns:
        touchdowns: [(time [s], foot or site name)] at contact starts.
        liftoffs: [(time [s], foot or site name)] at contact ends.
    """
    cs = foot_contacts(contacts, feet) if feet is not None else list(contacts)
    return (sorted((c.start, c.site) for c in cs), sorted((c.end, c.site) for c in cs))


def figure_sites(model, sites: Sequence[str] | None) -> tuple[str, ...]:
    """`sites`, or the contact sites of the model's figure (`solver.figure.model_contact_sites`) when None.

    Raises:
        InputError: `sites` is None and the model's figure has no feet annotation.
    """
    if sites is not None:
        return tuple(sites)
    from solver.figure import model_contact_sites

    return model_contact_sites(model)


def site_positions(model, qpos: np.ndarray, sites: Sequence[str] | None = None) -> np.ndarray:
    """(n, s, 3) world positions [m] of the named sites for (n, nq) qpos (mj_kinematics, site_xpos);
    sites None: the model's figure's contact sites (`figure_sites`).

    Raises:
        InputError: the model lacks a site.
    """
    import mujoco

    sites = figure_sites(model, sites)
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


def contact_radii(model, sites: Sequence[str] | None = None) -> np.ndarray:
    """(s,) radius [m] of each contact site's sphere: 0 (a point) unless the figure's MJCF annotates it;
    sites None: the model's figure's contact sites (`figure_sites`).

    A contact site may stand for a rounded part of the sole, a sphere centred on the site (a heel that
    rolls on its round back edge at heel strike, the forefoot rolling over the toes at push-off;
    docs/contacts.md, "Rounded contacts"): ``<custom><numeric name="figure:radius:l_heel"
    data="0.04"/></custom>``. The shipped figure has none (every site a point).

    Raises:
        InputError: a radius is not one finite number >= 0.
    """
    sites = figure_sites(model, sites)
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


def contact_points(model, qpos: np.ndarray, sites: Sequence[str] | None = None) -> np.ndarray:
    """(n, s, 3) the lowest points [m] of the named contact sites' spheres (`lowest_points` of
    `site_positions` with `contact_radii`): where heights above a surface are measured; sites None: the
    model's figure's contact sites (`figure_sites`).

    Raises:
        InputError: the model lacks a site, or a radius annotation is malformed.
    """
    sites = figure_sites(model, sites)
    return lowest_points(site_positions(model, qpos, sites), contact_radii(model, sites))


def site_heights(model, site_pos: np.ndarray) -> np.ndarray:
    """(n, s) height [m] of each point above the surface under it in the model's scene (give the contact
    points, `contact_points`, for a figure whose sites are rounded)."""
    from solver.surfaces import StaticSurfaces

    return StaticSurfaces.from_model(model).height_above(site_pos)


def airborne_intervals(times: np.ndarray, heights: np.ndarray, height: float = FLIGHT_HEIGHT) -> tuple[tuple[float, float], ...]:
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
