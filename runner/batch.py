"""A batch of motion-capture clips: `process_clip` (mocap) or `process_clean` (clean) on each, in worker
processes, resumable, with a summary.

Layout under the output folder DIR:

    DIR/<clip stem>/      process_clip's outputs (keyframes, scene, .npz, metrics JSON, video if asked), or
                          process_clean's (<stem>.clean.npz, .bvh, .glb, .metrics.json, the scene)
    DIR/<clip stem>/done.json   written last, when the clip finished ok: the SHA-256 of the clip's bytes,
                          the options and the clip's summary row; a rerun with the same clip bytes and
                          options skips the clip (if its outputs are still there)
    DIR/summary.csv, DIR/summary.json   one row per clip and a totals row (written atomically); the
                          columns are the mode's: COLUMNS (mocap) or CLEAN_COLUMNS (clean: the cleaned
                          clip's figures, `runner.bench.clean_measure`)

A bad clip (unreadable, another skeleton, a failed optimization) is a row with its one-line error; the
batch goes on. Ctrl-C: no new clips are started, the running ones stop with their best path (their
outputs are written atomically, they are not marked done), the summary of what finished is written.
"""
from __future__ import annotations

import csv
import dataclasses
import hashlib
import io
import json
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from runner.bench.clean_measure import clean_result_figures
from runner.clean import CleanOptions, process_clean
from runner.files import atomic_output, check_writable_dir
from runner.pipeline import ClipOptions, process_clip
from runner.progress import Steps
from solver.errors import InputError

ENGINES = ("local", "ray")
DONE = "done.json"
#: the summary's columns, in order (CSV header; JSON rows have the same keys)
COLUMNS = ("clip", "folder", "status", "error", "wall_time_s", "keyframes", "variable_frames", "solver_status",
           "max_penetration_mm", "plain_float_contact_mm", "optimized_float_contact_mm", "plain_skate_mm",
           "optimized_skate_mm")
#: the summary's columns with `CleanOptions` (`batch --mode clean`): the cleaned clip's penetration [mm], float
#: and skate in contact [mm, mm/frame], deviation from the capture [cm] and of its joint angles [deg], the change's peak accelerations beside
#: the capture's at 6 Hz [m/s^2, rad/s^2] (`runner.bench.clean_measure`), the clean's CPU time [s]
CLEAN_COLUMNS = ("clip", "folder", "status", "error", "wall_time_s", "displacement_frames", "solver_status",
                 "penetration_mm", "sole_mm", "float_mm", "skate_mm", "deviation_mean_cm", "deviation_max_cm", "angle_mean_deg",
                 "angle_max_deg", "change_pelvis_m_s2", "capture_pelvis_m_s2", "change_joint_rad_s2", "capture_joint_rad_s2", "cpu_s")
#: the figures of CLEAN_COLUMNS that the totals row gives as the mean over the clips (the others: the worst)
CLEAN_MEANS = ("deviation_mean_cm", "angle_mean_deg")
#: row statuses: ok (done now), skipped (done before, same clip and options), failed, interrupted (stopped
#: by Ctrl-C, outputs of the best path so far), not run (Ctrl-C came first)
STATUSES = ("ok", "skipped", "failed", "interrupted", "not run")


def find_clips(paths: Sequence[str | Path]) -> list[Path]:
    """The .bvh files named or inside the named folders (not recursive), sorted per folder, no repeats.

    Raises:
        InputError: a path does not exist, or no clip was found.
    """
    clips: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            clips.extend(sorted(f for f in p.iterdir() if f.suffix.lower() == ".bvh" and f.is_file()))
        elif p.is_file():
            clips.append(p)
        else:
            raise InputError(f"{p}: no such clip or folder (current folder: {Path.cwd()}); give .bvh files or folders of them")
    seen, unique = set(), []
    for c in clips:
        if c.resolve() not in seen:
            seen.add(c.resolve())
            unique.append(c)
    if not unique:
        raise InputError(f"no .bvh clips in {', '.join(map(str, paths))}; give .bvh files or folders of them")
    return unique


