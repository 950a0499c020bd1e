"""The scaling benchmark's estimators (benchmarks/scaling.py): block times, the block floor and the core capacity."""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import scaling  # noqa: E402


def test_block_seconds_cover_the_timed_window_in_blocks():
    block = scaling.WAITING_BLOCK_STEPS
    steps = 2 * block + block // 2  # a shorter last block
    starts = 10.0 + 0.001 * np.arange(steps) ** 1.5  # steps of growing length
    end = starts[-1] + 0.5
    blocks = scaling.block_seconds(starts, end)
    assert len(blocks) == 3
    assert blocks[0] == starts[block] - starts[0]
    assert blocks[2] == end - starts[2 * block]
    # The blocks tile the window: their sum is its length up to round-off of three subtractions.
    assert abs(sum(blocks) - (end - starts[0])) < 1e-12


def test_block_floor_takes_each_blocks_fastest_run():
    runs = [[1.0, 3.0, 2.0],
            [2.0, 1.0, 2.5],
            [1.5, 2.0, 0.5]]
    assert scaling.floor_seconds(runs) == 1.0 + 1.0 + 0.5
    # Never above the fastest whole run, equal to it when one run is fastest in every block.
    assert scaling.floor_seconds(runs) <= min(sum(run) for run in runs)
    assert scaling.floor_seconds([[1.0, 1.0], [2.0, 3.0]]) == 2.0


def test_core_capacity_sums_alone_over_together_per_round(monkeypatch):
    """The machine probe (benchmarks/core_capacity.py): per round, the sum over the cores of the loop's time alone
    over its time with all cores busy, and the median of the rounds (the loop is shortened: only the
    bookkeeping is tested; the machine's figure is not asserted)."""
    import core_capacity

    monkeypatch.setattr(core_capacity, "LOOP_ITERATIONS", 200_000)
    result = core_capacity.core_capacity(1, rounds=3)
    alone = np.array(result["alone_seconds"])
    together = np.array(result["together_seconds"])
    assert alone.shape == together.shape == (3, 1) and np.all(alone > 0) and np.all(together > 0)
    assert np.allclose(result["capacity_of_rounds"], (alone / together).sum(axis=1), rtol=0, atol=1e-15)
    assert result["capacity"] == float(np.median(result["capacity_of_rounds"]))
