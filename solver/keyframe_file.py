"""Keyframe files: human-readable JSON with named joints (format "dynsplines.keyframes/1").

Format (docs/keyframe-format.md has a full example)::

    {
      "format": "dynsplines.keyframes/1",
      "model": "humanoid39.xml",            # the figure, relative to this file
      "scene": "run_and_step.xml",          # the scene (figure + floor + boxes), relative to this file
      "source": {"clip": ..., "command": ..., "hand_edits": ...},   # provenance, free-form strings
      "terms": "all",                       # optional: "default" (the constraints) or "all" (also forces)
      "contacts": [                         # optional: contact sites on surfaces over [start, end] s
        {"site": "l_toe", "start": 0.0, "end": 0.2, "surface": "floor"},
        {"foot": "right", "start": 0.3, "end": 0.5}             # a foot: its heel and its toe
      ],
      "flights": [[0.22, 0.31]],            # optional: where the motion flies (every site 3 cm clear), s
      "keyframes": [
        {"time": 0.0, "joints": {"root": [x, y, z, qw, qx, qy, qz], "l_hip": [qw, qx, qy, qz], ...}},
        {"time": 0.25, "joints": {"root": [x, y, z, qw, qx, qy, qz], "l_knee": [qw, null, null, null]}}
      ]
    }

Times in seconds, positions in metres, quaternions w x y z, or a joint's rotation in degrees as an object
({"euler": [...], "order": "xyz"} or {"axis": [...], "angle": a}; the root adds "pos": solver/joint_angles.py).
In a keyframe, an omitted joint is entirely
free and a `null` component is free (a partial keyframe, paper sec. 2). A keyframe may carry a
"comment" string. Checks of times (increasing, not negative), of the keyframe count (>= 2), of
keyframes that fix nothing and of zero quaternions are `solver.Keyframes`'s; this module checks the
file and the fields and names the file, keyframe index and field in every message.
"""
from __future__ import annotations

import json
import math
import os
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from solver.contact_schedule import ContactSchedule
from solver.contacts import Contact, checked_intervals
from solver.errors import InputError
from solver.figure import foot_sites, model_feet
from solver.keyframes import Keyframes
from solver.layout import StateLayout

FORMAT = "dynsplines.keyframes/1"
_TOP_KEYS = {"format", "model", "scene", "source", "terms", "contacts", "flights", "keyframes", "comment"}
_CONTACT_KEYS = {"site", "foot", "start", "end", "surface", "comment"}
_KEYFRAME_KEYS = {"time", "joints", "comment"}
_JSON_CONSTANTS = {"NaN": math.nan, "Infinity": math.inf, "-Infinity": -math.inf}
_DIGITS = 6  # [decimals] written: 1 micrometre, 1e-6 of a unit quaternion


