"""Plots of a run's history.csv (matplotlib, Agg backend: no display needed).

    plot_history("out/demo")  ->  out/demo/plots/energies.png, wall_forces.png, particles.png,
                                  reactions.png, deflections.png, temperatures.png, heat.png
                                  (those with data)

Columns used (missing ones are skipped): ``time``; every ``*_energy`` column, ``wall_work``,
``thermoelastic_work``, ``frame_work`` and ``support_work``;
``mean_force_<wall>_x/_y/_z`` per wall and contact solid (the mean over each output interval;
``force_<wall>_*``, the value at the output time, when a history has no means);
``reaction_<solid>_<group>_x/_y/_z``; ``max_displacement_<solid>``; ``particles`` and ``contacts``;
with heat, ``temperature_<body>_min/_mean/_max`` (particles and each conducting solid), ``heat_<name>``,
``heat_in``, ``heat_out`` and ``thermal_energy`` (drawn apart from the mechanical energies, which they would dwarf).
A quantity that stays constant over the whole run gets no curve (its value is named in the
title instead), and a figure all of whose quantities are constant is not drawn.
"""
from __future__ import annotations

import collections
import csv
import logging
import math
import re
from pathlib import Path
from typing import Dict, List

import numpy as np

from pdemfem.errors import PdemfemError
from pdemfem.monitor import THERMAL_ENERGIES, total_energy

__all__ = ["read_history", "plot_history"]

log = logging.getLogger("pdemfem")

_WALL_FORCE = re.compile(r"^force_(.+)_([xyz])$")
_MEAN_FORCE = re.compile(r"^mean_force_(.+)_([xyz])$")
_REACTION = re.compile(r"^reaction_(.+)_([xyz])$")
_DEFLECTION = re.compile(r"^max_displacement_(.+)$")
_TEMPERATURE = re.compile(r"^temperature_(.+)_(min|mean|max)$")
_HEAT = re.compile(r"^heat_(.+)$")
# Heat content carried in by inserted and out by removed particles (not a body's heat_<name>).
_CARRIED_HEAT = {"heat_in": "brought in by inserted particles", "heat_out": "taken out by removed particles"}


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
        text = handle.read()
    rows = list(csv.reader(text.splitlines()))
    if not rows or not rows[0]:
        raise PdemfemError(str(path), "the file is empty (no header)", "re-run the scene; history.csv is written by rank 0")
    header = [name.strip() for name in rows[0]]
    if "time" not in header:
        raise PdemfemError(str(path), f"no 'time' column (columns: {', '.join(header)})",
                           "pass the output directory of a pdemfem run")
    body = [row for row in rows[1:] if row]
    if body and _incomplete(body[-1], header, text):
        # Rows are flushed whole; a last row cut short is a run killed while writing it (or still running).
        log.warning("note: %s: the last row (line %d) is incomplete (%d of %d columns%s), as a run killed while "
                    "writing it leaves it; plotting the %d complete rows without it", path, len(rows),
                    len(body[-1]), len(header), "" if text.endswith("\n") else ", no line end", len(body) - 1)
        body = body[:-1]
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


def _incomplete(row, header, text: str) -> bool:
    """A last row cut short: fewer fields than the header, no line end, or a field that is no number."""
    if len(row) != len(header) or not text.endswith(("\n", "\r")):
        return True
    try:
        [float(value) for value in row]
    except ValueError:
        return True
    return False


def is_constant(values: np.ndarray) -> bool:
    """Does a column hold one value over the whole run (to round-off of that value)?"""
    if len(values) < 2:
        return True
    spread = float(values.max() - values.min())
    # 1e-12 of the magnitude: a sum recomputed each row may differ in its last bits without changing.
    return spread <= 1e-12 * max(float(np.abs(values).max()), np.finfo(float).tiny)


def _vector_columns(data, pattern) -> Dict[str, Dict[str, str]]:
    """{name: {component: column}} of the columns matching `pattern` (groups: name, component)."""
    found: Dict[str, Dict[str, str]] = {}
    for column in data:
        match = pattern.match(column)
        if match:
            found.setdefault(match.group(1), {})[match.group(2)] = column
    return found


