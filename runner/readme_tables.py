"""Measured tables in a Markdown file, between marker comments, regenerated from runs of the code.

    <!-- bench:NAME -->
    | generated | table |
    <!-- /bench:NAME -->

`replace_blocks` writes new blocks; `compare_blocks` checks a file's blocks against freshly generated
ones. A `Block` is Markdown text plus the cells that are machine-dependent figures: wall times, and the
evaluation and frame counts of a solve (an optimizer's path follows the round-off of the CPU's BLAS
kernels: a `--terms all` solve took 850 evaluations here and 1024 with OpenBLAS's Sandybridge kernels,
to the same final E, and ended with 43 frames on one kernel and 38 on another: the refinement places
frames where each subproblem stopped), and an optimized figure that sits inside its constraint's bound
(where in it the solve stops follows the same round-off). Those differ from machine to machine, so
the check skips them. Every other figure is compared within a tolerance, because the same code gives
slightly different figures on another CPU (BLAS kernels, library versions change the round-off, and an
optimizer's path follows it): integers within `COUNT_RTOL`, other numbers within `VALUE_RTOL` or one unit in their last printed
digit, whichever is larger, both relative to the file's figure; the words around them must match exactly, but for a figure's
`WORSE` mark where the figures differ (`lines_agree`). `exact=True` compares every
figure as printed (a manual check on the machine that wrote the tables). `dynsplines bench docs
[--check] [--exact]` (runner/commands/bench.py) runs the workloads and uses these; the tables live in
docs/benchmarks.md.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

from solver.errors import InputError

TIMING = "\x00t"
"""Marks where a table cell's machine-dependent part starts (stripped when written, masked when checked)."""
COUNT_RTOL = 0.10
"""Relative tolerance of an integer figure (evaluations, frames) in `compare_blocks`: 10 %."""
VALUE_RTOL = 0.20
"""Relative tolerance of a decimal figure in `compare_blocks`: 20 % (or one unit in the last printed
digit, whichever is larger: 0.01 against 0.00 passes). An optimized figure follows the optimizer's path,
which another CPU's BLAS kernels change through rounding: the peak root force in flight of `--terms all`
moves 13 % between OpenBLAS's SkylakeX and Sandybridge kernels while the evaluation count moves 3 %.
What the check guards against is a changed result (a flight 43 % longer), not the last digits."""
_BLOCK = re.compile(r"(<!-- bench:(?P<name>[\w-]+) -->\n)(?P<body>.*?)(<!-- /bench:(?P=name) -->)", re.S)
WORSE = " (worse)"
"""The mark of a figure worse than the plain spline's (`runner.console.comparison_rows`)."""
_NUMBER = re.compile(r"(?<![\w.])-?\d+(?:\.\d+)?(?:e[-+]?\d+)?(?![\w.])")


@dataclass
class Block:
    """One generated block: Markdown lines; a cell's part from TIMING on is machine-dependent (`timing`)."""

    name: str
    lines: list[str] = field(default_factory=list)

    def text(self) -> str:
        return "".join(line.replace(TIMING, "") + "\n" for line in self.lines)

    def masked(self) -> list[str]:
        return [_mask_line(line) for line in self.lines]


def timing(text: str) -> str:
    """Mark `text`, the end of a table cell, as machine-dependent (a wall time, a solve's evaluation count)."""
    return TIMING + text


def table(header: list[str], rows: list[list[str]]) -> list[str]:
    """Markdown table lines."""
    out = ["| " + " | ".join(header) + " |", "| " + " | ".join("---" for _ in header) + " |"]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return out


def _mask_line(line: str) -> str:
    """A line with every machine-dependent part of a cell replaced by '*'."""
    return re.sub(re.escape(TIMING) + r"[^|]*", "* ", line).rstrip()


def _mask_against(found: str, expected: str) -> str:
    """`found` (a line of the file) with the cells masked where `expected` (a generated line) has
    wall times; the other cells as they are."""
    if TIMING not in expected:
        return found.rstrip()
    exp_cells, got_cells = expected.split("|"), found.split("|")
    if len(exp_cells) != len(got_cells):
        return found.rstrip()
    cells = []
    for e, g in zip(exp_cells, got_cells, strict=True):
        if TIMING in e:  # a wall time ends its cell: compare what comes before it
            cells.append(g[:e.index(TIMING)] + "* ")
        else:
            cells.append(g)
    return "|".join(cells).rstrip()