@dataclass(frozen=True)
class KeyframeFileInfo:
    """What a keyframe file says besides the keyframes.

    Attributes:
        path: the keyframe file.
        model: the figure's MJCF, resolved against the file's folder (None if the file has no "model").
        scene: the scene's MJCF, resolved likewise (None if absent).
        source: the "source" object (provenance), {} if absent.
        terms: the "terms" value, "default" or "all" (also the force bounds), None if absent.
        contacts: the "contacts" list as a `ContactSchedule` (sorted by start; a foot's entry expanded
            to its heel and toe, the figure's `Figure.feet`); empty if absent.
        flights: the "flights" list as ((start, end), ...) [s]: where the motion the keyframes came from
            flies, for the clearance constraint (docs/contacts.md); None if absent (every
            gap of the contacts is a flight).
    """

    path: Path
    model: Path | None
    scene: Path | None
    source: dict = field(default_factory=dict)
    terms: str | None = None
    contacts: ContactSchedule = field(default_factory=ContactSchedule.empty)
    flights: tuple[tuple[float, float], ...] | None = None


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def read_document(path: str | os.PathLike) -> Any:
    """The parsed JSON of a keyframe file, with the file checks of `read_keyframes` (its messages).

    NaN and Infinity literals are accepted here (read_keyframes rejects them per value, naming the
    joint and component).

    Raises:
        InputError: missing, a folder, unreadable, not UTF-8, malformed or too deeply nested JSON.
    """
    p = Path(path)
    src = str(path)
    try:
        text = p.read_text(encoding="utf-8-sig")  # a byte-order mark (Notepad, .NET) is not JSON
    except FileNotFoundError:
        from solver.shipped import shipped_hint

        hint = shipped_hint(p)
        if hint:
            raise InputError(f"{src}: no such keyframe file{hint}") from None
        raise InputError(f"{src}: no such keyframe file (current folder: {Path.cwd()}); check the path") from None
    except IsADirectoryError:
        raise InputError(f"{src}: is a folder; give the path of a .json keyframe file") from None
    except UnicodeDecodeError as e:
        raise InputError(f"{src}: not a text file (byte {e.start} is not UTF-8); give a .json keyframe file") from None
    except OSError as e:
        raise InputError(f"{src}: cannot read the keyframe file: {e.strerror}; check its permissions") from None
    try:
        return json.loads(text, parse_constant=_JSON_CONSTANTS.__getitem__)
    except json.JSONDecodeError as e:
        raise InputError(
            f"{src}: line {e.lineno}, column {e.colno}: malformed JSON ({e.msg}); check brackets, commas and "
            "quotes near there (JSON has no comments and no trailing commas)"
        ) from None
    except RecursionError:
        raise InputError(f"{src}: JSON nested too deeply to read; a keyframe file is an object of lists") from None


def read_keyframes(path: str | os.PathLike, layout) -> tuple[Keyframes, KeyframeFileInfo]:
    """Read and check a keyframe file.

    Args:
        path: the .json keyframe file.
        layout: the figure's qpos layout, `StateLayout.from_model(model)` (joint names and sizes), or
            the mujoco.MjModel itself (then the contacts name that figure's feet and sites,
            `solver.figure.Figure`, and a scene's surface names are checked here; with a layout, a
            contact's site and surface are checked when its problem is built, `solver.build_problem`,
            naming this file and entry, and a "foot" entry is an error: give the model).
    Returns:
        (keyframes, info): solver.Keyframes with times (k,) [s], values (k, nq) (NaN where free) and
        mask (k, nq) (True where fixed), source = str(path); and the file's KeyframeFileInfo.
    Raises:
        InputError: unreadable file; malformed JSON (line and column); no "format" field, or not a
            keyframe file (format); a bad "contacts" entry (`read_contacts`);
            missing "keyframes", "time" or "joints"; an unknown field, an unknown joint (the valid ones
            are listed); a joint with the wrong number of components (the right number is given);
            NaN, infinity or a non-number value; and everything solver.Keyframes rejects (times not
            increasing or negative, fewer than two keyframes, a keyframe fixing nothing, a zero
            quaternion); a "model" field that does not name an existing file.
    """
    surfaces, mj_model = None, None if isinstance(layout, StateLayout) else layout
    if mj_model is not None:
        from solver.surfaces import StaticSurfaces

        found = StaticSurfaces.from_model(mj_model)
        surfaces = tuple(found.names) if found.count else None  # a figure alone: checked with its scene
        layout = StateLayout.from_model(mj_model)
    p = Path(path)
    src = str(path)
    doc = _checked_document(path)
    times, values, mask = _keyframe_table(doc["keyframes"], layout, src)
    model = _relative_path(doc, "model", p)
    if model is not None and not model.is_file():
        raise InputError(
            f"{src}: field 'model' is {doc['model']!r}, but {model} is not a file (the path is relative to "
            f"the keyframe file's folder); write the figure's path relative to {p.parent.resolve()} (e.g. the "
            "humanoid39.xml the scene includes) or remove the field"
        )
    source = doc.get("source", {})
    if not isinstance(source, dict):
        raise InputError(f"{src}: field 'source' is {source!r}; it must be an object (provenance notes)")
    terms = doc.get("terms")
    if terms is not None and terms not in ("default", "all"):
        raise InputError(f"{src}: field 'terms' is {terms!r}; give \"default\" (the constraints) or \"all\" (the "
                         "constraints and the force bounds), or remove the field")
    feet = model_feet(mj_model) if mj_model is not None and doc.get("contacts") else None
    contacts = read_contacts(doc.get("contacts", []), src, surfaces, feet)
    keyframes = Keyframes(times, values, mask, source=src)
    flights = read_flights(doc["flights"], src) if "flights" in doc else None
    return keyframes, KeyframeFileInfo(p, model, _relative_path(doc, "scene", p), dict(source), terms, contacts,
                                       flights)


