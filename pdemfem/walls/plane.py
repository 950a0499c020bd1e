"""Analytic plane walls: flat rigid bodies with an optional prescribed velocity."""
from __future__ import annotations

import numpy as np
from numba import njit

from pdemfem import state_dict as kinds
from pdemfem.neighbors.history import restore_wall_records


class PlaneWalls(kinds.StateComponent):
    """Arrays for all plane walls of a scene; the normal points into the particles' side."""

    def __init__(self, wall_configs, material_names: list):
        self.names = [wall.name for wall in wall_configs]
        count = len(self.names)
        self.points = np.array([wall.point for wall in wall_configs], dtype=float).reshape(count, 3)
        normals = np.array([wall.normal for wall in wall_configs], dtype=float).reshape(count, 3)
        lengths = np.linalg.norm(normals, axis=1) if count else np.zeros(0)
        self.normals = normals / lengths[:, None] if count else normals
        # The velocity the plane moves with, and (velocities) the velocity of its surface the contact law
        # sees: plus a conveyor's transport_velocity along the plane (the plane itself does not move with it).
        self.motion = np.array([wall.velocity for wall in wall_configs], dtype=float).reshape(count, 3)
        transport = np.array([getattr(wall, "transport_velocity", (0.0, 0.0, 0.0)) for wall in wall_configs],
                             dtype=float).reshape(count, 3)
        transport -= np.sum(transport * self.normals, axis=1)[:, None] * self.normals
        self.velocities = self.motion + transport
        self._moving = bool(np.any(self.motion))
        self.material_index = np.array([material_names.index(wall.material) for wall in wall_configs],
                                       dtype=np.int32)
        self.forces = np.zeros((count, 3))
        # Fixed temperature [K] of each wall with heat on; NaN: adiabatic.
        self.temperatures = np.array([np.nan if getattr(wall, "temperature", None) is None else wall.temperature
                                      for wall in wall_configs], dtype=float).reshape(count)
        # (particle, wall) pairs that may touch before the next list build, particle-major, and each one's
        # contact history (pdemfem.contact.registry.history_layout): only the particles near a wall hold a
        # row.  Across a rebuild the history travels as contact records (pdemfem.neighbors.history).
        self.candidate_particles = np.zeros(0, dtype=np.int64)
        self.candidate_walls = np.zeros(0, dtype=np.int64)
        self.candidate_history = np.zeros((0, 0))
        self.points_at_build = self.points.copy()
        # Work the walls have done on the particles (a moving wall feeds energy in), and their power at the
        # last force evaluation (the particle system books each step's work as the trapezoid of two powers).
        self.work = 0.0
        self.previous_power = 0.0

    @property
    def count(self) -> int:
        return len(self.names)

    def move(self, dt: float) -> None:
        if self._moving:
            self.points += dt * self.motion

    def largest_displacement_since_build(self) -> float:
        # Called every step: planes that never move (most scenes) skip the numpy passes.
        if not self.count or not self._moving:
            return 0.0
        return float(np.sqrt(np.max(np.sum((self.points - self.points_at_build) ** 2, axis=1))))

    def build_candidates(self, positions: np.ndarray, radii: np.ndarray, skin: float, history_width: int) -> None:
        """Owned particles within radius + skin of each wall (the wall side or behind it), with zero history
        (restore_history fills it)."""
        self.points_at_build = self.points.copy()
        if not self.count or not len(positions):
            self.candidate_particles = np.zeros(0, dtype=np.int64)
            self.candidate_walls = np.zeros(0, dtype=np.int64)
        else:
            self.candidate_particles, self.candidate_walls = _near_walls(positions, radii, skin, self.points,
                                                                         self.normals)
        self.candidate_history = np.zeros((len(self.candidate_particles), history_width))

    @property
    def candidates(self) -> tuple:
        """(particle rows, walls, history) of the candidate pairs: what the contact records are taken from."""
        return self.candidate_particles, self.candidate_walls, self.candidate_history

    def restore_history(self, ids: np.ndarray, owned_count: int, records: np.ndarray) -> None:
        """The candidates' history from the contact records of the plane walls (partner key -1 - wall)."""
        if len(records) and self.candidate_history.shape[1]:
            restore_wall_records(self.candidate_particles, self.candidate_walls, self.candidate_history, ids,
                                 owned_count, np.ascontiguousarray(records))

    # ------------------------------------------------------------ checkpoints
    _ARRAYS = ("points", "velocities", "forces")

    def state_dict(self) -> dict:
        state = {name: kinds.global_array(getattr(self, name)) for name in self._ARRAYS}
        state["work"] = kinds.scalar(float(self.work))
        state["previous_power"] = kinds.scalar(float(self.previous_power))
        return state

    def load_state_dict(self, state: dict) -> None:
        for name in self._ARRAYS:
            stored = np.asarray(state[name])
            if stored.shape != getattr(self, name).shape:
                raise kinds.StateMismatch("the scene's plane walls differ from the checkpoint's")
        for name in self._ARRAYS:
            getattr(self, name)[...] = state[name]
        self.work = float(state["work"])
        # A checkpoint written before the trapezoid rule: the power of its forces (the same evaluation).
        self.previous_power = float(state.get("previous_power", -np.sum(self.forces * self.velocities)))

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no wall named '{name}' (walls: {self.names})") from None


@njit(cache=True)
def _near_walls(positions, radii, skin, points, normals):
    """(particle, wall) pairs closer than radius + skin, particle-major in ascending row (the force summation
    order; restore_wall_records relies on each particle's pairs being one run)."""
    wall_count = points.shape[0]
    offsets = np.empty(wall_count)
    for w in range(wall_count):
        offsets[w] = points[w, 0] * normals[w, 0] + points[w, 1] * normals[w, 1] + points[w, 2] * normals[w, 2]
    # Two passes (count, then fill) keep the allocation to the pairs actually near a wall.
    particles = np.empty(0, dtype=np.int64)
    walls = np.empty(0, dtype=np.int64)
    for fill in (False, True):
        count = 0
        for i in range(positions.shape[0]):
            reach = radii[i] + skin
            for w in range(wall_count):
                distance = (positions[i, 0] * normals[w, 0] + positions[i, 1] * normals[w, 1]
                            + positions[i, 2] * normals[w, 2] - offsets[w])
                if distance < reach:
                    if fill:
                        particles[count] = i
                        walls[count] = w
                    count += 1
        if not fill:
            particles = np.empty(count, dtype=np.int64)
            walls = np.empty(count, dtype=np.int64)
    return particles, walls