def clip_folders(clips: Sequence[Path], out: Path) -> list[Path]:
    """One folder per clip under `out`: the clip's stem, "-2", "-3", ... appended when stems repeat."""
    used: dict[str, int] = {}
    folders = []
    for c in clips:
        n = used.get(c.stem.lower(), 0) + 1
        used[c.stem.lower()] = n
        folders.append(out / (c.stem if n == 1 else f"{c.stem}-{n}"))
    return folders


def clip_duration(path: Path) -> float:
    """The clip's length [s] from its BVH header ("Frames: N" times "Frame Time: T"), read without
    parsing the motion; 0 if the header cannot be read (such a clip fails at once when run)."""
    frames = None
    try:
        with open(path, errors="replace") as f:
            for line in f:
                words = line.split()
                if words[:1] == ["Frames:"] and len(words) == 2:
                    frames = int(words[1])
                elif words[:2] == ["Frame", "Time:"] and len(words) == 3 and frames is not None:
                    return max(0.0, frames * float(words[2]))
    except (OSError, ValueError):
        pass
    return 0.0


def longest_first(todo: list, durations: Sequence[float]) -> list:
    """`todo` ordered by decreasing clip duration (ties: the given order): the longest-processing-time
    rule, so that with several workers a long clip does not start last and run alone at the end (a
    clip's solve time grows with its length)."""
    order = sorted(range(len(todo)), key=lambda j: -durations[j])
    return [todo[j] for j in order]


def columns_of(options: ClipOptions | CleanOptions) -> tuple[str, ...]:
    """The summary's columns for a clip run with `options`: COLUMNS (mocap) or CLEAN_COLUMNS (clean)."""
    return CLEAN_COLUMNS if isinstance(options, CleanOptions) else COLUMNS


def options_fingerprint(options: ClipOptions | CleanOptions) -> dict:
    """The options that decide a clip's outputs, as JSON values (not `quiet` or `command`); a clean's has
    "mode": "clean"."""
    d = dataclasses.asdict(options)
    for k in ("quiet", "command"):
        d.pop(k, None)
    if isinstance(options, CleanOptions):
        d["mode"] = "clean"
    return json.loads(json.dumps(d, sort_keys=True, default=str))


