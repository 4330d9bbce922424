"""`dynsplines bench corpus`: every (clip, keying) pair solved as `dynsplines mocap` solves it and held to
the acceptance bounds (`runner.corpus_bounds`), tuning and validation clips reported apart
(`runner.corpus_sets`); docs/corpus.md.

Underneath it is a batch (`runner.batch.run_batch`: worker processes or Ray, resumable through each
pair's done.json): a pair is the clip with one keying's `ClipOptions`, in the folder
`OUT/<clip stem>.<keying>/`. Once the batch is done each pair's metrics report and keyframe file are read
back, its figures checked against every bound, and the run written as `OUT/corpus.md` (the tables) and
`OUT/corpus.json` (every pair's figures and checks, the pass rates).
"""
from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Sequence
from pathlib import Path

from runner.batch import file_sha256, run_batch
from runner.corpus_bounds import BOUND_BY_NAME, BOUNDS, CAUSES, FORCED, NOT_TOLD, check_pair, pair_figures, schedule_flight_s
from runner.corpus_sets import SETS, clip_set
from runner.files import atomic_output
from runner.pipeline import ClipOptions
from solver.errors import InputError

KEYS = ("every", "contacts")
#: the keyings of the acceptance list: every 0.2 / 0.25 / 0.33 s and --keys contacts
DEFAULT_EVERY = (0.2, 0.25, 0.33)


@dataclasses.dataclass(frozen=True)
class Keying:
    """How a pair's keyframes are picked: `keys` "every" (spacing `every` [s]) or "contacts" (`every`: the
    largest gap [s], None = none), as `dynsplines mocap --keys KEYS --every EVERY`."""

    keys: str
    every: float | None = None

    @property
    def label(self) -> str:
        """"every 0.25", "contacts", "contacts 0.5"."""
        return self.keys + ("" if self.every is None else f" {self.every:g}")

    @property
    def slug(self) -> str:
        """The label in a folder name: "every0.25", "contacts"."""
        return self.label.replace(" ", "")


@dataclasses.dataclass(frozen=True)
class Pair:
    """One (clip, keying) pair of the corpus. `folder`: its folder name under the output folder; `set`:
    "tuning" or "validation" (`corpus_sets.clip_set`)."""

    clip: Path
    keying: Keying
    folder: str
    set: str


def parse_every(text: str) -> tuple[float, ...]:
    """--every "0.2,0.25,0.33" -> (0.2, 0.25, 0.33) [s]; an argparse type.

    Raises:
        ValueError: naming the bad entry (argparse turns it into a one-line usage error).
    """
    out = []
    for word in (w.strip() for w in text.split(",")):
        try:
            v = float(word)
        except ValueError:
            raise ValueError(f"{text!r}: {word!r} is not a number; give spacings in s, e.g. 0.2,0.25") from None
        if not v > 0:
            raise ValueError(f"{text!r}: {word} is not a positive spacing in s")
        out.append(v)
    return tuple(dict.fromkeys(out))


def parse_keys(text: str) -> tuple[str, ...]:
    """--keys "every,contacts" -> ("every", "contacts"); an argparse type.

    Raises:
        ValueError: an entry not in KEYS.
    """
    names = tuple(dict.fromkeys(w.strip() for w in text.split(",") if w.strip()))
    bad = [n for n in names if n not in KEYS]
    if bad or not names:
        raise ValueError(f"{text!r}: expected a list from {','.join(KEYS)}, e.g. every,contacts")
    return names


def keyings(keys: Sequence[str], every: Sequence[float]) -> list[Keying]:
    """The keyings of a run: each spacing of `every` for "every"; "contacts" once, with no largest gap
    (the acceptance list's `--keys contacts`)."""
    out = [Keying("every", e) for e in every] if "every" in keys else []
    return out + ([Keying("contacts")] if "contacts" in keys else [])


