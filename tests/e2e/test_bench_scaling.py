"""`dynsplines bench scaling` with repeats: the lengths alternate, every run of a length takes the same
evaluations (the table's medians are of the same work), and the run-by-run ratio line is printed."""
import re

import pytest

from runner.cli import main


@pytest.mark.slow
def test_bench_scaling_repeats(capsys):
    assert main(["bench", "scaling", "--factors", "1,2", "--repeat", "2"]) == 0
    printed = capsys.readouterr().out
    rows = re.findall(r"^\s+([12])x\s+(\d+)\s+(\d+)\s+(\d+)\s+[\d.]+\s+([\d.]+)\s+(\d+)\s+(\d+)", printed, re.M)
    assert [r[0] for r in rows] == ["1", "2"]
    points = [int(r[3]) for r in rows]
    assert points[1] == 2 * points[0]  # the tiled clip: exactly twice the quadrature points
    assert all(int(r[6]) >= 1 for r in rows)  # a converged solve ends on a refinement check: each length made one
    assert "median of 2 runs per length, the lengths alternating" in printed
    ratios = re.search(r"CPU time 2x / 1x, run by run: ([\d.]+), ([\d.]+) \(median", printed)
    assert ratios and all(0.5 < float(r) < 20 for r in ratios.groups())
    for row in rows:  # penetration 0 and keyframes met at both lengths
        line = next(ln for ln in printed.splitlines() if ln.strip().startswith(f"{row[0]}x"))
        pen, kf_err = re.search(r"\|\s+([\d.]+)\s+(\S+)\s+[\d.]+\s+CONVERGED", line).groups()
        assert float(pen) <= 0.5 and float(kf_err) < 1e-12


def test_bench_scaling_rejects_zero_repeats(capsys):
    assert main(["bench", "scaling", "--repeat", "0"]) != 0
    assert "--repeat must be at least 1" in capsys.readouterr().err