def file_sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def read_done(folder: Path, sha: str, fingerprint: dict) -> dict | None:
    """The row recorded in `folder/done.json` if it is for these clip bytes and options and every output it
    lists still exists; else None."""
    try:
        done = json.loads((folder / DONE).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(done, dict) or done.get("clip_sha256") != sha or done.get("options") != fingerprint:
        return None
    outputs = done.get("outputs") or {}
    if not all(Path(p).is_file() for p in outputs.values()):
        return None
    return done.get("row")


def _one_line(e: BaseException) -> str:
    text = " ".join(str(e).split())
    return text if isinstance(e, InputError) else f"{type(e).__name__}: {text}"


def _motion(result: dict, which: str, key: str):
    v = result.get("metrics", {}).get("motion", {}).get(which, {}).get("path", {}).get(key)
    return None if v is None else float(v)


def _mocap_figures(result: dict) -> dict:
    """A mocap row's figures from `process_clip`'s result."""
    opt = result["metrics"]["optimized"]
    return dict(
        wall_time_s=float(result["wall_time_s"]), keyframes=int(result["keyframes"]),
        variable_frames=int(result["variable_frames"]), max_penetration_mm=float(opt["max_penetration_mm"]),
        plain_float_contact_mm=_motion(result, "plain", "float_contact_mm"),
        optimized_float_contact_mm=_motion(result, "optimized", "float_contact_mm"),
        plain_skate_mm=_motion(result, "plain", "skate_mm"), optimized_skate_mm=_motion(result, "optimized", "skate_mm"))


def run_clip(clip: Path, folder: Path, options: ClipOptions | CleanOptions, fingerprint: dict, sha: str) -> dict:
    """Process one clip quietly (a worker's job): `process_clean` with `CleanOptions`, else `process_clip`;
    its summary row; never raises for a bad clip. On success `done.json` is written last (atomically)."""
    t0 = time.perf_counter()
    clean = isinstance(options, CleanOptions)
    row = dict.fromkeys(columns_of(options))
    row.update(clip=str(clip), folder=folder.name)
    try:
        if clean:
            o = dataclasses.replace(options, quiet=True, summary=False)
            result = process_clean(clip, folder, o, say=lambda *a: None)
        else:
            result = process_clip(clip, folder, dataclasses.replace(options, quiet=True), say=lambda *a: None)
        row.update(status=result["exit"], solver_status=result["status"], wall_time_s=time.perf_counter() - t0)
        row.update(clean_result_figures(result) if clean else _mocap_figures(result))
    except KeyboardInterrupt:
        row.update(status="interrupted", error="interrupted (Ctrl-C)", wall_time_s=time.perf_counter() - t0)
        return row
    except Exception as e:  # noqa: BLE001 - any failure of one clip is its row; the batch goes on
        row.update(status="failed", error=_one_line(e), wall_time_s=time.perf_counter() - t0)
        return row
    if result["exit"] == "failed":
        row["error"] = f"the optimization failed ({result['status']}); the best path before it was written"
    elif result["exit"] == "interrupted":
        row["error"] = "interrupted (Ctrl-C); the best path so far was written"
    else:
        outputs = result["outputs"]
        if clean:  # a clean lists the fitted scene's path, not written with a given --scene
            outputs = {k: v for k, v in outputs.items() if Path(v).is_file()}
        done = {"clip": str(clip), "clip_sha256": sha, "options": fingerprint, "outputs": outputs, "row": row}
        with atomic_output(folder / DONE) as tmp:
            tmp.write_text(json.dumps(done, indent=1) + "\n")
    return row


def totals(rows: list[dict], wall_time_s: float, columns: Sequence[str] = COLUMNS) -> dict:
    """The totals row: counts per status, the batch's wall time, and for mocap (COLUMNS) summed keyframes
    and variable frames, the worst penetration and the mean float/skate over the clips that have them; for
    clean (CLEAN_COLUMNS) the summed displacement frames and CPU time, the mean of CLEAN_MEANS and the
    worst (largest) of every other figure."""
    def values(k):
        return [r[k] for r in rows if r.get(k) is not None]

    def mean(k):
        v = values(k)
        return sum(v) / len(v) if v else None

    counts = {s: sum(r["status"] == s for r in rows) for s in STATUSES}
    t = dict.fromkeys(columns)
    t.update(clip="TOTAL", folder=f"{len(rows)} clips",
             status=", ".join(f"{n} {s}" for s, n in counts.items() if n),
             error=f"{counts['failed']} failed" if counts["failed"] else "", wall_time_s=wall_time_s)
    if columns == CLEAN_COLUMNS:
        for k in CLEAN_COLUMNS[CLEAN_COLUMNS.index("penetration_mm"):]:
            t[k] = mean(k) if k in CLEAN_MEANS else max(values(k), default=None)
        t.update(displacement_frames=sum(values("displacement_frames")), cpu_s=sum(values("cpu_s")), counts=counts)
        return t
    t.update(keyframes=sum(values("keyframes")), variable_frames=sum(values("variable_frames")),
             max_penetration_mm=max(values("max_penetration_mm"), default=None))
    for k in ("plain_float_contact_mm", "optimized_float_contact_mm", "plain_skate_mm", "optimized_skate_mm"):
        t[k] = mean(k)
    t["counts"] = counts
    return t


def write_summary(out: Path, rows: list[dict], total: dict, meta: dict,
                  columns: Sequence[str] = COLUMNS) -> tuple[Path, Path]:
    """DIR/summary.csv (`columns`, a row per clip, then the totals row) and DIR/summary.json, atomically."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=columns, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in [*rows, total]:
        w.writerow({k: ("" if r.get(k) is None else f"{r[k]:.6g}" if isinstance(r[k], float) else r[k])
                    for k in columns})
    paths = (out / "summary.csv", out / "summary.json")
    with atomic_output(paths[0]) as tmp:
        tmp.write_text(buf.getvalue())
    with atomic_output(paths[1]) as tmp:
        tmp.write_text(json.dumps({**meta, "clips": rows, "totals": total}, indent=1) + "\n")
    return paths


def _ignore_sigint():
    """A local worker's start: Ctrl-C (sent to the whole process group) does not kill it; inside the solve
    `process_clip`'s own handler still stops the optimization with its best path."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _single_threaded() -> bool:
    """True on Linux when this process runs one thread (none of numpy's, MuJoCo's or a progress bar's):
    then the local engine forks its workers, which start at once with everything imported; otherwise
    (another thread could hold a lock the child would inherit) they are spawned, and each new
    interpreter imports numpy, scipy, MuJoCo and the solver first (~1.2 s of a 10 s batch of the three
    shipped clips on 2 quiet cores)."""
    import sys

    if not sys.platform.startswith("linux"):
        return False
    try:
        return len(os.listdir("/proc/self/task")) == 1
    except OSError:
        return False


def _submitter(engine: str, workers: int, ray_address: str | None):
    """(submit(fn, *args) -> handle, wait(handles) -> (done, pending), result(handle), cancel_all, close)."""
    if engine == "local":
        import multiprocessing
        from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

        method = "fork" if _single_threaded() else "spawn"
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context(method),
                                   initializer=_ignore_sigint)
        if method == "fork":  # fork every worker now, while this process still has one thread
            pool.submit(int).result()

        def close(cancel):
            pool.shutdown(wait=not cancel, cancel_futures=cancel)

        return (pool.submit, lambda hs: wait(hs, return_when=FIRST_COMPLETED), lambda h: h.result(),
                lambda hs: [h.cancel() for h in hs], close)
    try:
        import ray
    except ImportError:
        raise InputError('--engine ray needs Ray: pip install -e ".[cluster]"') from None
    # a local Ray (no address) gets `workers` CPUs: at most that many clips at once, as with --engine local,
    # and workers at the priority of the local engine's: Ray starts its workers at niceness 15, and on a
    # machine shared with other work such a worker got a fraction of a core (a clip ~7x slower)
    local = {} if ray_address else {"num_cpus": workers, "_system_config": {"worker_niceness": 0}}
    ray.init(address=ray_address, ignore_reinit_error=True, log_to_driver=False, **local)
    remote = ray.remote(num_cpus=1)(run_clip)

    def wait_ray(hs):  # with a timeout: a blocked ray.wait would not see Ctrl-C until a clip finished
        done, pending = ray.wait(list(hs), num_returns=1, timeout=0.5)
        return set(done), set(pending)

    def cancel_ray(hs):
        for h in hs:
            ray.cancel(h)

    return (lambda fn, *a: remote.remote(*a), wait_ray, ray.get, cancel_ray, lambda cancel: ray.shutdown())