def _checked_document(path) -> dict:
    """The keyframe file's top-level object, with its format and fields checked (`read_keyframes`)."""
    src = str(path)
    doc = read_document(path)
    if not isinstance(doc, dict):
        raise InputError(f"{src}: the top level is a {type(doc).__name__}; a keyframe file is a JSON object {{...}}")
    if "format" not in doc:
        raise InputError(f"{src}: missing field 'format'; add \"format\": \"{FORMAT}\" to the top-level object "
                         "(the file format this program reads)")
    fmt = doc["format"]
    if fmt != FORMAT:
        raise InputError(f"{src}: field 'format' is {fmt!r}; this program reads {FORMAT!r} files")
    unknown = sorted(set(doc) - _TOP_KEYS)
    if unknown:
        raise InputError(
            f"{src}: unknown top-level field(s) {', '.join(map(repr, unknown))}; the fields are "
            f"{', '.join(sorted(_TOP_KEYS))}"
        )
    if "keyframes" not in doc:
        raise InputError(f"{src}: missing field 'keyframes'; add a list of {{\"time\": ..., \"joints\": {{...}}}}")
    if not isinstance(doc["keyframes"], list):
        raise InputError(f"{src}: field 'keyframes' is a {type(doc['keyframes']).__name__}; it must be a list of keyframes")
    return doc


