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
    that end's row.  `close` ends an interval at a step of the schedule that gets no row of its own (the
    run's end falls a few steps after it): the next row off the schedule returns that interval's mean, and
    the steps after it count for the next interval, as in a run that goes on.  A checkpoint keeps the
    interval so far (the same on every rank: it adds the sums over the ranks), so the first row after a
    restart averages the whole interval, as the run without the restart did."""

    def __init__(self):
        self._sum = None
        self._steps = 0
        self._last = None
        self._closed = None  # the mean of an interval closed without its row

    def add(self, values) -> None:
        values = np.asarray(values, dtype=float)
        if self._sum is None:
            self._sum = np.zeros_like(values)
        self._sum += values
        self._steps += 1

    def state_dict(self) -> dict:
        def stored(values):
            return kinds.global_array(np.zeros(0) if values is None else values)

        return {"sum": stored(self._sum), "steps": kinds.scalar(int(self._steps)), "last": stored(self._last),
                "closed": stored(self._closed)}

    def load_state_dict(self, state: dict) -> None:
        def loaded(values):
            values = np.asarray(values, dtype=float)
            return values.copy() if values.size else None

        self._sum, self._last, self._closed = loaded(state["sum"]), loaded(state["last"]), loaded(state["closed"])
        self._steps = int(state["steps"])

    def close(self) -> None:
        if self._steps:
            self._closed = self._sum / self._steps
            self._sum[...] = 0.0
            self._steps = 0

    def take(self, fallback, restart: bool = True):
        if self._closed is not None:
            closed, self._closed = self._closed, None
            if not restart:
                self._last = closed
                return self._last
        if self._steps:
            self._last = self._sum / self._steps
            if restart:
                self._sum[...] = 0.0
                self._steps = 0
        return self._last if self._last is not None else np.asarray(fallback, dtype=float)