@dataclasses.dataclass
class _Plan:
    """What a batch will do: per clip its options, fingerprint, folder and row (set for the clips that
    are done before anything runs: skipped or unreadable), and the clips to run, longest first."""

    clips: list[Path]
    per_clip: list[ClipOptions | CleanOptions]
    prints: list[dict]
    folders: list[Path]
    rows: list[dict | None]
    todo: list[tuple[int, Path, Path, str]]

    @property
    def skipped(self) -> int:
        return sum(r is not None and r["status"] == "skipped" for r in self.rows)

    @property
    def columns(self) -> tuple[str, ...]:
        """The summary's columns: the first clip's mode's (`columns_of`)."""
        return columns_of(self.per_clip[0]) if self.per_clip else COLUMNS

    def failed_row(self, i: int, error: str, status: str = "failed") -> dict:
        row = dict.fromkeys(columns_of(self.per_clip[i])) | dict(clip=str(self.clips[i]), folder=self.folders[i].name,
                                            status=status, error=error)
        return row | {"wall_time_s": 0.0} if status == "failed" else row


def _plan(clips: Sequence[Path], out: Path, options, folders: Sequence[str] | None) -> _Plan:
    """The clips' options, folders and done rows (`read_done`); raises ValueError on mismatched lengths."""
    per_clip = [options] * len(clips) if isinstance(options, ClipOptions | CleanOptions) else list(options)
    if len(per_clip) != len(clips) or (folders is not None and len(folders) != len(clips)):
        raise ValueError(f"{len(clips)} clips, {len(per_clip)} options, {len(folders or clips)} folders")
    paths = clip_folders(clips, out) if folders is None else [out / f for f in folders]
    plan = _Plan(list(clips), per_clip, [options_fingerprint(o) for o in per_clip], paths, [None] * len(clips), [])
    for i, (clip, folder) in enumerate(zip(clips, paths)):
        try:
            sha = file_sha256(clip)
        except OSError as e:
            plan.rows[i] = plan.failed_row(i, f"{clip}: cannot read ({e.strerror})")
            continue
        done = read_done(folder, sha, plan.prints[i])
        if done is not None:
            plan.rows[i] = {**done, "status": "skipped", "wall_time_s": 0.0}
        else:
            plan.todo.append((i, clip, folder, sha))
    plan.todo = longest_first(plan.todo, [clip_duration(t[1]) for t in plan.todo])
    return plan


