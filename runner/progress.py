"""Progress on the console: tqdm bars on a terminal, plain lines otherwise, and Ctrl-C during an
optimization (the tables are `runner.console`)."""
from __future__ import annotations

import signal
import sys
import time


class StopRequest:
    """Ctrl-C during the optimization sets a flag (the solver returns its best path); a second
    Ctrl-C aborts at once."""

    def __init__(self, quiet=False):
        self.requested = False
        self.quiet = quiet

    def __enter__(self):
        self._old = signal.signal(signal.SIGINT, self._handle)
        return self

    def __exit__(self, *exc):
        signal.signal(signal.SIGINT, self._old)

    def _handle(self, signum, frame):
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True
        print("\nstopping: keeping the best path so far (Ctrl-C again to abort)", file=sys.stderr, flush=True)

    def __call__(self) -> bool:
        return self.requested


#: [s] off a terminal, a running round or task prints a "(still ...)" line at most this often
QUIET_INTERVAL = 5.0


def _bar(stream, **kw):
    """A tqdm bar on `stream` (a terminal), redrawn at most 10 times a second."""
    from tqdm import tqdm

    return tqdm(file=stream, mininterval=0.1, dynamic_ncols=True, leave=True, **kw)


class Progress:
    """Progress of an optimization (`solver.paper.solve`'s progress callback).

    On a terminal: a tqdm bar per round (evaluations, the current value of Phi, elapsed time). Off a terminal
    (a log, a pipe): one line when a round ends; a round still running after `QUIET_INTERVAL` seconds first
    prints that it started, then at most one line every `QUIET_INTERVAL` seconds, worded "(still optimizing)"
    so it does not read as a new round. A round of the least change ends with its worst constraint ("worst
    flight wrench 10.9 x tol": the constraint the solve is fighting, met at <= 1). The least violation a
    round's end may seek (`solver.feasibility`) shows the same way, with F, the violation it minimizes, in
    place of Phi, and the line of what it raised after it. `quiet`: nothing.

    Phi is the value the least change's subproblems minimize, the augmented Lagrangian (`solver.lagrangian`):
    the change E = D / (m g^2 T) plus the multipliers' and the penalty's terms, which can make it negative;
    the summary's E is the change alone.
    """

    def __init__(self, quiet=False, stream=None, interval=QUIET_INTERVAL):
        self.quiet, self.stream = quiet, sys.stdout if stream is None else stream
        self.tty = self.stream.isatty()
        self.interval = interval
        self.t0 = self.last = time.perf_counter()
        self.round = None  # {"round", "frames", "variable", "evals0", "t0"} of the running round
        self.evals, self.E = 0, None
        self.bar = None

    def _line(self, text):
        self.stream.write(text + "\n")
        self.stream.flush()

    def _E(self):
        if self.round is not None and self.round.get("search"):  # the least violation's F, not Phi
            return "F -" if self.round.get("F") is None else f"F {self.round['F']:.6g}"
        return "Phi -" if self.E is None else f"Phi {self.E:.6g}"

    def _short(self):
        """The running round's name in its later lines: "round N", or "least violation"."""
        return "least violation" if self.round["search"] else f"round {self.round.get('round', 0) + 1}"

    def _head(self):
        r = self.round
        if r.get("search"):
            after = "from the start" if r.get("round", 0) < 0 else f"after round {r.get('round', 0) + 1}"
            return f"least violation {after}: from {r.get('frames', 0)} frames"
        return f"round {r.get('round', 0) + 1}: {r.get('frames', 0)} frames ({r.get('variable', 0)} variable)"

    def __call__(self, event, info):
        if self.quiet:
            return
        if event in ("round", "search"):  # a subproblem round, or the least violation sought after one
            self._end_round()
            self.round = {**info, "evals0": self.evals, "t0": time.perf_counter(), "said": False,
                          "search": event == "search"}
            if self.tty:
                self.bar = _bar(self.stream, desc="  " + self._head(), unit=" evals")
            else:
                self.last = time.perf_counter()
        elif event == "eval":
            self.evals = info.get("evals", self.evals)
            self.E = info.get("E", self.E)
            if self.round is not None and "F" in info:
                self.round["F"] = info["F"]
            if self.bar is not None:
                self.bar.update(self.evals - self.round["evals0"] - self.bar.n)
                self.bar.set_postfix_str(self._E(), refresh=False)
            elif self.round is not None and time.perf_counter() - self.last >= self.interval:
                self.last = time.perf_counter()
                if not self.round["said"]:  # a long round: say when it started
                    self.round["said"] = True
                    self._line(f"  {self._head()}: started, {self.round['t0'] - self.t0:.1f} s")
                self._line(f"  {self._short()} (still optimizing): "
                           f"{self.evals - self.round['evals0']} evaluations, {self._E()}, "
                           f"{self.last - self.t0:.1f} s")
        elif event == "constraints" and self.round is not None:  # after a subproblem: the worst constraint
            self.round["worst"] = f"worst {info['worst']} {info['value']:.3g} x tol" if info.get("worst") else ""
        elif event == "certify":  # a frame set ended with a constraint broken: the least violation was sought
            self._end_round()
            self.evals = info.get("evals", self.evals)
            raised = info.get("raised") or {}
            what = ("every constraint can be met, nothing raised" if not raised else
                    ("out of reach from this start (sought again after the rounds, from two starts)" if info["round"] < 0
                     else "out of reach, limits raised") + " by [SI]: " + ", ".join(f"{k} {v:.3g}" for k, v in raised.items()))
            when = "start" if info["round"] < 0 else f"round {info['round'] + 1}"
            self._line(f"  {when}: least violation sought ({info.get('spent', 0)} evaluations, "
                       f"{info.get('frames', 0)} frames): {what}")
        elif event == "kept":  # a clean's later search certified some column beyond the first's: the first's kept
            self._line("  the first search's certificate kept: the search after the rounds raised "
                       + ", ".join(f"{k} by {v:.3g}" for k, v in info["worse"].items()) + " [SI] beyond it")
        elif event == "finer":  # limits were raised: the least violation sought at a finer spacing checks them
            self._end_round()
            self._line(f"  limits raised: the least violation sought again at {info['rate']:g} points/s (segments down "
                       f"to {1e3 * info['segment']:.3g} ms), from the path found")
        elif event == "estimate":  # after a round: what refinement still predicts (SolveOptions.tol)
            self._end_round()
            tol = f" (tol {info['tol']:g})" if info.get("tol") else ""
            self._line(f"  round {info['round'] + 1}: refinement estimate {info['estimate']:.3g} of Phi{tol}")

    def _end_round(self):
        if self.round is None:
            return
        worst = f", {self.round['worst']}" if self.round.get("worst") else ""
        if self.bar is not None:
            self.bar.set_postfix_str(self._E() + worst, refresh=False)
            self.bar.close()
            self.bar = None
        else:
            r = self.round
            head = self._short() if r["said"] else self._head()
            self._line(f"  {head}: done, {self.evals - r['evals0']} evaluations, {self._E()}"
                       f"{worst}, {time.perf_counter() - r['t0']:.1f} s")
        self.round = None

    def done(self):
        """The optimization ended: close the running round."""
        if not self.quiet:
            self._end_round()


