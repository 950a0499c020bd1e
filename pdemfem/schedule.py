"""The steps at which a run writes its output rows and checkpoints: every `interval` seconds of a run of step
`dt`, the k-th at the step nearest k x interval.

Each write is rounded to its nearest step on its own, not the interval once: with the interval rounded to
whole steps, the k-th write drifted from k x interval by k times the rounding (87.4 steps rounded to 87 put the
1000th output 400 steps early), and the last intervals before time.end fell due after it and were never
written.  Now a write is at most half a step from its time, and at time.end = k x interval the k-th write is
the end's step or the one before it.
"""
from __future__ import annotations

import math


class Schedule:
    """Writes every `interval` [s] on the step grid of `dt` [s] (an interval below a step: every step)."""

    def __init__(self, interval: float, dt: float):
        self.interval = float(interval)
        self.dt = float(dt)
        self._steps_per_interval = self.interval / self.dt  # > 1 unless every step is due

    def step_of(self, index: int) -> int:
        """The step of the index-th write."""
        if self._steps_per_interval <= 1.0:
            return index
        return math.floor(index * self._steps_per_interval + 0.5)

    def index_at(self, step: int) -> int:
        """The write whose step is nearest `step`."""
        if self._steps_per_interval <= 1.0:
            return step
        return math.floor(step / self._steps_per_interval + 0.5)

    def is_due(self, step: int) -> bool:
        return self.step_of(self.index_at(step)) == step

    def next_after(self, step: int) -> int:
        """The first step after `step` with a write due."""
        index = max(0, self.index_at(step) - 1)
        while self.step_of(index) <= step:
            index += 1
        return self.step_of(index)

    def due_before_end(self, step: int, end: float) -> bool:
        """Whether a write is due at `step` for a time before `end` [s] (by more than half a step).  The write
        due at the end's time (end = k x interval, its step the end's or the one before) is left to the end's
        own write: two writes of one moment made checkpoint.keep 2 prune the run's middle checkpoint."""
        if self._steps_per_interval <= 1.0:
            return step * self.dt < end - 0.5 * self.dt
        return self.is_due(step) and self.index_at(step) * self.interval < end - 0.5 * self.dt
