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


def test_round_efficiency_pairs_the_runs_of_each_round(monkeypatch):
    """--repeat N: the p-rank run of each round against the one-rank run of the same round (the runs are faked: only
    the pairing and the arithmetic are tested).  The fastest runs come from different rounds here, so the usual
    efficiency (4.0 / (2 x 2.5) = 80 %) differs from both rounds' own figures."""
    walls = {1: iter([4.0, 6.0]), 2: iter([3.5, 2.5])}

    def fake_launch(ranks, particles, args):
        wall = next(walls[ranks])
        return {"ranks": ranks, "particles": particles, "wall_seconds": wall, "block_wall_seconds": [wall],
                "positions_checksum": 1.0, "particle_steps_per_second": particles * 10 / wall,
                "work_core_seconds": wall * ranks}

    monkeypatch.setattr(scaling, "launch", fake_launch)
    monkeypatch.setattr(scaling, "core_capacity", lambda cores, rounds: {"capacity": 2.0})
    args = type("Args", (), dict(repeat=2, ranks=[1, 2], particles=1000, per_rank=1000, launcher=None,
                                 busy_reference=False))()
    rows = scaling.study("strong", args)
    assert "efficiency_of_rounds" not in rows[0]
    # Round 1: 4.0 / (2 x 3.5); round 2: 6.0 / (2 x 2.5).  Same arithmetic as the code: equal to the last bit.
    assert rows[1]["efficiency_of_rounds"] == [4.0 / (2 * 3.5), 6.0 / (2 * 2.5)]
    assert abs(rows[1]["efficiency"] - 4.0 / (2 * 2.5)) < 1e-15