class _Tracker:
    """Records finished clips into the plan's rows and shows them above the progress bar."""

    def __init__(self, plan: _Plan, bar, say: Callable):
        self.plan, self.bar, self.say = plan, bar, say
        self.t0 = time.perf_counter()
        self.interrupted = False

    def note(self) -> None:
        rows = self.plan.rows
        n_done = sum(r is not None for r in rows)
        failed = sum(r is not None and r["status"] == "failed" for r in rows)
        ran, left = n_done - self.plan.skipped, len(rows) - n_done
        elapsed = time.perf_counter() - self.t0
        eta = f", ETA {elapsed / ran * left:.0f} s" if ran and left else ""
        self.bar.update(n_done, f"{failed} failed, {left} left, {elapsed:.0f} s{eta}")

    def finished(self, i: int, row: dict) -> None:
        self.plan.rows[i] = row
        name = Path(row["clip"]).name
        name = row["folder"] if row.get("folder") and row["folder"] != Path(row["clip"]).stem else name
        msg = f"  {name}: {row['status']}, {row['wall_time_s']:.1f} s"
        msg += f": {row['error']}" if row.get("error") else ""
        (self.bar.bar.write if self.bar.bar is not None else self.say)(msg)  # above a terminal's bar
        self.interrupted |= row["status"] == "interrupted"
        self.note()


def _run_here(plan: _Plan, track: _Tracker) -> None:
    """The clips one after the other in this process (no start-up cost); stops at an interrupted clip."""
    for i, clip, folder, sha in plan.todo:
        track.finished(i, run_clip(clip, folder, plan.per_clip[i], plan.prints[i], sha))
        if track.interrupted:
            return


