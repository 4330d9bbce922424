"""A clip's contact schedule as a file the animator edits: `dynsplines clean` writes the contacts it found
(`<stem>.contacts.json`), and `--contacts FILE` reads them back in place of contact detection.

Contact detection from heights and speeds (`runner.capture.contact_detection`) is a threshold heuristic, and
such heuristics are known to be unreliable against pressure-insole ground truth (UnderPressure, Mourot et al.
2022; ../shared/METRICS.md "Contact labels": let the user override contacts). A slow, low step is one it
cannot tell from a planted foot: a foot that shuffles 14 cm back at 0.4 m/s, 2-4 cm up, stays "in contact",
and a clean in planted mode holds it where it stood. The file is the override: delete that contact, or split
it around the step, and clean again.

The file is JSON, {"format": "dynsplines.contacts/1", "source": {"clip": ...}, "contacts": [...], "flights":
[...]}, its "contacts" and "flights" as a keyframe file has them (docs/keyframe-format.md: a site or a foot,
start and end [s] on the clip's time, counted from its first frame of motion, and the surface). A keyframe
file written by `dynsplines mocap` of the same clip is read the same way.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

from solver.errors import InputError

__all__ = ["FORMAT", "read_contacts_file", "write_contacts_file"]

FORMAT = "dynsplines.contacts/1"


def write_contacts_file(path: str | os.PathLike, contacts, flights, clip: str | os.PathLike) -> None:
    """Write the contact schedule of `clip`, atomically (`runner.files.atomic_output`).

    Args:
        path: the .json file. contacts: `solver.contacts.Contact`s. flights: ((start, end), ...) [s] where every
            contact site is above the flight height. clip: the BVH clip they are of (recorded as "source").
    Raises:
        InputError: a contact that does not read back (`solver.keyframe_file.read_contacts`).
    """
    from runner.files import atomic_output
    from solver.keyframe_file import contacts_document, read_contacts

    doc = {"format": FORMAT, "source": {"clip": str(clip)}, "contacts": contacts_document(contacts),
           "flights": [[round(float(a), 6), round(float(b), 6)] for a, b in flights]}
    read_contacts(doc["contacts"], str(path))
    head = ",\n".join(f" {json.dumps(k)}: {json.dumps(doc[k])}" for k in ("format", "source"))
    rows = [f"  {json.dumps(c)}" for c in doc["contacts"]]  # one contact a line, to edit
    listed = "[\n" + ",\n".join(rows) + "\n ]" if rows else "[]"
    text = "{\n" + head + ',\n "contacts": ' + listed + ',\n "flights": ' + json.dumps(doc["flights"]) + "\n}\n"
    with atomic_output(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def read_contacts_file(path: str | os.PathLike, model, duration: float, flights: tuple) -> tuple[list, tuple]:
    """The contacts and flights of a contacts file or a keyframe file.

    Args:
        path: the .json file. model: the scene's MjModel (its figure's feet and sites, its surfaces).
        duration: [s] the clip's length: a contact must start within it. flights: ((start, end), ...) [s] the
            capture's own, taken where the file has no "flights".
    Returns:
        (contacts: `solver.contacts.Contact`s, a surface left out "" (the caller names the one under the site);
        flights: the file's, else `flights`).
    Raises:
        InputError: naming the file, the entry and the fix: missing or malformed, no "contacts" list, an entry
            `solver.keyframe_file.read_contacts` refuses (unknown site, foot or surface, bad times), a contact
            that starts after the clip ends or inside a flight (the file's, else the capture's).
    """
    from solver.figure import model_feet
    from solver.keyframe_file import read_contacts, read_document, read_flights
    from solver.surfaces import StaticSurfaces

    src = str(path)
    if not Path(path).is_file():
        raise InputError(f"{src}: no such contacts file (current folder: {Path.cwd()}); give the <stem>.contacts.json "
                         "a clean wrote, or a keyframe file with contacts")
    doc = read_document(path)
    if not isinstance(doc, dict) or "contacts" not in doc:
        raise InputError(f"{src}: no \"contacts\" list; give the <stem>.contacts.json a clean wrote, or a keyframe file "
                         "with contacts (docs/keyframe-format.md)")
    schedule = read_contacts(doc["contacts"], src, tuple(StaticSurfaces.from_model(model).names), model_feet(model))
    flights, whose = (read_flights(doc["flights"], src), "flights") if "flights" in doc else (tuple(flights), "the capture's flight")
    for c, label in zip(schedule.contacts, schedule.labels, strict=True):
        if c.start > duration + 1e-6:  # [s] a file's times are rounded to 1e-6
            raise InputError(f"{src}: {label} starts at {c.start:g} s, after the clip's last frame at {duration:g} s; "
                             "is the file of this clip? (times count from its first frame of motion)")
        # a detected contact starts below the flight height, so never inside a flight (it may run into one, a site
        # staying within 5 cm while all are 3 cm up): one that does was written into the air
        i = next((i for i, (a, b) in enumerate(flights) if a + 1e-6 < c.start < b - 1e-6), None)
        if i is not None:
            a, b = flights[i]
            raise InputError(f"{src}: {label} ({c.site}, {c.start:g}-{c.end:g} s) starts in {whose}[{i}] ({a:g}-{b:g} s), "
                             "where every contact site is in the air; delete or shorten the one or the other")
    return list(schedule.contacts), flights