def _constant_note(data, columns, unit: str) -> str:
    constants = [column for column in columns if is_constant(data[column])]
    if not constants:
        return ""
    shown = ", ".join(f"{column} = {data[column][0]:.4g}{unit}" for column in constants[:3])
    more = f" and {len(constants) - 3} more" if len(constants) > 3 else ""
    return f"constant: {shown}{more}"


def agg_pyplot():
    """matplotlib's pyplot on the Agg backend (no display needed), for the plots and the benchmarks' figures."""
    import warnings

    import matplotlib

    matplotlib.use("Agg")
    from pdemfem.render import _prefer_the_toolkit_beside

    with warnings.catch_warnings():
        # Debian's matplotlib beside pip's warns that its 3-D axes cannot load; no 3-D plots here, but `render` in
        # the same process needs them: the toolkit beside this matplotlib is put first before pyplot registers it.
        warnings.simplefilter("ignore", UserWarning)
        _prefer_the_toolkit_beside(matplotlib)
        from matplotlib import pyplot
    return pyplot


def plot_history(outdir) -> List[Path]:
    """Draw OUTDIR/history.csv into OUTDIR/plots/*.png; returns the files written."""
    outdir = Path(outdir)
    data = read_history(outdir / "history.csv")

    pyplot = agg_pyplot()
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

    def finish(figure, axes, ylabel, title, note, name):
        """Label a figure of curves over time (legend, grid, title with its constants note) and save it."""
        axes.set_xlabel("time [s]")
        axes.set_ylabel(ylabel)
        axes.set_title(title + (f"\n({note})" if note else ""), fontsize="medium")
        axes.legend(fontsize="small")
        axes.grid(alpha=0.3)
        save(figure, name)

    # Work done on the system (and the streams' net energy brought in), subtracted from the total as
    # pdemfem.monitor.total_energy does.
    fed_in = ("wall_work", "thermoelastic_work", "stream_energy", "frame_work", "support_work")
    energies = [name for name in data if (name.endswith("_energy") or name in (*fed_in, "solid_load_potential"))
                and name not in THERMAL_ENERGIES]  # heat content has its own figure (heat.png)
    varying = [name for name in energies if not is_constant(data[name])]
    if varying:
        figure, axes = pyplot.subplots(figsize=(7, 4.5))
        for name in varying:
            axes.plot(time, data[name], label=name.replace("_", " "))
        if len(energies) > 1:
            # The bookkeeping total, as the run monitor sums it (elementwise over the rows).
            # A column the run did not write (e.g. no rotation) counts as zero.
            total = total_energy(collections.defaultdict(float, data))
            axes.plot(time, total, "k--", label="total (conserved up to integration error)")
        finish(figure, axes, "energy [J]", "energies", _constant_note(data, energies, " J"), "energies.png")

    means = _vector_columns(data, _MEAN_FORCE)
    walls = means or _vector_columns(data, _WALL_FORCE)
    how = "mean over each output interval" if means else "at the output times"
    _vector_figure(pyplot, save, time, data, walls, f"contact force on each wall and solid ({how})", "F", "N",
                   "wall_forces.png")
    _vector_figure(pyplot, save, time, data, _vector_columns(data, _REACTION),
                   "support reactions of the solids (solid_group)", "R", "N", "reactions.png")

    deflections = {match.group(1): column for column in data if (match := _DEFLECTION.match(column))}
    if any(not is_constant(data[column]) for column in deflections.values()):
        figure, axes = pyplot.subplots(figsize=(7, 4))
        for solid, column in deflections.items():
            if not is_constant(data[column]):
                axes.plot(time, 1e3 * data[column], label=solid)
        finish(figure, axes, "largest displacement [mm]", "deflection of each solid (largest nodal displacement)",
               _constant_note(data, list(deflections.values()), " m"), "deflections.png")

    _temperature_figures(pyplot, finish, time, data)

    counts = [name for name in ("particles", "contacts") if name in data]
    varying = [name for name in counts if not is_constant(data[name])]
    if varying:
        figure, axes = pyplot.subplots(figsize=(7, 4))
        colors = {"particles": "tab:blue", "contacts": "tab:orange"}
        for name in varying:
            axes.plot(time, data[name], color=colors[name], label=name)
        finish(figure, axes, "count", "particle and contact count", _constant_note(data, counts, ""),
               "particles.png")
    return written


