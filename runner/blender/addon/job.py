"""The `dynsplines` command run outside Blender's Python: the commands of one solve, run one after the
other in subprocesses, their output read by threads so that Blender's UI never waits on a pipe.

A job is `mocap` (the keyframes, the solve, the saved path) then `export` (the saved path back onto the
armature's skeleton as BVH). Cancelling sends the running command SIGINT, as Ctrl-C does: `mocap` then
writes the best path so far (exit 130) and the export still runs, so a cancelled solve returns a valid
action. The user-facing error is the command's own one line ("dynsplines: error: ...").
"""
import os
import re
import shutil
import signal
import subprocess
import sys
import threading

#: exit codes of `dynsplines` after which its saved path is there to export: 0 done, 3 failed partway
#: (the best path before it written), 130 interrupted (the best path so far written)
WROTE_PATH = (0, 3, 130)
_ROUND = re.compile(r"round (\d+)")
_WARNING = re.compile(r"\s*(?:dynsplines: )?warning: (.+?)\s*$")


class JobError(Exception):
    """A command of the job failed; the message is the command's own one line."""


def find_cli(path):
    """The `dynsplines` executable: `path` (the add-on's preference) if given, else found on PATH.

    Raises:
        JobError: not found (the message says where to set it).
    """
    if path:
        path = os.path.expanduser(path)
        if os.path.isfile(path) and os.access(path, os.X_OK):
            return path
        raise JobError(f"dynsplines: the command {path} (add-on preferences) is not an executable file; give the "
                       "path of the installed `dynsplines` (e.g. .venv/bin/dynsplines)")
    found = shutil.which("dynsplines")
    if found is None:
        raise JobError("dynsplines: the `dynsplines` command is not on PATH; install it (pip install dynsplines, "
                       "README) or give its path in the add-on's preferences")
    return found


def last_error(text, code):
    """The one line a failed command printed ("dynsplines: error: ..."), else its last line."""
    lines = [ln.strip() for ln in re.split(r"[\r\n]+", text) if ln.strip()]
    errors = [ln for ln in lines if ln.startswith("dynsplines:") and "error" in ln]
    if errors:
        return errors[-1]
    return lines[-1] if lines else f"dynsplines: the command stopped with exit code {code}"


def warning_lines(text):
    """[str] the warnings a command printed ("warning: ..." or "dynsplines: warning: ..."), each once, in order,
    as "dynsplines: warning: ..." (an assumed length unit, a solve that failed partway: what the user must know
    about a result that still comes back)."""
    out = []
    for ln in re.split(r"[\r\n]+", text):
        m = _WARNING.match(ln)
        if m and f"dynsplines: warning: {m.group(1)}" not in out:
            out.append(f"dynsplines: warning: {m.group(1)}")
    return out


class Job:
    """Runs `commands` ([(label, argv)]) one after the other, each after the last one succeeded.

    Poll with `poll()` (non-blocking; returns True when every command finished) or run to the end with
    `run()` (blocking, background mode). `status` is the latest line of output, `rounds` the solve rounds
    seen so far, `warnings` what the finished commands warned of; `cancel()` interrupts the running command
    (SIGINT; Windows: terminate).
    """

    def __init__(self, commands, cwd):
        self.commands, self.cwd = list(commands), cwd
        self.index, self.proc, self.status, self.rounds = -1, None, "starting", 0
        self.cancelled, self.error, self._out, self._threads = False, None, [], []
        self.codes = []  # the exit code of each command that finished
        self.warnings = []  # `warning_lines` of the commands that finished

    @property
    def label(self):
        return self.commands[self.index][0] if 0 <= self.index < len(self.commands) else ""

    def _start_next(self):
        self.index += 1
        label, argv = self.commands[self.index]
        self._out = []
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        self.proc = subprocess.Popen(argv, cwd=self.cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL, env=env)
        reader = threading.Thread(target=self._read, args=(self.proc.stdout,), daemon=True)
        reader.start()
        self._threads = [reader]
        self.status = label

    def _read(self, stream):
        for raw in iter(lambda: stream.read1(4096) if hasattr(stream, "read1") else stream.read(4096), b""):
            text = raw.decode("utf-8", "replace")
            self._out.append(text)
            for line in re.split(r"[\r\n]+", text):
                if line.strip():
                    self.status = line.strip()[:160]
                    if m := _ROUND.search(line):
                        self.rounds = max(self.rounds, int(m.group(1)))

    def poll(self):
        """Start or advance the job; True when it is over (done, failed: `error`, or cancelled)."""
        if self.error is not None:
            return True
        if self.proc is None:
            self._start_next()
            return False
        code = self.proc.poll()
        if code is None:
            return False
        for t in self._threads:
            t.join()
        self.codes.append(code)
        self.warnings += [w for w in warning_lines("".join(self._out)) if w not in self.warnings]
        if code not in (WROTE_PATH if self.index == 0 else (0,)):
            self.error = last_error("".join(self._out), code)
            return True
        if self.index + 1 >= len(self.commands):
            return True
        self._start_next()
        return False

    def run(self):
        """Run every command to the end (blocking). Raises JobError on a failed command."""
        while not self.poll():
            if self.proc is not None:
                self.proc.wait()
        if self.error is not None:
            raise JobError(self.error)

    def cancel(self):
        """Interrupt the running command: the solve keeps its best path so far (exit 130)."""
        self.cancelled = True
        if self.proc is not None and self.proc.poll() is None:
            if sys.platform == "win32":
                self.proc.terminate()
            else:
                self.proc.send_signal(signal.SIGINT)

    def output(self):
        """What the running (or last) command printed so far."""
        return "".join(self._out)
