"""The scaling workload (runner.bench.scaling): the tiled gait is exact copies; the cost's growth with
length is measured by `dynsplines bench scaling` (docs/scaling.md), not asserted here."""

import numpy as np
import pytest

from runner.bench.scaling import FIGURE, floor_model, tile_keyframes
from solver.keyframe_file import read_keyframes
from solver.layout import StateLayout


def gait():
    model = floor_model()
    layout = StateLayout.from_model(model)
    keyframes, _ = read_keyframes(FIGURE.parent / "run_and_step.keyframes.json", layout)
    return model, layout, keyframes


def test_tiled_keyframes_are_copies_carried_forward():
    _, _, kf = gait()
    t3 = tile_keyframes(kf, 3)
    k, span = kf.count, kf.times[-1] - kf.times[0]
    disp = kf.values[-1, :2] - kf.values[0, :2]
    assert t3.count == 3 * (k - 1) + 1
    np.testing.assert_allclose(t3.times[-1] - t3.times[0], 3 * span, rtol=1e-14)
    copy2 = t3.values[2 * (k - 1):3 * (k - 1) + 1].copy()
    copy2[:, :2] -= 2 * disp
    np.testing.assert_allclose(copy2, kf.values, atol=1e-12)
    np.testing.assert_array_equal(t3.mask[k - 1:2 * (k - 1)], kf.mask[:-1])


def _row(factor, repeat, cpu, evals=100):
    return {"factor": factor, "repeat": repeat, "cpu_s": cpu, "wall_s": cpu + 0.5, "obj_cpu_s": cpu / 2,
            "peak_mb": 10.0 * factor + repeat, "evals": evals}


def test_median_rows_and_repeat_ratios():
    from runner.bench.scaling import median_rows, repeat_ratios

    rows = [_row(1, 0, 1.0), _row(8, 0, 9.0), _row(1, 1, 2.0), _row(8, 1, 16.0), _row(1, 2, 1.5), _row(8, 2, 11.0)]
    med = median_rows(rows)
    assert [m["factor"] for m in med] == [1, 8] and [m["repeats"] for m in med] == [3, 3]
    assert med[0]["cpu_s"] == 1.5 and med[1]["cpu_s"] == 11.0  # medians of (1, 2, 1.5) and (9, 16, 11)
    assert med[1]["wall_s"] == 11.5 and med[1]["peak_mb"] == 81.0 and med[1]["evals"] == 100
    # run by run: 9/1, 16/2, 11/1.5 (each 8x next to its own 1x)
    np.testing.assert_allclose(repeat_ratios(rows, 8, 1), [9.0, 8.0, 11.0 / 1.5])
    with pytest.raises(RuntimeError, match="different evaluation counts"):
        median_rows([_row(1, 0, 1.0, evals=100), _row(1, 1, 1.0, evals=101)])