def _temperature_figures(pyplot, finish, time, data) -> None:
    """temperatures.png: each body's min / mean / max temperature; heat.png: the heat each wall or solid gave
    the particles (cumulative), and what inserted particles brought in and removed ones took out (drawn negative),
    beside the change of the heat content, which they balance."""
    bodies: Dict[str, Dict[str, str]] = {}
    for column in data:
        match = _TEMPERATURE.match(column)
        if match:
            bodies.setdefault(match.group(1), {})[match.group(2)] = column
    if any(not is_constant(data[column]) for columns in bodies.values() for column in columns.values()):
        figure, axes = pyplot.subplots(figsize=(7, 4.5))
        for index, (body, columns) in enumerate(bodies.items()):
            color = f"C{index}"
            if "mean" in columns:
                axes.plot(time, data[columns["mean"]], color=color, label=f"{body} (mean)")
            if "min" in columns and "max" in columns:
                axes.fill_between(time, data[columns["min"]], data[columns["max"]], color=color, alpha=0.2,
                                  label=f"{body} (min to max)")
        finish(figure, axes, "temperature [K]", "temperatures", "", "temperatures.png")
    flows = {match.group(1): column for column in data
             if (match := _HEAT.match(column)) and column not in _CARRIED_HEAT}
    # Without streams, outlets or losses these stay zero: no curve.
    carried = [column for column in _CARRIED_HEAT if column in data and not is_constant(data[column])]
    if any(not is_constant(data[column]) for column in [*flows.values(), *carried]):
        figure, axes = pyplot.subplots(figsize=(7, 4.5))
        for body, column in flows.items():
            axes.plot(time, data[column], label=f"given by {body}")
        for column in carried:
            sign = -1.0 if column == "heat_out" else 1.0  # what leaves lowers the content
            axes.plot(time, sign * data[column], label=_CARRIED_HEAT[column] + (" (negative)" if sign < 0 else ""))
        if "particle_thermal_energy" in data:
            gained = data["particle_thermal_energy"] - data["particle_thermal_energy"][0]
            axes.plot(time, gained, "k--", label="particles' heat content change")
            if carried:  # the books' sum, drawn over the change it balances
                books = sum(data[column] for column in flows.values()) + data["heat_in"] - data["heat_out"]
                axes.plot(time, books, ":", color="0.5", linewidth=2.5, label="sum of the books (in - out included)")
        finish(figure, axes, "heat [J]", "heat given to the particles (cumulative)", "", "heat.png")


def _vector_figure(pyplot, save, time, data, vectors, title, symbol, unit, name) -> None:
    """One row per component that varies for some entry; entries constant in every component are named."""
    rows = [component for component in "xyz"
            if any(component in columns and not is_constant(data[columns[component]]) for columns in vectors.values())]
    if not rows:
        return
    figure, axes = pyplot.subplots(len(rows), 1, figsize=(7, 2.4 * len(rows) + 0.8), sharex=True, squeeze=False)
    axes = axes[:, 0]
    constant_entries = []
    for entry, columns in vectors.items():
        if all(is_constant(data[column]) for column in columns.values()):
            constant_entries.append(entry)
            continue
        for component, axis in zip(rows, axes):
            if component in columns:
                axis.plot(time, data[columns[component]], label=entry)
    for component, axis in zip(rows, axes):
        axis.set_ylabel(f"{symbol}_{component} [{unit}]")
        axis.grid(alpha=0.3)
    note = f"constant, not drawn: {', '.join(constant_entries)}" if constant_entries else ""
    axes[0].set_title(title + (f"\n({note})" if note else ""), fontsize="medium")
    shown = len(vectors) - len(constant_entries)
    axes[0].legend(fontsize="small", ncol=max(1, math.ceil(shown / 4)))
    axes[-1].set_xlabel("time [s]")
    save(figure, name)
