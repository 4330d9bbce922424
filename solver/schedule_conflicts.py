"""Keyframes against the contact schedule: what they contradict, and what the contact terms excuse.

Keyframes are met exactly, so where a keyframe contradicts the schedule (a site the schedule plants
held up, two keyframes in one contact holding a site apart, a swinging site held on the ground) no
weight of a contact term can reach its bound there, and penalty continuation would raise the weight
in vain. `ScheduleConflicts` records those findings and what follows from them, as a value:

- `planted`: contacts the planted term's `violation` leaves out,
- `swings`: (site, a, b) swings and flights the clearance term's `violation` leaves out,
- `lowered`: (site, a, b) -> the clearance band of that swing [m], lowered to the lowest height a
  keyframe holds the site at in it (`solver.terms.clearance`, module docstring),
- `lifts`: (a, b) -> the ceiling [m] of that flight's ballistic lift, lowered to the lowest site a
  keyframe holds where the lift is at its ceiling,
- `held`: contact -> (lo, hi) [s], the part of a contact the planted term pulls to its surface where
  a keyframe inside it holds the site off its plant (`Planted.held`: the rest of the contact is the
  site's way down or up, which the keyframe fixes),
- `found`: [(kind, keyframe index, site, distance [m])] for the warnings ("planted", "sliding",
  "clearance"; `solver.problem.keyframe_conflicts`).

`solver.problem.keyframe_conflicts` makes it from the keyframes; the terms are built with it
(`Planted(..., conflicts=)`, `Clearance(..., conflicts=)`) and never change afterwards.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from types import MappingProxyType

from solver.contacts import Contact


def _frozen(d: Mapping) -> Mapping:
    return MappingProxyType(dict(d))


@dataclass(frozen=True)
class ScheduleConflicts:
    """What keyframes contradict in a contact schedule, and what the contact terms excuse for it.

    Attributes:
        found: ((kind, keyframe index, site, distance [m]), ...) in the order found.
        planted: contacts (`Contact` values of the schedule) left out of the planted term's violation.
        swings: (site, a [s], b [s]) swings or flights left out of the clearance term's violation.
        lowered: {(site, a, b): band [m]} lowered clearance bands of swings (read-only mapping).
        lifts: {(a, b): ceiling [m]} lowered ballistic-lift ceilings of flights (read-only mapping).
        held: {contact: (lo [s], hi [s])} the planted term's height and sliding pull on that contact
            limited to [lo, hi] (lo >= hi: none) (read-only mapping).
    """

    found: tuple[tuple[str, int, str, float], ...] = ()
    planted: frozenset[Contact] = frozenset()
    swings: frozenset[tuple[str, float, float]] = frozenset()
    lowered: Mapping[tuple[str, float, float], float] = field(default_factory=lambda: _frozen({}))
    lifts: Mapping[tuple[float, float], float] = field(default_factory=lambda: _frozen({}))
    held: Mapping[Contact, tuple[float, float]] = field(default_factory=lambda: _frozen({}))

    def __post_init__(self):
        object.__setattr__(self, "found", tuple(self.found))
        object.__setattr__(self, "planted", frozenset(self.planted))
        object.__setattr__(self, "swings", frozenset(self.swings))
        object.__setattr__(self, "lowered", _frozen(self.lowered))
        object.__setattr__(self, "lifts", _frozen(self.lifts))
        object.__setattr__(self, "held", _frozen(self.held))

    def __hash__(self) -> int:
        return hash((self.found, self.planted, self.swings, tuple(sorted(self.lowered.items())),
                     tuple(sorted(self.lifts.items())), tuple(sorted(self.held.items(), key=repr))))

    @property
    def excuses(self) -> bool:
        """Whether anything is excused or lowered (terms built with it differ from the schedule's own)."""
        return bool(self.planted or self.swings or self.lowered or self.lifts or self.held)

    def merged(self, other: ScheduleConflicts) -> ScheduleConflicts:
        """Both together: findings concatenated (self's first), excusals united, bands and ceilings
        the lower of the two, held parts the intersection."""
        lowered = dict(self.lowered)
        for k, v in other.lowered.items():
            lowered[k] = min(lowered.get(k, v), v)
        lifts = dict(self.lifts)
        for k, v in other.lifts.items():
            lifts[k] = min(lifts.get(k, v), v)
        held = dict(self.held)
        for k, (lo, hi) in other.held.items():
            a, b = held.get(k, (lo, hi))
            held[k] = (max(a, lo), min(b, hi))
        return ScheduleConflicts(self.found + other.found, self.planted | other.planted,
                                 self.swings | other.swings, lowered, lifts, held)

    def with_found(self, found) -> ScheduleConflicts:
        """The same excusals with other findings."""
        return replace(self, found=tuple(found))
