"""history.csv: one row of scalars per output interval, written by rank 0.

Each row is written and flushed whole, so an interrupted run leaves a file
whose every line is complete.
"""
from __future__ import annotations

import csv
from pathlib import Path


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
        self._writer.writerow([repr(float(values[name])) if not isinstance(values[name], int) else values[name]
                               for name in self.columns])
        self._file.flush()

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None