def _keyframe_table(frames: list, layout, src: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The "keyframes" list as times (k,) [s], values (k, nq) (NaN where free) and mask (k, nq)."""
    times = np.empty(len(frames))
    values = np.full((len(frames), layout.nq), np.nan)
    mask = np.zeros((len(frames), layout.nq), bool)
    for i, kf in enumerate(frames):
        where = f"{src}: keyframe {i}"
        if not isinstance(kf, dict):
            raise InputError(f"{where} is a {type(kf).__name__}; a keyframe is an object {{\"time\": t, \"joints\": {{...}}}}")
        extra = sorted(set(kf) - _KEYFRAME_KEYS)
        if extra:
            raise InputError(
                f"{where}: unknown field(s) {', '.join(map(repr, extra))}; a keyframe has 'time', 'joints' "
                "and optionally 'comment'"
            )
        if "time" not in kf:
            raise InputError(f"{where}: missing field 'time'; give the keyframe's time in seconds")
        t = kf["time"]
        if not _is_number(t) or not math.isfinite(t):
            raise InputError(f"{where}: 'time' is {t!r}; give a finite number of seconds")
        times[i] = t
        if "joints" not in kf:
            raise InputError(f"{where} (t={t} s): missing field 'joints'; give an object {{joint name: [values]}}")
        joints = kf["joints"]
        if not isinstance(joints, dict):
            raise InputError(f"{where} (t={t} s): 'joints' is a {type(joints).__name__}; it must be an object {{name: [values]}}")
        for name, comps in joints.items():
            _joint_values(layout, f"{where} (t={t} s)", name, comps, values[i], mask[i])
    return times, values, mask


def _joint_values(layout, where: str, name: str, comps, values: np.ndarray, mask: np.ndarray) -> None:
    """One joint's components of a keyframe into its row of `values` and `mask` (free: None)."""
    try:
        jt = layout.joint(name)
    except InputError as e:
        raise InputError(f"{where}, joints: {e}") from None
    what = "x y z qw qx qy qz" if jt.kind == "free" else ("qw qx qy qz" if jt.kind == "ball" else "value")
    if isinstance(comps, dict):  # degrees: Euler angles or an axis and an angle (solver/joint_angles.py)
        from solver.joint_angles import joint_components

        comps = joint_components(jt.kind, comps, f"{where}, joint {name!r}")
    if not isinstance(comps, list) or len(comps) != jt.nq:
        got = f"has {len(comps)} components" if isinstance(comps, list) else "is not a list"
        raise InputError(
            f"{where}, joint {name!r}: {comps!r} {got}; a {jt.kind} joint "
            f"takes a list of {jt.nq} ({what}), null for a free component"
            + ("; or, in degrees, an object such as {\"axis\": [0, 1, 0], \"angle\": 25}" if jt.kind == "ball" else "")
        )
    for c, v in enumerate(comps):
        if v is None:
            continue
        if not _is_number(v) or not math.isfinite(v):
            raise InputError(
                f"{where}, joint {name!r}, component {c} ({what.split()[c]}): {v!r} is not a "
                "finite number; give a number, or null to leave it free"
            )
        values[jt.qposadr + c] = v
        mask[jt.qposadr + c] = True


def _relative_path(doc: dict, key: str, p: Path) -> Path | None:
    """A path field of the file, resolved against the file's folder (None when absent)."""
    v = doc.get(key)
    if v is None:
        return None
    if not isinstance(v, str) or not v or "\x00" in v:
        raise InputError(f"{p}: field {key!r} is {v!r}; give a path relative to the keyframe file")
    return (p.parent / v).resolve()


def read_contacts(entries: Any, src: str, surfaces: tuple[str, ...] | None = None, feet=None) -> ContactSchedule:
    """The "contacts" field of a keyframe file as a `ContactSchedule` (a foot expanded to its heel and
    toe; each contact labelled "contacts[i]" with its entry's index, for later messages).

    Each entry is {"site": a contact site | "foot": a foot ("left" | "right"), "start": s, "end": s,
    "surface": name (optional, "" = whichever surface is under the site), "comment": optional}.

    Args:
        entries: the parsed field. src: the file, for messages. surfaces: the scene's surface names, if
            known (else the contact terms check them against their scene, naming this file and entry).
            feet: {side: (heel, toe)}, the figure's feet (`Figure.feet`); None: no figure at hand, a
            "site" is kept as written (`build_problem` checks it against the figure, naming this file and
            entry) and a "foot" entry raises.
    Raises:
        InputError: naming the file, the field ("contacts", entry index, key), the value and the fix:
            not a list, an entry that is not an object, an unknown key, site or foot, a time that is not
            a finite number >= 0, end not after start, an unknown surface (with `surfaces`).
    """
    named = {} if feet is None else feet
    known = foot_sites(named)
    sites_hint = ", ".join(known) or "a contact site of the figure, e.g. l_toe"
    feet_hint = " or ".join(map(repr, named)) or "a foot of the figure, e.g. 'left'"
    if not isinstance(entries, list):
        raise InputError(f"{src}: field 'contacts' is a {type(entries).__name__}; it must be a list of "
                         '{"site": "l_toe", "start": s, "end": s} or {"foot": "left", "start": s, "end": s}')
    out: list[Contact] = []
    labels: list[str] = []
    for i, c in enumerate(entries):
        where = f"{src}: contacts[{i}]"
        if not isinstance(c, dict):
            raise InputError(f"{where} is {c!r}; a contact is an object "
                             '{"site": "l_toe", "start": 0.0, "end": 0.2, "surface": "floor"}')
        extra = sorted(set(c) - _CONTACT_KEYS)
        if extra:
            raise InputError(f"{where}: unknown field(s) {', '.join(map(repr, extra))}; a contact has 'site' or "
                             "'foot', 'start', 'end' and optionally 'surface' and 'comment'")
        if ("site" in c) == ("foot" in c):
            raise InputError(f"{where}: give exactly one of 'site' ({sites_hint}) or 'foot' ({feet_hint})")
        if "site" in c:
            if not isinstance(c["site"], str):
                raise InputError(f"{where}: 'site' is {c['site']!r}; give a contact site's name "
                                 f"({sites_hint}) or use 'foot': {feet_hint}")
            if feet is not None and c["site"] not in known:
                raise InputError(f"{where}: 'site' is {c['site']!r}; the figure's contact sites are "
                                 f"{sites_hint} (or use 'foot': {feet_hint})")
            sites: tuple[str, ...] = (c["site"],)
        else:
            if feet is None:
                raise InputError(f"{where}: 'foot' is {c['foot']!r}, but the contacts were read without the "
                                 "figure; read the file with its model (read_keyframes(path, model)) or give a 'site'")
            if c["foot"] not in feet:
                raise InputError(f"{where}: 'foot' is {c['foot']!r}; give {feet_hint} (or a 'site')")
            sites = feet[c["foot"]]
        for key in ("start", "end"):
            if key not in c:
                raise InputError(f"{where}: missing field {key!r}; give the contact's {key} time in seconds")
            v = c[key]
            if not _is_number(v) or not math.isfinite(v) or v < 0:
                raise InputError(f"{where}: {key!r} is {v!r}; give a finite number of seconds >= 0")
        surface = c.get("surface", "")
        if not isinstance(surface, str):
            raise InputError(f"{where}: 'surface' is {surface!r}; give a surface's name (a geom of the scene, "
                             'e.g. "floor") or leave it out')
        out += [Contact(site, float(c["start"]), float(c["end"]), surface) for site in sites]
        labels += [f"contacts[{i}]"] * len(sites)
    # start < end, the sites, and (with the scene) the surfaces: checked once, by the schedule
    if feet is None:  # the sites as written, checked against the figure by `build_problem`
        known = tuple(dict.fromkeys(c.site for c in out))
    return ContactSchedule.of(out, known, surfaces, source=src, labels=labels)


def read_flights(entries: Any, src: str) -> tuple[tuple[float, float], ...]:
    """The "flights" field of a keyframe file: [[start, end], ...] [s], the intervals where the motion the
    keyframes came from has every contact site above the flight height (docs/keyframe-format.md).

    Raises:
        InputError: naming the file, the entry and the value: not a list, an entry that is not two
            finite numbers of seconds with start < end.
    """
    if not isinstance(entries, list):
        raise InputError(f"{src}: field 'flights' is a {type(entries).__name__}; it must be a list of "
                         "[start, end] pairs in seconds")
    return checked_intervals(entries, f"{src}: flights")


def contacts_document(contacts) -> list[dict]:
    """The "contacts" field for Contacts: one entry per site contact, times rounded outward to 6 decimals
    (start down, end up), so a contact read back still holds every frame it held."""
    scale = 10.0**_DIGITS
    out = []
    for c in contacts:
        start = math.floor(round(c.start * scale, 3)) / scale
        end = math.ceil(round(c.end * scale, 3)) / scale
        entry: dict[str, Any] = {"site": c.site, "start": start, "end": end}
        if c.surface:
            entry["surface"] = c.surface
        out.append(entry)
    return out


def _num(v: float) -> str:
    r = round(float(v), _DIGITS)
    if r == 0:
        r = 0.0  # no "-0.0"
    return repr(r)


def _format(doc_head: Mapping[str, Any], keyframes: Keyframes, layout: StateLayout) -> str:
    """The file's text: one line per joint, so the file reads (and diffs) like a table."""
    lines = ["{"]
    for key, value in doc_head.items():
        if key in ("contacts", "flights") and value:  # one contact (flight) per line
            items = ",\n".join(f"    {json.dumps(v, ensure_ascii=False)}" for v in value)
            lines.append(f"  {json.dumps(key)}: [\n{items}\n  ],")
            continue
        lines.append(f"  {json.dumps(key)}: {json.dumps(value, ensure_ascii=False)},")
    lines.append('  "keyframes": [')
    for i in range(keyframes.count):
        joints = []
        for jt in layout.joints:
            m = keyframes.mask[i, jt.qpos_slice]
            if not m.any():
                continue
            vals = keyframes.values[i, jt.qpos_slice]
            comps = ", ".join(_num(v) if f else "null" for v, f in zip(vals, m))
            joints.append(f"      {json.dumps(jt.name)}: [{comps}]")
        end = "," if i < keyframes.count - 1 else ""
        lines.append(f'    {{"time": {_num(keyframes.times[i])}, "joints": {{')
        lines.append(",\n".join(joints))
        lines.append(f"    }}}}{end}")
    lines.append("  ]")
    lines.append("}")
    return "\n".join(lines) + "\n"


def write_keyframes(
    path: str | os.PathLike,
    keyframes: Keyframes,
    layout: StateLayout,
    model: str | os.PathLike | None = None,
    scene: str | os.PathLike | None = None,
    source: Mapping[str, Any] | None = None,
    terms: str | None = None,
    contacts=None,
    flights=None,
) -> None:
    """Write keyframes as a keyframe file, atomically (a temporary file in the same folder, then
    `os.replace`), so a reader never sees half a file.

    Components a keyframe leaves free are written as null; a joint with no fixed component is omitted.
    Values are rounded to 6 decimals (1 micrometre, 1e-6 of a unit quaternion).

    Args:
        path: the .json file to write.
        keyframes: solver.Keyframes, values (k, nq) in the layout's qpos order.
        layout: the figure's qpos layout (joint names).
        model, scene: paths of the figure and scene MJCF files; written relative to the file's folder.
        source: provenance (clip, command, hand edits), JSON-serializable.
        terms: optional "default" or "all" (`KeyframeFileInfo.terms`).
        contacts: optional `solver.contacts.Contact`s, written as the "contacts" list (one entry per
            site; checked as `read_keyframes` checks them).
        flights: optional ((start, end), ...) [s], written as the "flights" list (start rounded down,
            end up, to 6 decimals).
    Raises:
        InputError: keyframes and layout disagree in size, the folder does not exist or is not writable,
            or source is not JSON-serializable; terms other than "default" or "all".
    """
    p = Path(path)
    if keyframes.nq != layout.nq:
        raise InputError(f"{p}: keyframes have {keyframes.nq} components per frame but the figure has nq={layout.nq}")
    folder = p.parent if str(p.parent) else Path(".")
    if not folder.is_dir():
        raise InputError(f"{p}: the folder {folder} does not exist; create it first")
    head: dict[str, Any] = {"format": FORMAT}
    if model is not None:
        head["model"] = Path(os.path.relpath(Path(model).resolve(), folder.resolve())).as_posix()
    if scene is not None:
        head["scene"] = Path(os.path.relpath(Path(scene).resolve(), folder.resolve())).as_posix()
    head["source"] = dict(source or {})
    if terms is not None:
        if terms not in ("default", "all"):
            raise InputError(f"{p}: terms is {terms!r}; give 'default' or 'all'")
        head["terms"] = terms
    if contacts is not None:
        head["contacts"] = contacts_document(contacts)
        read_contacts(head["contacts"], str(p))
    if flights is not None:
        scale = 10.0**_DIGITS
        head["flights"] = [[math.floor(round(a * scale, 3)) / scale, math.ceil(round(b * scale, 3)) / scale]
                           for a, b in flights]
        read_flights(head["flights"], str(p))
    try:
        text = _format(head, keyframes, layout)
    except (TypeError, ValueError) as e:
        raise InputError(f"{p}: source cannot be written as JSON ({e}); use strings and numbers") from None
    try:
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{p.name}.", suffix=".tmp")
    except OSError as e:
        raise InputError(f"{p}: cannot write in {folder}: {e.strerror}; check the folder's permissions") from None
    try:
        mask = os.umask(0)  # mkstemp makes the file 0600; give it the permissions a new file gets
        os.umask(mask)
        os.fchmod(fd, 0o666 & ~mask)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, p)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
