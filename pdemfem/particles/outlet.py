"""Outlets: sinks that remove the particles reaching them, counted per outlet (docs/streams.md).

    outlets:
      - {name: chute, kind: plane, point: [0, 0, -0.1], normal: [0, 0, -1]}   # centre beyond the plane
      - {name: bin, kind: box, box: [[...], [...]]}                          # centre inside the box

The particle system asks the outlets at every list rebuild, where it also removes the particles
that left the domain box (ParticleSystem._remove_lost): between two rebuilds no particle moves
more than half the skin, so a particle is taken at most that far beyond an outlet plane (a box
outlet should be thicker than the skin, or a fast particle may cross it between two rebuilds).
The first outlet (scene order) that holds a particle takes it.  Totals are summed over the ranks
in the same collective call: particles and mass per outlet, and the kinetic + rotational +
potential energy the removed particles carried out (the energy bookkeeping's stream_energy).
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI

from pdemfem import state_dict as kinds
from pdemfem.particles.energy import energy_leaving


class Outlets(kinds.StateComponent):
    """The scene's outlets (a checkpointed component); `take` is called by the particle system."""

    def __init__(self, outlet_configs):
        self.names = [outlet.name for outlet in outlet_configs]
        self.kinds = [outlet.kind for outlet in outlet_configs]
        self.points = [np.asarray(outlet.point, dtype=float) if outlet.kind == "plane" else None
                       for outlet in outlet_configs]
        self.normals = [np.asarray(outlet.normal, dtype=float) / np.linalg.norm(outlet.normal)
                        if outlet.kind == "plane" else None for outlet in outlet_configs]
        self.boxes = [np.asarray(outlet.box, dtype=float) if outlet.kind == "box" else None
                      for outlet in outlet_configs]
        self.counts = np.zeros(len(self.names), dtype=np.int64)
        self.masses = np.zeros(len(self.names))
        self.energy_out = 0.0  # kinetic + rotational + potential (-m g.x) carried out [J]

    @classmethod
    def from_scene(cls, scene):
        return cls(scene.outlets) if scene.outlets else None

    @property
    def count_out(self) -> int:
        return int(self.counts.sum())

    @property
    def mass_out(self) -> float:
        return float(self.masses.sum())

    def holds(self, index: int, positions: np.ndarray) -> np.ndarray:
        """Which positions outlet `index` takes."""
        if self.kinds[index] == "plane":
            return (positions - self.points[index]) @ self.normals[index] > 0.0
        lower, upper = self.boxes[index]
        return np.all((positions >= lower) & (positions <= upper), axis=1)

    def take(self, state, eligible: np.ndarray, gravity, comm, half_dt: float = 0.0) -> np.ndarray:
        """Collective: the mask of the owned particles (among `eligible`) an outlet takes; adds them
        to the outlets' totals (summed over the ranks), their energy at the end of the step (energy_leaving,
        half_dt: half the step).  The caller removes them."""
        owned = state.owned_count
        positions = state.positions[:owned]
        taken = np.zeros(owned, dtype=bool)
        outlet = np.full(owned, -1, dtype=np.int64)
        for index in range(len(self.names)):
            new = self.holds(index, positions) & eligible & ~taken
            outlet[new] = index
            taken |= new
        rows = np.flatnonzero(taken)
        count = len(self.names)
        totals = np.concatenate([np.bincount(outlet[rows], minlength=count).astype(float),
                                 np.bincount(outlet[rows], weights=state.mass[rows], minlength=count),
                                 [energy_leaving(state, rows, gravity, half_dt)]])
        if comm.size > 1:
            comm.Allreduce(MPI.IN_PLACE, totals, op=MPI.SUM)
        self.counts += np.rint(totals[:count]).astype(np.int64)
        self.masses += totals[count:2 * count]
        self.energy_out += float(totals[-1])
        return taken

    # ------------------------------------------------------------ checkpoints
    def state_dict(self) -> dict:
        return {"names": kinds.scalar(list(self.names)), "counts": kinds.global_array(self.counts),
                "masses": kinds.global_array(self.masses), "energy_out": kinds.scalar(float(self.energy_out))}

    def load_state_dict(self, state: dict) -> None:
        if list(state["names"]) != self.names:
            raise kinds.StateMismatch(f"holds the outlets {list(state['names'])}, the scene has {self.names}")
        self.counts = np.array(state["counts"], dtype=np.int64)
        self.masses = np.array(state["masses"], dtype=float)
        self.energy_out = float(state["energy_out"])