def corpus_pairs(clips: Sequence[Path], keyings_: Sequence[Keying]) -> list[Pair]:
    """Every (clip, keying) pair, clip by clip, with its folder name and set.

    Raises:
        InputError: a clip that cannot be read, or two clips with the same stem (their folders would clash).
    """
    stems: dict[str, Path] = {}
    pairs = []
    for clip in clips:
        other = stems.setdefault(clip.stem.lower(), clip)
        if other != clip:
            raise InputError(f"{clip} and {other}: two clips named {clip.stem}; the corpus names each pair's "
                             "folder by the clip's stem, so rename one")
        try:
            which = clip_set(clip)
        except OSError as e:
            raise InputError(f"{clip}: cannot read ({e.strerror}); give readable .bvh clips") from None
        pairs += [Pair(clip, k, f"{clip.stem}.{k.slug}", which) for k in keyings_]
    return pairs


def pair_options(base: ClipOptions, keying: Keying) -> ClipOptions:
    """`base` with the pair's keying, no video, no summary, quiet."""
    return dataclasses.replace(base, keys=keying.keys, every=keying.every, render=False, summary=False, quiet=True)


def read_pair(pair: Pair, row: dict, folder: Path) -> dict:
    """A pair's result from its batch row and, when it ran, its metrics report and keyframe file:
    {"clip", "keying", "set", "folder", "status", "error", "wall_time_s" (this run's; 0 when skipped),
    "variable_frames", "figures", "checks" (`check_pair`)}."""
    out = {"clip": str(pair.clip), "keying": pair.keying.label, "set": pair.set, "folder": pair.folder,
           "status": row.get("status"), "error": row.get("error") or "", "wall_time_s": row.get("wall_time_s"),
           "variable_frames": row.get("variable_frames"), "figures": {}, "checks": []}
    if row.get("status") not in ("ok", "skipped"):
        return out
    try:
        report = json.loads((folder / f"{pair.clip.stem}.metrics.json").read_text())
        flight = _schedule_flight(folder / f"{pair.clip.stem}.keyframes.json", report)
    except (OSError, ValueError, KeyError, InputError) as e:
        out.update(status="failed", error=f"{folder}: its results cannot be read ({e}); delete the folder and rerun")
        return out
    out["figures"] = pair_figures(report, flight)
    out["checks"] = check_pair(out["figures"])
    return out


def _schedule_flight(keyframes_json: Path, report: dict) -> float | None:
    """The schedule's flight time over the motion metrics' frames (`corpus_bounds.schedule_flight_s`)."""
    from solver.keyframe_file import read_contacts

    doc = json.loads(keyframes_json.read_text())
    motion = report.get("metrics", {}).get("motion", {}).get("plain")
    if motion is None or not doc.get("keyframes"):
        return None
    contacts = read_contacts(doc.get("contacts", []), str(keyframes_json))
    return schedule_flight_s(contacts, motion["sites"], float(doc["keyframes"][0]["time"]), motion["frames"],
                             motion["fps"])


def held_all(result: dict) -> bool:
    """The pair ran and no counted bound was missed ("n/a" bounds and the figures shown beside the bounds,
    `Bound.counted` False, do not count)."""
    return result["status"] in ("ok", "skipped") and all(c["held"] is not False for c in result["checks"]
                                                         if c.get("counted", True))


def held_but_forced(result: dict) -> bool:
    """The pair ran and every counted bound it missed is one no path through its keyframes can hold
    (cause "keyframes force the skate", `corpus_bounds.forced_out_of_reach`)."""
    return result["status"] in ("ok", "skipped") and all(
        c["held"] is not False or FORCED in c["causes"] for c in result["checks"] if c.get("counted", True))