def read_blocks(path: Path) -> dict[str, str]:
    """{name: body text} of the file's marked blocks."""
    return {m.group("name"): m.group("body") for m in _BLOCK.finditer(Path(path).read_text(encoding="utf-8"))}


def replace_blocks(path: Path, blocks: list[Block]) -> list[str]:
    """Write the blocks' text between their markers in the file. Returns the names replaced.

    Raises:
        InputError: a block whose markers are not in the file (add them where the table goes)."""
    path = Path(path)
    text = path.read_text(encoding="utf-8")
    names = set(read_blocks(path))
    missing = [b.name for b in blocks if b.name not in names]
    if missing:
        raise InputError(f"{path}: no markers for {', '.join(missing)}; add '<!-- bench:NAME -->' and "
                         "'<!-- /bench:NAME -->' lines where the table goes")
    by_name = {b.name: b for b in blocks}

    def sub(m):
        b = by_name.get(m.group("name"))
        return m.group(0) if b is None else m.group(1) + b.text() + m.group(4)

    new = _BLOCK.sub(sub, text)
    if new != text:
        tmp = path.with_name(f".{path.name}.tmp")
        tmp.write_text(new, encoding="utf-8")
        tmp.replace(path)
    return [b.name for b in blocks]


def _close(found: str, expected: str) -> bool:
    """Whether a printed number of the file (`found`) and the code's (`expected`) agree within the
    stated tolerances (module docstring), relative to the file's figure."""
    f, e = float(found), float(expected)
    if re.fullmatch(r"-?\d+", expected) and re.fullmatch(r"-?\d+", found):
        return abs(f - e) <= max(COUNT_RTOL * abs(f), 1.0)
    mantissas = [s.lower().split("e")[0] for s in (found, expected)]
    decimals = max(len(m.split(".")[1]) if "." in m else 0 for m in mantissas)
    exponent = int(found.lower().split("e")[1]) if "e" in found.lower() else 0
    unit = 10.0 ** (exponent - decimals)
    return abs(f - e) <= max(VALUE_RTOL * abs(f), unit * (1 + 1e-9))


def lines_agree(found: str, expected: str) -> bool:
    """Whether a line of the file (`found`) and a generated line (`expected`, wall times masked in
    both) say the same: the same words, every number within the tolerances (module docstring). A
    `WORSE` mark follows its figure past a threshold (`runner.verdict`), so figures that differ within the
    tolerance may fall either side of it (a flight time of 0.185 s marked, 0.193 s not, under two BLAS
    kernels); figures printed alike must be marked alike."""
    if found == expected:
        return True
    f_nums, e_nums = _NUMBER.findall(found), _NUMBER.findall(expected)
    if f_nums != e_nums:
        found, expected = found.replace(WORSE, ""), expected.replace(WORSE, "")
    if len(f_nums) != len(e_nums) or _NUMBER.split(found) != _NUMBER.split(expected):
        return False
    return all(_close(f, e) for f, e in zip(f_nums, e_nums, strict=True))


def compare_blocks(path: Path, blocks: list[Block], exact: bool = False) -> list[str]:
    """Differences between the file's blocks and freshly generated ones, wall times skipped.

    Args:
        path: the Markdown file with the marked blocks.
        blocks: freshly generated blocks.
        exact: compare every figure as printed instead of within `COUNT_RTOL` / `VALUE_RTOL`.

    Returns:
        one message per block that differs (the first differing line, file vs code), [] if all match.
    """
    found = read_blocks(path)
    problems = []
    for b in blocks:
        if b.name not in found:
            problems.append(f"{path}: no block bench:{b.name}")
            continue
        got = found[b.name].splitlines()
        exp = b.lines
        if len(got) != len(exp):
            problems.append(f"bench:{b.name}: {len(got)} lines in {path}, {len(exp)} generated")
            continue
        for g, e in zip(got, exp, strict=True):
            gm, em = _mask_against(g, e), _mask_line(e)
            if (gm != em) if exact else not lines_agree(gm, em):
                problems.append(f"bench:{b.name}: {path} has\n    {gm}\n  the code gives\n    {em}")
                break
    return problems