class Steps:
    """Progress of a task of `total` steps (frames to render, files to export, stages of an import):
    a tqdm bar on a terminal; off a terminal a line when it starts, at most one every `QUIET_INTERVAL`
    seconds "(still ...)", and one when it ends; nothing when `quiet`. Use as a context manager;
    `update(i)` sets the steps done so far."""

    def __init__(self, desc, total, quiet=False, stream=None, unit=" steps", interval=QUIET_INTERVAL):
        self.desc, self.total, self.quiet, self.unit = desc, int(total), quiet, unit
        self.stream = sys.stdout if stream is None else stream
        self.tty = self.stream.isatty()
        self.interval, self.done_steps, self.bar = interval, 0, None

    def __enter__(self):
        self.t0 = self.last = time.perf_counter()
        if self.quiet:
            return self
        if self.tty:
            self.bar = _bar(self.stream, desc="  " + self.desc, total=self.total, unit=self.unit)
        else:
            self._line(f"  {self.desc}: 0/{self.total}")
        return self

    def _line(self, text):
        self.stream.write(text + "\n")
        self.stream.flush()

    def update(self, done, note=None):
        self.done_steps = done
        if self.quiet:
            return
        if self.bar is not None:
            if note is not None:
                self.bar.set_postfix_str(note, refresh=False)
            self.bar.update(done - self.bar.n)
        elif done < self.total and time.perf_counter() - self.last >= self.interval:
            self.last = time.perf_counter()
            self._line(f"  {self.desc} (still working): {done}/{self.total}"
                       f"{f' ({note})' if note else ''}, {self.last - self.t0:.1f} s")

    def __exit__(self, *exc):
        if self.quiet:
            return
        if self.bar is not None:
            self.bar.close()
        elif exc[0] is None:
            self._line(f"  {self.desc}: {self.done_steps}/{self.total} done, {time.perf_counter() - self.t0:.1f} s")
