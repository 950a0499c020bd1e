"""Particle state as structure-of-arrays numpy arrays: owned particles first, then ghosts.

Kernels read and write these arrays directly; nothing here holds scene objects.
Rows [0, owned_count) are the particles this rank integrates; rows after them
are ghost copies of neighbours' particles (read-only inputs to the contact
kernels, refreshed every step).  Every per-particle array is permuted by
`reorder` (cell sort) and travels with a particle when it migrates
(`pack_rows` / `append_rows`).  Core fields are listed below; a module that
needs its own per-particle state (e.g. mesh-wall contact history) registers it
with `add_field` and reads it as `state.fields[name]`.
"""
from __future__ import annotations

import numpy as np

# Fields that define a particle and move with it between ranks.
MIGRATING_FIELDS = (
    "ids",
    "material_index",
    "radii",
    "mass",
    "inverse_mass",
    "inverse_inertia",
    "positions",
    "velocities",
    "angular_velocities",
    "temperatures",
    "wall_history",
)
# Per-step scratch, recomputed after every migration.
SCRATCH_FIELDS = ("forces", "torques", "positions_at_build")
# What a ghost copy carries: everything the contact kernels read of a partner.
GHOST_FIELDS = ("ids", "material_index", "radii", "mass", "inverse_mass", "inverse_inertia", "positions",
                "velocities", "angular_velocities", "temperatures")
# Refreshed every step between list builds.
GHOST_UPDATE_FIELDS = ("positions", "velocities", "angular_velocities")


class ParticleState:
    """Spheres: identity, material, size, kinematics, loads and contact history."""

    def __init__(self, ids, material_index, radii, densities, positions, velocities, angular_velocities,
                 temperatures, wall_count: int, history_width: int = 3):
        count = len(ids)
        self.ids = np.ascontiguousarray(ids, dtype=np.int64)
        self.material_index = np.ascontiguousarray(material_index, dtype=np.int32)
        self.radii = np.ascontiguousarray(radii, dtype=np.float64)
        self.mass = 4.0 / 3.0 * np.pi * self.radii**3 * np.asarray(densities, dtype=np.float64)
        self.inverse_mass = 1.0 / self.mass
        # Solid sphere: I = 2/5 m r^2.
        self.inverse_inertia = 1.0 / (0.4 * self.mass * self.radii**2)
        self.positions = np.ascontiguousarray(positions, dtype=np.float64).reshape(count, 3)
        self.velocities = np.ascontiguousarray(velocities, dtype=np.float64).reshape(count, 3)
        self.angular_velocities = np.ascontiguousarray(angular_velocities, dtype=np.float64).reshape(count, 3)
        self.temperatures = np.ascontiguousarray(temperatures, dtype=np.float64)
        # Contact history (pdemfem.contact.registry.history_layout) of each particle against each plane wall.
        self.wall_history = np.zeros((count, max(wall_count, 1), history_width))
        self.forces = np.zeros((count, 3))
        self.torques = np.zeros((count, 3))
        self.positions_at_build = self.positions.copy()
        self.fields = {}
        self.owned_count = count

    # ------------------------------------------------------------ fields
    def add_field(self, name: str, tail_shape: tuple = (), dtype=np.float64, fill=0) -> np.ndarray:
        """Register an extra per-particle array of shape (count, *tail_shape); it migrates."""
        if name in self.fields:
            raise ValueError(f"per-particle field '{name}' registered twice")
        self.fields[name] = np.full((self.count, *tail_shape), fill, dtype=dtype)
        return self.fields[name]

    def _arrays(self, names):
        for name in names:
            yield name, getattr(self, name)

    def _all_arrays(self):
        yield from self._arrays(MIGRATING_FIELDS + SCRATCH_FIELDS)
        yield from self.fields.items()

    def _set(self, name, values):
        if name in self.fields:
            self.fields[name] = values
        else:
            setattr(self, name, values)

    @property
    def count(self) -> int:
        """Rows held: owned particles plus ghosts."""
        return len(self.ids)

    @property
    def ghost_count(self) -> int:
        return self.count - self.owned_count

    # ------------------------------------------------------------ reshaping
    def reorder(self, permutation: np.ndarray) -> None:
        """Permute the owned rows (ghosts must have been dropped first)."""
        assert self.ghost_count == 0, "reorder owned particles only"
        for name, values in self._all_arrays():
            self._set(name, np.ascontiguousarray(values[permutation]))

    def keep(self, rows: np.ndarray) -> None:
        """Keep only the given rows (owned); drops ghosts."""
        for name, values in self._all_arrays():
            self._set(name, np.ascontiguousarray(values[rows]))
        self.owned_count = len(rows)

    def drop_ghosts(self) -> None:
        if self.ghost_count:
            self.keep(np.arange(self.owned_count))

    def _layout(self, names_and_arrays):
        layout, width = [], 0
        for name, values in names_and_arrays:
            columns = int(np.prod(values.shape[1:], dtype=np.int64))
            layout.append((name, width, columns, values.shape[1:], values.dtype))
            width += columns
        return layout, width

    def migrating_layout(self):
        return self._layout(list(self._arrays(MIGRATING_FIELDS)) + list(self.fields.items()))

    def ghost_layout(self):
        return self._layout(self._arrays(GHOST_FIELDS))

    def pack_rows(self, rows: np.ndarray, layout, width) -> np.ndarray:
        """Rows of the named fields as one float64 matrix (ids and ints are exact below 2^53)."""
        packed = np.empty((len(rows), width))
        for name, start, columns, _, _ in layout:
            values = self.fields[name] if name in self.fields else getattr(self, name)
            packed[:, start:start + columns] = values[rows].reshape(len(rows), columns)
        return packed

    def append_rows(self, packed: np.ndarray, layout, as_ghosts: bool) -> None:
        """Append unpacked rows; fields not in the layout get zeros."""
        count = len(packed)
        given = {name for name, *_ in layout}
        for name, start, columns, tail, dtype in layout:
            values = self.fields[name] if name in self.fields else getattr(self, name)
            new = packed[:, start:start + columns].reshape((count, *tail))
            if np.issubdtype(dtype, np.integer):
                new = np.rint(new)
            self._set(name, np.ascontiguousarray(np.concatenate([values, new.astype(dtype)])))
        for name, values in self._all_arrays():
            if name not in given:
                self._set(name, np.ascontiguousarray(
                    np.concatenate([values, np.zeros((count, *values.shape[1:]), dtype=values.dtype)])))
        if not as_ghosts:
            self.owned_count += count

    def nbytes(self) -> int:
        return sum(values.nbytes for _, values in self._all_arrays())
