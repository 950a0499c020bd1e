"""Plots of a run's history.csv (matplotlib, Agg backend: no display needed).

    plot_history("out/demo")  ->  out/demo/plots/energies.png, wall_forces.png, particles.png

Columns used (missing ones are skipped): ``time``; every ``*_energy`` column;
``force_<wall>_x/_y/_z`` per wall; ``particles`` and ``contacts``.
"""
from __future__ import annotations

import csv
import math
import re
from pathlib import Path
from typing import Dict, List

import numpy as np

from pdemfem.errors import PdemfemError

__all__ = ["read_history", "plot_history"]

_WALL_FORCE = re.compile(r"^force_(.+)_([xyz])$")


def read_history(path) -> Dict[str, np.ndarray]:
    """history.csv -> {column: float array}; PdemfemError when it is missing or unreadable."""
    path = Path(path)
    if not path.is_file():
        folder = path.parent
        hint = "run a scene first: pdemfem run scene.yaml -o DIR, then pdemfem plot DIR"
        if not folder.is_dir():
            raise PdemfemError(str(folder), "no such output directory", hint)
        raise PdemfemError(str(path), "history.csv not found in the output directory", hint)
    with open(path, newline="") as handle:
        rows = list(csv.reader(handle))
    if not rows or not rows[0]:
        raise PdemfemError(str(path), "the file is empty (no header)", "re-run the scene; history.csv is written by rank 0")
    header = [name.strip() for name in rows[0]]
    if "time" not in header:
        raise PdemfemError(str(path), f"no 'time' column (columns: {', '.join(header)})",
                           "pass the output directory of a pdemfem run")
    body = [row for row in rows[1:] if row]
    if not body:
        raise PdemfemError(str(path), "no data rows yet", "let the run write at least one output interval")
    columns: Dict[str, np.ndarray] = {}
    for index, name in enumerate(header):
        values = []
        for line, row in enumerate(body, start=2):
            try:
                values.append(float(row[index]))
            except (IndexError, ValueError):
                raise PdemfemError(f"{path}, line {line}", f"column '{name}' is not a number ({row[index:index + 1]})",
                                   "the file is damaged; re-run the scene") from None
        columns[name] = np.asarray(values)
    return columns


def plot_history(outdir) -> List[Path]:
    """Draw OUTDIR/history.csv into OUTDIR/plots/*.png; returns the files written."""
    outdir = Path(outdir)
    data = read_history(outdir / "history.csv")

    import warnings

    import matplotlib

    matplotlib.use("Agg")
    with warnings.catch_warnings():
        # Debian's matplotlib beside pip's warns that its 3-D axes cannot load; no 3-D plots here.
        warnings.simplefilter("ignore", UserWarning)
        from matplotlib import pyplot

    plots = outdir / "plots"
    plots.mkdir(exist_ok=True)
    time = data["time"]
    written: List[Path] = []

    def save(figure, name):
        target = plots / name
        figure.tight_layout()
        figure.savefig(target, dpi=110)
        pyplot.close(figure)
        written.append(target)

    energies = [name for name in data if name.endswith("_energy")]
    if energies:
        figure, axes = pyplot.subplots(figsize=(7, 4.5))
        for name in energies:
            axes.plot(time, data[name], label=name.replace("_", " "))
        if len(energies) > 1:
            axes.plot(time, sum(data[name] for name in energies), "k--", label="sum of the above")
        axes.set_xlabel("time [s]")
        axes.set_ylabel("energy [J]")
        axes.set_title("energies")
        axes.legend(fontsize="small")
        axes.grid(alpha=0.3)
        save(figure, "energies.png")

    walls: Dict[str, Dict[str, str]] = {}
    for name in data:
        match = _WALL_FORCE.match(name)
        if match:
            walls.setdefault(match.group(1), {})[match.group(2)] = name
    if walls:
        figure, axes = pyplot.subplots(3, 1, figsize=(7, 7), sharex=True)
        for component, axis in zip("xyz", axes):
            for wall, names in walls.items():
                if component in names:
                    axis.plot(time, data[names[component]], label=wall)
            axis.set_ylabel(f"F_{component} [N]")
            axis.grid(alpha=0.3)
        axes[0].set_title("contact force on each wall")
        axes[0].legend(fontsize="small", ncol=max(1, math.ceil(len(walls) / 4)))
        axes[-1].set_xlabel("time [s]")
        save(figure, "wall_forces.png")

    if "particles" in data:
        figure, axes = pyplot.subplots(figsize=(7, 4))
        axes.plot(time, data["particles"], label="particles")
        axes.set_xlabel("time [s]")
        axes.set_ylabel("particles")
        if "contacts" in data:
            twin = axes.twinx()
            twin.plot(time, data["contacts"], color="tab:orange", label="contacts")
            twin.set_ylabel("contacts")
            axes.legend(handles=axes.get_lines() + twin.get_lines(), fontsize="small")
        axes.set_title("particle and contact count")
        axes.grid(alpha=0.3)
        save(figure, "particles.png")
    return written
