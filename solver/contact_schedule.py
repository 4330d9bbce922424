"""The contact schedule: which contact site rests on which surface of the scene, and when.

A `ContactSchedule` is a checked, immutable, sorted tuple of `solver.contacts.Contact`s (site, start,
end [s], surface; docs/contacts.md "Contact schedules") with the queries the contact terms, the keyframe checks and the
metrics ask of it: the flights (no site in contact), each site's swings (between two of its contacts),
touch-downs and lift-offs, and which site is in contact at given times. It is checked once, when it is
made; every later user trusts it. The empty schedule is a valid value (a motion with no known
contacts: the contact terms cannot be chosen).

Keyframe files (`solver.keyframe_file`) and contact detection (`runner.capture.contact_detection.reference_contacts`)
make one; `solver.problem.build_problem` checks it against its scene's surfaces (`for_scene`).
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from solver.contacts import Contact, contact_mask, foot_contacts, touchdowns_liftoffs
from solver.errors import InputError


def merged(intervals: Iterable[tuple[float, float]]) -> list[tuple[float, float]]:
    """Sorted, merged list of (start, end) intervals [s] (touching intervals merge)."""
    out: list[tuple[float, float]] = []
    for s, e in sorted(intervals):
        if out and s <= out[-1][1]:
            out[-1] = (out[-1][0], max(out[-1][1], e))
        else:
            out.append((s, e))
    return out


@dataclass(frozen=True)
class ContactSchedule:
    """Contacts of the figure's sites with the scene's surfaces, checked once and sorted.

    Make one with `ContactSchedule.of(contacts, ...)` (which checks), or `ContactSchedule.empty()`.
    It behaves as a read-only sequence of its contacts (`len`, iteration, indexing, `bool`).

    Attributes:
        contacts: the contacts, sorted by (start, site order in `sites`, end, surface).
        sites: the figure's contact sites the contacts were checked against.
        surfaces: the scene's surface names the contacts were checked against; None: not yet checked
            against a scene (a surface name is then only known to be a string).
        source: where the contacts come from (a keyframe file's path, or ""), for error messages.
        labels: per contact (in `contacts` order), where it was written, e.g. "contacts[3]" (the file
            entry) or "contact 3" (the index in the sequence given to `of`).
    """

    contacts: tuple[Contact, ...] = ()
    sites: tuple[str, ...] = ()
    surfaces: tuple[str, ...] | None = None
    source: str = field(default="", compare=False)
    labels: tuple[str, ...] = field(default=(), compare=False)

    @classmethod
    def empty(cls) -> ContactSchedule:
        """The schedule with no contacts (valid: no contact terms, no flights, no swings)."""
        return cls()

    @classmethod
    def of(cls, contacts: Iterable, sites: Sequence[str], surfaces: Sequence[str] | None = None,
           source: str = "", labels: Sequence[str] | None = None) -> ContactSchedule:
        """The checked, sorted schedule of `contacts`; a ContactSchedule is returned as it is when it
        was checked against the same sites and (if `surfaces` is given) the same surfaces.

        Args:
            contacts: objects with site, start, end [s] and surface ("" = whichever is under the site),
                e.g. `Contact`s, or a ContactSchedule.
            sites: the figure's contact site names. surfaces: the scene's surface names (None: do not
                check surface names). source: for messages (a file path). labels: per contact, where it
                was written (default "contact i").
        Raises:
            InputError: one line naming the source, the contact (its label), the field, the value and
                the valid choices: an unknown site, a start or end that is not a finite number of
                seconds, start >= end, an unknown surface (when `surfaces` is given).
        """
        if isinstance(contacts, ContactSchedule):
            if contacts.sites == tuple(sites) and (surfaces is None or contacts.surfaces == tuple(surfaces)):
                return contacts
            return cls.of(contacts.contacts, sites, surfaces, source or contacts.source, contacts.labels)
        items = list(contacts or ())
        labels = list(labels) if labels is not None else [f"contact {i}" for i in range(len(items))]
        if len(labels) != len(items):
            raise InputError(f"{len(labels)} labels for {len(items)} contacts; give one label per contact")
        checked = [_checked(c, where, sites, surfaces, source) for c, where in zip(items, labels, strict=True)]
        order = sorted(range(len(checked)), key=lambda i: (checked[i].start, list(sites).index(checked[i].site),
                                                           checked[i].end, checked[i].surface))
        return cls(tuple(checked[i] for i in order), tuple(sites), None if surfaces is None else tuple(surfaces),
                   source, tuple(labels[i] for i in order))

    def for_scene(self, surfaces: Sequence[str]) -> ContactSchedule:
        """This schedule checked against a scene's surface names (itself if already checked so).

        Raises:
            InputError: a contact names a surface the scene does not have (its source and label named).
        """
        return ContactSchedule.of(self, self.sites, surfaces)

    # --- a read-only sequence of contacts ---------------------------------------------------------
    def __len__(self) -> int:
        return len(self.contacts)

    def __iter__(self):
        return iter(self.contacts)

    def __getitem__(self, i):
        return self.contacts[i]

    def __bool__(self) -> bool:
        return bool(self.contacts)

    # --- queries ----------------------------------------------------------------------------------
    @property
    def span(self) -> tuple[float, float] | None:
        """(first start, last end) [s], None if empty."""
        if not self.contacts:
            return None
        return min(c.start for c in self.contacts), max(c.end for c in self.contacts)

    def flights(self) -> list[tuple[float, float]]:
        """Intervals (a, b) [s] between the first and the last contact where no site is in contact."""
        busy = merged((c.start, c.end) for c in self.contacts)
        return [(busy[i][1], busy[i + 1][0]) for i in range(len(busy) - 1)]

    def swings(self, site: str) -> list[tuple[float, float]]:
        """Gaps (a, b) [s] between consecutive (merged) contacts of one site (none before its first or
        after its last contact)."""
        busy = merged((c.start, c.end) for c in self.contacts if c.site == site)
        return [(busy[i][1], busy[i + 1][0]) for i in range(len(busy) - 1)]

    def feet(self, feet: Mapping[str, Sequence[str]]) -> list[Contact]:
        """Whole-foot contacts (`solver.contacts.foot_contacts`: a foot's heel and toe merged); feet: the
        figure's {foot: its sites} (`Figure.feet`)."""
        return foot_contacts(self.contacts, feet)

    def events(self, feet: Mapping[str, Sequence[str]] | None) -> tuple[list[tuple[float, str]], list[tuple[float, str]]]:
        """(touch-downs, lift-offs): [(time [s], foot or site name)] (`solver.contacts.touchdowns_liftoffs`);
        feet: the figure's {foot: its sites} for a foot's events, None for each site's."""
        return touchdowns_liftoffs(self.contacts, feet)

    def mask(self, times: np.ndarray, sites: Sequence[str] | None = None) -> np.ndarray:
        """(n, s) bool: site k in contact at times[i] (closed intervals, 1e-9 s tolerance; `sites`
        default this schedule's)."""
        return contact_mask(self.contacts, self.sites if sites is None else sites, times)


def _checked(c, where: str, sites: Sequence[str], surfaces: Sequence[str] | None, source: str) -> Contact:
    """One contact as a `Contact`, checked (see `ContactSchedule.of`)."""
    at = f"{source}: {where}" if source else where
    for attr in ("site", "start", "end"):
        if not hasattr(c, attr):
            raise InputError(f"{at}: {c!r} has no {attr!r}; a contact has site, start, end [s] and surface")
    if c.site not in sites:
        raise InputError(f"{at}: 'site' is {c.site!r}; the figure's contact sites are {', '.join(sites)}")
    times = []
    for key in ("start", "end"):
        v = getattr(c, key)
        try:
            x = float(v)
        except (TypeError, ValueError):
            x = math.nan
        if isinstance(v, bool) or not math.isfinite(x):
            raise InputError(f"{at}: {key!r} is {v!r}; give a finite number of seconds")
        times.append(x)
    start, end = times
    if not start < end:
        fix = "swap them" if end < start else "give the contact a duration"
        raise InputError(f"{at}: 'end' {end:g} is not after 'start' {start:g}; {fix}")
    surface = getattr(c, "surface", "") or ""
    if not isinstance(surface, str):
        raise InputError(f"{at}: 'surface' is {surface!r}; give a surface's name or leave it out")
    if surface and surfaces is not None and surface not in surfaces:
        raise InputError(f"{at}: 'surface' is {surface!r}, which the scene does not have; its surfaces are "
                         f"{', '.join(surfaces) or 'none'} (or leave 'surface' out: whichever is under the site)")
    return c if type(c) is Contact and isinstance(c.start, float) and isinstance(c.end, float) \
        else Contact(c.site, start, end, surface)