def _run_pool(plan: _Plan, track: _Tracker, workers: int, pool: tuple, say: Callable) -> None:
    """The clips on `pool` (`_submitter`'s five functions), at most `workers` in flight, so that after
    Ctrl-C none is queued to start; the running ones then keep their best path."""
    submit, wait, result, cancel, close = pool
    queue, handles, pending = iter(plan.todo), {}, set()

    def hand_out():
        while len(pending) < workers and not track.interrupted:
            nxt = next(queue, None)
            if nxt is None:
                return
            i = nxt[0]
            h = submit(run_clip, nxt[1], nxt[2], plan.per_clip[i], plan.prints[i], nxt[3])
            handles[h] = i
            pending.add(h)

    def drain(stopping: bool) -> None:
        """Record clips as they finish, handing out the next; with `stopping` (after Ctrl-C) a
        cancelled or dead clip stays "not run"."""
        while pending:
            done, still = wait(pending)
            pending.clear()
            pending.update(still)
            for h in done:
                try:
                    row = result(h)
                except KeyboardInterrupt:
                    raise
                except BaseException as e:  # noqa: BLE001 - a worker that died: the clip's row
                    if stopping:
                        continue
                    row = plan.failed_row(handles[h], _one_line(e))
                track.finished(handles[h], row)
            hand_out()

    try:
        hand_out()
        drain(stopping=False)
        close(False)
    except KeyboardInterrupt:
        track.interrupted = True
        cancel(pending)
        say("stopping: no new clips; waiting for the running ones to keep their best path "
            "(Ctrl-C again to stop waiting)")
        try:
            drain(stopping=True)
        except KeyboardInterrupt:
            pass
        close(True)


def run_batch(clips: Sequence[Path], out: Path, options: ClipOptions | CleanOptions | Sequence, *, workers: int = 1,
              engine: str = "local", ray_address: str | None = None, say: Callable = print, quiet: bool = False,
              folders: Sequence[str] | None = None, name: str = "dynsplines batch") -> dict:
    """Run `run_clip` on every clip not already done (see the module docstring).

    Args:
        clips: the .bvh files; one may come several times with different options (`bench corpus`).
        out: the output folder. options: one ClipOptions (mocap) or CleanOptions (clean) for all, or one per
            clip (the summary's columns are the first clip's mode's: `columns_of`).
        workers, engine, ray_address: where the clips run (`dynsplines batch --help`).
        folders: each clip's folder name under `out` [`clip_folders`: the stems, made unique].
        name: what the first line calls the run.
    Returns:
        {"rows" (`columns_of` per clip, in the clips' order), "totals", "interrupted", "summary" (the two paths),
        "wall_time_s"}.
    Raises:
        InputError: `out` is not writable; --engine ray without Ray installed.
    """
    t0 = time.perf_counter()
    out = Path(out)
    check_writable_dir(out / "summary.json", "--out")
    plan = _plan(clips, out, options, folders)
    say(f"{name}: {len(clips)} clips -> {out}: {plan.skipped} already done, {len(plan.todo)} to run "
        f"({engine}, {workers} worker{'s' if workers != 1 else ''})")
    serial = engine == "local" and workers == 1
    # workers start before the progress bar (whose monitor thread would rule out forking them)
    pool = _submitter(engine, workers, ray_address) if plan.todo and not serial else None
    with Steps("clips", len(clips), quiet, unit=" clips") as bar:
        track = _Tracker(plan, bar, say)
        track.note()
        if plan.todo and serial:
            _run_here(plan, track)
        elif plan.todo:
            _run_pool(plan, track, workers, pool, say)
    rows = [r if r is not None else plan.failed_row(i, "not started: the batch was interrupted", "not run")
            for i, r in enumerate(plan.rows)]
    wall = time.perf_counter() - t0
    total = totals(rows, wall, plan.columns)
    one = isinstance(options, ClipOptions | CleanOptions)
    meta = {"out": str(out), "engine": engine, "workers": workers, "interrupted": track.interrupted,
            "wall_time_s": wall, "options": plan.prints[0] if one else plan.prints}
    summary = write_summary(out, rows, total, meta, plan.columns)
    return {"rows": rows, "totals": total, "interrupted": track.interrupted, "summary": summary,
            "wall_time_s": wall}