def held_but_certified(result: dict) -> bool:
    """The pair ran and every counted bound it missed is one its keyframes force (`held_but_forced`) or one
    whose constraint the solve certified out of reach: a term of the bound (`Bound.terms`) among the limits
    the least violation raised (the report's "stalled", `Solution.certificate`). The certificate is of the
    constraint as posed, not of the bound's own figure: the bound is put down to it, not proved."""
    certified = set(result.get("figures", {}).get("stalled", ()))
    return result["status"] in ("ok", "skipped") and all(
        c["held"] is not False or FORCED in c["causes"] or set(BOUND_BY_NAME[c["bound"]].terms) & certified
        for c in result["checks"] if c.get("counted", True))


def pass_rates(results: Sequence[dict]) -> dict:
    """{set: {"pairs": n, "held_all": pairs holding every bound, "held_but_forced": pairs holding every bound
    the keyframes leave in reach (`held_but_forced`), "held_but_certified": pairs missing only bounds forced or
    certified out of reach (`held_but_certified`), bound name: [held, checked]}} over the results of each
    set (a pair that did not run holds no bound and counts in "pairs" only)."""
    rates = {}
    for s in SETS:
        rs = [r for r in results if r["set"] == s]
        d = {"pairs": len(rs), "held_all": sum(held_all(r) for r in rs),
             "held_but_forced": sum(held_but_forced(r) for r in rs),
             "held_but_certified": sum(held_but_certified(r) for r in rs)}
        for b in BOUNDS:
            checks = [c for r in rs for c in r["checks"] if c["bound"] == b.name and c["held"] is not None]
            d[b.name] = [sum(bool(c["held"]) for c in checks), len(checks)]
        rates[s] = d
    return rates


def run_corpus(clips: Sequence[Path], out: Path, keyings_: Sequence[Keying], base: ClipOptions, *, workers: int = 1,
               engine: str = "local", ray_address: str | None = None, say: Callable = print,
               quiet: bool = False) -> dict:
    """Solve every pair (a batch), check the bounds, write OUT/corpus.md and OUT/corpus.json.

    Args:
        clips: .bvh files. out: the output folder. keyings_: `keyings(...)`. base: the solve options of
            every pair (`dynsplines mocap`'s; keys, every, render and summary are set per pair).
        workers, engine, ray_address, say, quiet: as `run_batch`.
    Returns:
        {"results" (`read_pair` per pair), "rates" (`pass_rates`), "markdown" (the text of corpus.md),
        "paths" (corpus.md, corpus.json), "batch" (`run_batch`'s result)}.
    Raises:
        InputError: unreadable clips, clashing stems, an unwritable output folder, Ray missing.
    """
    pairs = corpus_pairs(clips, keyings_)
    out = Path(out)
    batch = run_batch([p.clip for p in pairs], out, [pair_options(base, p.keying) for p in pairs], workers=workers,
                      engine=engine, ray_address=ray_address, say=say, quiet=quiet, folders=[p.folder for p in pairs],
                      name="dynsplines bench corpus")
    results = [read_pair(p, row, out / p.folder) for p, row in zip(pairs, batch["rows"], strict=True)]
    rates = pass_rates(results)
    meta = {"out": str(out), "engine": engine, "workers": workers, "wall_time_s": batch["wall_time_s"],
            "interrupted": batch["interrupted"], "keyings": [k.label for k in keyings_],
            "clips": {str(c): {"set": clip_set(c), "sha256": file_sha256(c)} for c in clips}}
    from runner.corpus_report import markdown_report

    text = markdown_report(results, rates, meta)
    paths = (out / "corpus.md", out / "corpus.json")
    with atomic_output(paths[0]) as tmp:
        tmp.write_text(text)
    doc = {**meta, "bounds": [dataclasses.asdict(b) for b in BOUNDS], "causes": CAUSES, "not_told": NOT_TOLD,
           "pairs": results, "rates": rates}
    with atomic_output(paths[1]) as tmp:
        tmp.write_text(json.dumps(doc, indent=1, default=float) + "\n")
    return {"results": results, "rates": rates, "markdown": text, "paths": paths, "batch": batch}
