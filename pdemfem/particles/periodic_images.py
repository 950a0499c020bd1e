"""Periodic images of particles near the faces of a periodic domain, for the tests that place particles
(insertion's overlap check, a stream's clearance): on a periodic axis a particle near one face touches the
particles near the opposite face, which a plain distance test does not see.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PeriodicBox:
    """The domain box's corners and which of its axes are periodic."""

    lower: np.ndarray
    upper: np.ndarray
    periodic: np.ndarray  # (3,) bool

    @classmethod
    def from_scene(cls, scene):
        """The scene's periodic box, or None when no axis is periodic."""
        domain = scene.domain
        if not domain.periodic or domain.box is None:
            return None
        lower, upper = (np.asarray(corner, dtype=float) for corner in domain.box)
        return cls(lower, upper, np.array(["xyz"[axis] in domain.periodic for axis in range(3)]))

    @classmethod
    def from_lengths(cls, lower, lengths):
        """From the domain's lower corner and the periodic lengths (0 on an axis that is not periodic)."""
        lengths = np.asarray(lengths, dtype=float)
        if not np.any(lengths > 0.0):
            return None
        lower = np.asarray(lower, dtype=float)
        return cls(lower, lower + lengths, lengths > 0.0)

    @property
    def lengths(self) -> np.ndarray:
        return np.where(self.periodic, self.upper - self.lower, 0.0)

    def wrapped(self, positions: np.ndarray) -> np.ndarray:
        """The positions moved into the box along the periodic axes (a copy)."""
        positions = np.array(positions, dtype=float, copy=True).reshape(-1, 3)
        for axis in np.flatnonzero(self.periodic):
            length = self.upper[axis] - self.lower[axis]
            positions[:, axis] = self.lower[axis] + np.mod(positions[:, axis] - self.lower[axis], length)
        return positions

    def nearest_separation(self, separation: np.ndarray) -> np.ndarray:
        """The separation to the nearest periodic image along the periodic axes."""
        lengths = self.lengths
        return separation - lengths * np.round(separation / np.where(lengths > 0.0, lengths, np.inf))

    def with_images(self, positions: np.ndarray, radii: np.ndarray, reach: float):
        """(positions, radii, rows): the positions moved into the box, followed by the images of those within
        `reach` of a periodic face, shifted by the period across it (along each axis, edges and corners
        included), with their radii; rows[k] is the input row that position k copies."""
        positions = self.wrapped(positions)
        lengths = self.lengths
        near_lower = positions - self.lower < reach
        near_upper = self.upper - positions < reach
        axes = np.flatnonzero(self.periodic)
        rows, shifted = [np.arange(len(positions))], [positions]
        for shifts in itertools.product((-1, 0, 1), repeat=len(axes)):
            if not any(shifts):
                continue
            selected = np.ones(len(positions), dtype=bool)
            offset = np.zeros(3)
            for axis, shift in zip(axes, shifts):
                if shift:
                    # +1: a particle near the lower face reappears beyond the upper one.
                    selected &= near_lower[:, axis] if shift > 0 else near_upper[:, axis]
                    offset[axis] = shift * lengths[axis]
            selected_rows = np.flatnonzero(selected)
            rows.append(selected_rows)
            shifted.append(positions[selected_rows] + offset)
        rows = np.concatenate(rows).astype(np.int64)
        return np.concatenate(shifted), np.asarray(radii, dtype=float)[rows], rows
