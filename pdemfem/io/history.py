"""history.csv: one row of scalars per output interval, written by rank 0.

Each row is written and flushed whole, so an interrupted run leaves a file
whose every line is complete.
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from pdemfem import state_dict as kinds


class HistoryWriter:
    def __init__(self, path: Path, columns: list, is_writer: bool, append: bool = False):
        self.path = Path(path)
        self.columns = list(columns)
        self.is_writer = is_writer
        self._file = None
        if is_writer:
            exists = append and self.path.exists()
            self._file = open(self.path, "a" if exists else "w", newline="")
            self._writer = csv.writer(self._file)
            if not exists:
                self._writer.writerow(self.columns)
                self._file.flush()

    def write(self, values: dict) -> None:
        if self._file is None:
            return
        # A column this run does not write (kept from the run it continues): nan.
        row = [values.get(name, np.nan) for name in self.columns]
        self._writer.writerow([value if isinstance(value, int) else repr(float(value)) for value in row])
        self._file.flush()

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


class IntervalMean(kinds.StateComponent):
    """The mean of a quantity over the steps since it was last taken (a history row's output interval).

    `add` once per step; `take` returns the mean and starts the next interval.  Taken again with no
    step in between (two rows at one step), it repeats the last mean; before any step it returns
    `fallback` (the value now).  `take(..., restart=False)` (a row off the output schedule: the end, a
    stop) returns the mean so far and keeps the interval going, so the next scheduled row averages its
    whole interval: a run extended past its old end (raised time.end) read a mean over the few steps since
    that end's row.  A checkpoint keeps the interval so far (the same on every rank: it adds
    the sums over the ranks), so the first row after a restart averages the whole interval, as the run
    without the restart did."""

    def __init__(self):
        self._sum = None
        self._steps = 0
        self._last = None

    def add(self, values) -> None:
        values = np.asarray(values, dtype=float)
        if self._sum is None:
            self._sum = np.zeros_like(values)
        self._sum += values
        self._steps += 1

    def state_dict(self) -> dict:
        return {"sum": kinds.global_array(np.zeros(0) if self._sum is None else self._sum),
                "steps": kinds.scalar(int(self._steps)),
                "last": kinds.global_array(np.zeros(0) if self._last is None else self._last)}

    def load_state_dict(self, state: dict) -> None:
        total, last = np.asarray(state["sum"], dtype=float), np.asarray(state["last"], dtype=float)
        self._sum = total.copy() if total.size else None
        self._steps = int(state["steps"])
        self._last = last.copy() if last.size else None

    def take(self, fallback, restart: bool = True):
        if self._steps:
            self._last = self._sum / self._steps
            if restart:
                self._sum[...] = 0.0
                self._steps = 0
        return self._last if self._last is not None else np.asarray(fallback, dtype=float)
