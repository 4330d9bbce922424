"""`dynsplines bench contacts` on the shipped run-and-step keyframes: both configurations solved in one
process, the CPU-time ratio printed, and the contact terms' effect visible in the metrics it prints
(stated bounds, not the code's own numbers)."""
import re

import pytest

from runner.cli import main


def _row(printed: str, label: str) -> list[float]:
    line = next(ln for ln in printed.splitlines() if ln.strip().startswith(label))
    return [float(x) for x in re.findall(r"-?\d+\.\d+", line[len(label) + 4:])]


@pytest.mark.slow
def test_bench_contacts_on_run_and_step(capsys):
    assert main(["bench", "contacts"]) == 0
    printed = capsys.readouterr().out
    evals = dict(re.findall(r"^\s+(geometric|contacts)\s+(\d+) evaluations\s+[\d.]+ s CPU", printed, re.M))
    assert set(evals) == {"geometric", "contacts"} and all(int(v) > 0 for v in evals.values())
    ratio = float(re.search(r"contacts / geometric: CPU time ([\d.]+)x", printed).group(1))
    assert 0 < ratio < 100
    # the objective-time ratio is the two solves' printed objective times divided (to their rounding)
    objective = dict(re.findall(r"^\s+(geometric|contacts)\s+\d+ evaluations .*?objective ([\d.]+) s", printed, re.M))
    obj_ratio = float(re.search(r"objective time ([\d.]+)x", printed).group(1))
    assert obj_ratio == pytest.approx(float(objective["contacts"]) / float(objective["geometric"]), rel=0.02)
    capture, plain, geometric, contacts = _row(printed, "float in contact [mm]")
    # bound: mean float during contact at most 5 mm, and lower than without the schedule's constraints
    assert contacts <= 5.0 and contacts < geometric
    capture_s, plain_s, _, contacts_s = _row(printed, "skate in contact [mm/frame]")
    assert contacts_s <= capture_s + 0.5 and contacts_s <= plain_s / 2
    pens = re.search(r"contacts ([\d.]+) / (\S+) / ([\d.]+) / ([\d.]+)$", printed, re.M)
    assert float(pens.group(1)) <= 1.0 and float(pens.group(2)) <= 1e-9  # penetration [mm], keyframe error
