"""MPI case: a wide plate under grains, the coupled surface's partial gather (tests/test_coupling_partial_gather.py).

usage: partial_gather_case.py OUT.npz CASE STEPS [MODE]
CASE  spread: grains over the whole 0.4 m plate, settling (each rank's share of the surface is part of it);
      fall:   grains 5 cm above the plate falling onto it (first selection empty: the particles must
              bring the plate into their selection as they come down);
      rise:   no gravity, grains at rest 5 cm above the plate, which is driven up into them at 2 m/s
              (the surface must bring itself into the selection as it moves);
      stream: spread plus a stream of grains over the plate (the scene keeps the whole gather);
      hot:    spread with heat (grains at 500 K, the plate at 300 K conducts) and fem_every 3 (the surface
              temperatures gathered, the contacts' heat and dashpots of 3-step windows sent to the plate).
MODE  whole: the whole gather (CoupledSurface.partial_gather off); frozen: the partial gather whose
      selection is never made anew after the first one (the negative control); ulp (serial): particle 0
      shifted by one unit in the last place of x (the round-off growth reference); default: partial.
Writes (rank 0) the particles by id, the surface force history, every rank's largest selection (nodes),
the surface's node count and the number of selections.
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import pdemfem  # noqa: F401,E402  (environment first)
from mpi4py import MPI  # noqa: E402

from pdemfem import Simulation  # noqa: E402
from pdemfem.coupling.surface import CoupledSurface  # noqa: E402


def wide_plate(case: str) -> dict:
    top = 0.02
    if case in ("spread", "hot", "stream"):
        region, velocity, gravity = [[0.01, 0.01, 0.026], [0.39, 0.09, 0.05]], [0.0, 0.0, 0.0], -9.81
    elif case == "fall":
        region, velocity, gravity = [[0.01, 0.01, 0.075], [0.39, 0.09, 0.1]], [0.0, 0.0, -2.0], -9.81
    else:
        region, velocity, gravity = [[0.01, 0.01, 0.075], [0.39, 0.09, 0.1]], [0.0, 0.0, 0.0], 0.0
    plate = {"name": "plate", "mesh": {"box": [[0, 0, 0], [0.4, 0.1, top]], "cells": [32, 4, 1]},
             "material": "plate", "element": "P1", "contact": ["zmax"], "damping": {"alpha": 2000.0, "beta": 0.0}}
    if case == "rise":
        plate["prescribed"] = [{"group": group, "velocity": [0.0, 0.0, 2.0]} for group in ("xmin", "xmax")]
    else:
        plate["fixed"] = ["xmin", "xmax"]
    scene = {
        "time": {"end": 1.0, "dt": 4e-5},
        "gravity": [0.0, 0.0, gravity],
        "materials": {"grain": {"density": 2500.0, "youngs_modulus": 1e7, "poisson_ratio": 0.3},
                      "plate": {"density": 2700.0, "youngs_modulus": 7e9, "poisson_ratio": 0.33}},
        "interactions": {"default": {"model": "hertz_mindlin", "restitution": 0.3, "friction": 0.5}},
        "particles": [{"name": "grains", "material": "grain", "radius": {"min": 0.0045, "max": 0.0055},
                       "insert": {"kind": "random", "region": {"box": region}, "count": 48, "seed": 5,
                                  "velocity": velocity}}],
        "solids": [plate],
    }
    if case == "stream":
        scene["particles"].append({"name": "poured", "material": "grain", "radius": {"min": 0.0045, "max": 0.0055},
                                   "insert": {"kind": "stream",
                                              "region": {"box": [[0.3, 0.02, 0.06], [0.38, 0.08, 0.08]]},
                                              "rate": 2000.0, "interval": 0.01, "seed": 3}})
    if case == "hot":
        scene["materials"]["grain"].update(conductivity=1.0, heat_capacity=0.5)
        scene["materials"]["plate"].update(conductivity=200.0, heat_capacity=0.9)
        scene["particles"][0]["initial_temperature"] = 500.0
        plate.update(initial_temperature=300.0, reference_temperature=300.0)
        scene["coupling"] = {"fem_every": 3}
    return scene


def main():
    out, case, steps = sys.argv[1], sys.argv[2], int(sys.argv[3])
    mode = sys.argv[4] if len(sys.argv) > 4 else "partial"
    comm = MPI.COMM_WORLD
    if mode == "whole":
        CoupledSurface.partial_gather = False
    elif mode == "frozen":
        from pdemfem.coupling import selection

        # Keep the first selection for the whole run: the particle region and the surface never count as moved.
        selection.region_within = lambda inner, outer, slack: outer is not None
        selection.SurfaceSelection.drift = lambda self, *arguments: 0.0
    from petsc4py import PETSc

    PETSc.Options().setValue("fem_ksp_rtol", "1e-13")  # as coupling_agreement.py: partitions agree on the start
    sim = Simulation.from_dict(wide_plate(case), comm=comm, output_dir=str(Path(out).parent / "unused"))
    surface = sim.coupled_surfaces[0]
    if mode == "ulp":
        state = sim.particle_system.state
        row = np.nonzero(state.ids == 0)[0]
        state.positions[row, 0] += np.spacing(state.positions[row, 0])
    largest_selection = 0
    forces = []
    for _ in range(steps):
        sim.step()
        forces.append(sim.wall_force("plate"))
        if surface.selection is not None:
            largest_selection = max(largest_selection, len(surface.selection.rows))
        else:
            largest_selection = len(surface.node_indices)
    p = sim.particles
    ids = comm.gather(p.ids, root=0)
    positions = comm.gather(p.positions, root=0)
    velocities = comm.gather(p.velocities, root=0)
    temperatures = comm.gather(p.temperatures if p.temperatures is not None else np.zeros(len(p.ids)), root=0)
    selected = comm.gather(largest_selection, root=0)
    if comm.rank == 0:
        ids = np.concatenate(ids)
        order = np.argsort(ids)
        np.savez(out, ids=ids[order], positions=np.concatenate(positions)[order],
                 velocities=np.concatenate(velocities)[order], forces=np.array(forces),
                 temperatures=np.concatenate(temperatures)[order],
                 selected=np.array(selected), nodes=len(surface.node_indices), selections=surface.selections)


if __name__ == "__main__":
    main()
