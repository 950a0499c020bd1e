"""Particle state as structure-of-arrays numpy arrays (owned particles first).

Kernels read and write these arrays directly; nothing here holds scene objects.
Every per-particle array is permuted together by `reorder` (cell sort on list
rebuild) and will travel with a particle when it migrates between ranks.  Core
fields are listed in PER_PARTICLE_FIELDS; a module that needs its own
per-particle state (e.g. mesh-wall contact history) registers it with
`add_field` and reads it as `state.fields[name]`.
"""
from __future__ import annotations

import numpy as np

PER_PARTICLE_FIELDS = (
    "ids",
    "material_index",
    "radii",
    "mass",
    "inverse_mass",
    "inverse_inertia",
    "positions",
    "velocities",
    "angular_velocities",
    "forces",
    "torques",
    "temperatures",
    "positions_at_build",
    "wall_history",
)


class ParticleState:
    """Spheres: identity, material, size, kinematics, loads and contact history."""

    def __init__(self, ids, material_index, radii, densities, positions, velocities, angular_velocities,
                 temperatures, wall_count: int):
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
        self.forces = np.zeros((count, 3))
        self.torques = np.zeros((count, 3))
        self.temperatures = np.ascontiguousarray(temperatures, dtype=np.float64)
        self.positions_at_build = self.positions.copy()
        # Tangential spring of each particle against each analytic wall.
        self.wall_history = np.zeros((count, max(wall_count, 1), 3))
        self.fields = {}

    def add_field(self, name: str, tail_shape: tuple = (), dtype=np.float64, fill=0) -> np.ndarray:
        """Register an extra per-particle array of shape (count, *tail_shape)."""
        if name in self.fields:
            raise ValueError(f"per-particle field '{name}' registered twice")
        self.fields[name] = np.full((self.count, *tail_shape), fill, dtype=dtype)
        return self.fields[name]

    @property
    def count(self) -> int:
        return len(self.ids)

    def reorder(self, permutation: np.ndarray) -> None:
        """Permute every per-particle array (e.g. into cell order)."""
        for name in PER_PARTICLE_FIELDS:
            setattr(self, name, np.ascontiguousarray(getattr(self, name)[permutation]))
        for name, values in self.fields.items():
            self.fields[name] = np.ascontiguousarray(values[permutation])

    def nbytes(self) -> int:
        return (sum(getattr(self, name).nbytes for name in PER_PARTICLE_FIELDS)
                + sum(values.nbytes for values in self.fields.values()))
