"""Scenes and state dumps shared by tests/test_restart*.py, tests/test_output_scene*.py and the
restart MPI cases."""
from __future__ import annotations

import contextlib

import numpy as np

DT = 4e-5

# The plate starts from a static solve; at the default rtol 1e-10, GAMG on another partition stops at another
# point within it (relative residuals 1.9e-13 on 1 rank, 1.7e-11 on 2: displacements 4e-13 apart), which would
# hide round-off-level differences of the continuation.  At 1e-13 (a decade above the residual's round-off
# floor ~1.5e-14 of this 3x3x1 plate; 8-11 CG iterations on 1-3 ranks) they agree to 7e-15.
CROSS_RANK_STATIC_RTOL = "1e-13"


@contextlib.contextmanager
def cross_rank_static_solve():
    """The static solve converged to CROSS_RANK_STATIC_RTOL while the block runs (PETSc option, then removed)."""
    from petsc4py import PETSc

    options = PETSc.Options()
    options.setValue("fem_ksp_rtol", CROSS_RANK_STATIC_RTOL)
    try:
        yield
    finally:
        options.delValue("fem_ksp_rtol")


def pile_scene(out_dir, steps: int, output_steps: int, checkpoint_steps=None, count: int = 96,
               element: str = "P1", fem_every: int = 2, cells=(3, 3, 1)) -> dict:
    """Grains thrown (2 m/s down, sideways) into a box of plane walls onto a clamped plate (a solid):
    pair, plane-wall and FE-surface contacts with friction within the first ~80 steps."""
    scene = {
        "time": {"end": steps * DT, "dt": DT},
        "gravity": [0.0, 0.0, -9.81],
        "materials": {"grain": {"density": 2500.0, "youngs_modulus": 1e7, "poisson_ratio": 0.3},
                      "plate": {"density": 2700.0, "youngs_modulus": 7e9, "poisson_ratio": 0.33}},
        "interactions": {"default": {"model": "hertz_mindlin", "restitution": 0.3, "friction": 0.5}},
        "particles": [
            {"name": "lower", "material": "grain", "radius": {"min": 0.0045, "max": 0.0055},
             "insert": {"kind": "lattice", "region": {"box": [[0.0556, 0.0556, 0.0256], [0.1444, 0.1444, 0.0368]]},
                        "count": count // 2, "spacing": 0.0112, "jitter": 0.05, "seed": 3,
                        "velocity": [0.6, 0.35, 1.0]}},
            {"name": "upper", "material": "grain", "radius": {"min": 0.0045, "max": 0.0055},
             "insert": {"kind": "lattice", "region": {"box": [[0.0556, 0.0556, 0.0369], [0.1444, 0.1444, 0.05]]},
                        "count": count - count // 2, "spacing": 0.0112, "jitter": 0.05, "seed": 4,
                        "velocity": [-0.5, 0.2, -2.0]}}],
        "walls": [{"name": f"side_{k}", "kind": "plane", "point": point, "normal": normal, "material": "grain"}
                  for k, (point, normal) in enumerate([([0.054, 0, 0], [1, 0, 0]), ([0.146, 0, 0], [-1, 0, 0]),
                                                        ([0, 0.054, 0], [0, 1, 0]), ([0, 0.146, 0], [0, -1, 0])])],
        "solids": [{"name": "plate", "mesh": {"box": [[0, 0, 0], [0.2, 0.2, 0.02]], "cells": list(cells)},
                    "material": "plate", "element": element, "fixed": ["xmin", "xmax", "ymin", "ymax"],
                    "contact": ["zmax"]}],
        "coupling": {"fem_every": fem_every},
        "output": {"dir": str(out_dir), "every": output_steps * DT},
    }
    if checkpoint_steps is not None:
        scene["checkpoint"] = {"every": checkpoint_steps * DT, "keep": 10}
    return scene


def cohesive(scene: dict) -> dict:
    """The pile with JKR adhesion (F_c = 3/2 pi W R* about a grain's weight) and elastic-plastic rolling
    resistance: contact history of 11 columns (tangential spring and its last applied force, rolling spring, their
    energy, touching flag) on pairs, plane walls and the FE surface."""
    scene["interactions"]["default"].update(model="jkr", work_of_adhesion=1.0, rolling_friction=0.1,
                                            rolling_model="elastic_plastic")
    return scene


def heated(scene: dict) -> dict:
    """The pile with heat on: the two grain groups start at 350 K and 300 K, side_0 is held at 400 K, and the
    grains' small heat capacity (dt sum(H) / (m c) ~ 0.05 per contact) lets the contacts move heat visibly
    within the run (temperatures in the checkpoint, on the ghosts every step, the wall's heat ledger)."""
    scene["materials"]["grain"].update(conductivity=1.0, heat_capacity=2.0e-3)
    scene["particles"][0]["initial_temperature"] = 350.0
    scene["particles"][1]["initial_temperature"] = 300.0
    scene["walls"][0]["temperature"] = 400.0
    return scene


def moving(scene: dict) -> dict:
    """The pile with the plate carried by a prescribed rigid motion (spinning about a tilted axis through its
    centre and translating): its surface, loads and dashpots in a moving frame, the frame's work booked."""
    scene["solids"][0]["motion"] = {"axis_point": [0.1, 0.1, 0.0], "angular_velocity": [0.5, 0.0, 5.0],
                                    "velocity": [0.1, 0.0, 0.0]}
    return scene


def free_axle(scene: dict) -> dict:
    """The moving pile with the plate's axis free along z under a carried mass (sinking under gravity and the
    grains' impacts): the axis's height, rate and acceleration in the checkpoint, one reduction per advance."""
    scene = moving(scene)
    scene["solids"][0]["motion"]["carried_mass"] = 5.0
    return scene


def gather_state(simulation) -> dict | None:
    """Everything compared between runs, gathered to rank 0 and sorted by particle id."""
    comm = simulation.comm
    system = simulation.particle_system
    state = system.state
    owned = state.owned_count
    local = {"ids": state.ids[:owned], "positions": state.positions[:owned],
             "velocities": state.velocities[:owned], "angular_velocities": state.angular_velocities[:owned],
             "forces": state.forces[:owned]}
    for name, values in state.fields.items():
        local["field:" + name] = values[:owned]
    gathered = comm.gather(local, root=0)
    # The contact history of the particle pairs and the plane walls, keyed by (owner id, partner key): one
    # record per owned particle of a pair on any rank count, as checkpoints hold them.
    records = comm.gather(system.neighbors.contact_records(state.ids, owned, system.walls.candidates).copy(), root=0)
    solids = {}
    for name, solid in simulation.solids.items():
        rows = comm.gather((np.asarray(solid.original_node_ids), solid.displacements, solid.velocities), root=0)
        if comm.rank == 0:
            ids = np.concatenate([r[0] for r in rows])
            order = np.argsort(ids)
            solids[f"solid:{name}:u"] = np.concatenate([r[1] for r in rows])[order]
            solids[f"solid:{name}:v"] = np.concatenate([r[2] for r in rows])[order]
    energies = simulation.energies()
    # Part of dissipated_energy, but far below its last bit in these runs: compared on its own, as its two running
    # sums (the particles' correction and the solid's dashpot work): their difference cancels most of their
    # digits, so its round-off between rank counts is the sums' size, not its own.
    if simulation.solids:
        coupling = simulation.coupling
        dashpot = comm.allreduce(np.array([sum(surface.dissipation_correction_local for surface in coupling.surfaces),
                                           sum(solid.damper_work_local for solid in coupling.solids.values())]))
    else:
        dashpot = np.zeros(2)
    heat_given = simulation.heat_given() if system.heat else {}
    heat_carried = simulation.heat_carried() if system.heat else {}
    if comm.rank != 0:
        return None
    result = {}
    for key in gathered[0]:
        result[key] = np.concatenate([g[key] for g in gathered])
    order = np.argsort(result["ids"])
    result = {key: values[order] for key, values in result.items()}
    result.update(solids)
    records = np.concatenate(records)
    result["contact_records"] = records[np.lexsort((records[:, 1], records[:, 0]))]
    result["energies"] = np.array([energies[k] for k in sorted(energies)])
    result["dashpot_correction"] = dashpot[:1]
    result["dashpot_damper_work"] = dashpot[1:]
    result["scalars"] = np.array([simulation.step_count, system.lost_particles, simulation.time])
    if system.heat:
        result["heat_given"] = np.array(list(heat_given.values()))
        result["heat_carried"] = np.array(list(heat_carried.values()))
    return result


LID_STL = """solid lid
facet normal 0 0 -1
outer loop
vertex 0.04 0.04 0.0485
vertex 0.16 0.16 0.0485
vertex 0.16 0.04 0.0485
endloop
endfacet
facet normal 0 0 -1
outer loop
vertex 0.04 0.04 0.0485
vertex 0.04 0.16 0.0485
vertex 0.16 0.16 0.0485
endloop
endfacet
endsolid lid
"""


def add_moving_walls(scene: dict, out_dir) -> dict:
    """A spinning drum (cylinder) round the grains and a spinning mesh lid pressed down onto them
    (writes lid.stl into out_dir, which must exist)."""
    import os
    from pathlib import Path

    # Every rank builds the scene: each writes its own file and renames it into place, so a rank reading the
    # lid never meets another's half-written (truncated) copy.
    own_copy = Path(out_dir) / f"lid.stl.{os.getpid()}"
    own_copy.write_text(LID_STL)
    os.replace(own_copy, Path(out_dir) / "lid.stl")
    scene["walls"] += [
        {"name": "drum", "kind": "cylinder", "material": "grain", "radius": 0.0585,
         "axis": {"point": [0.1, 0.1, 0.0], "direction": [0, 0, 1]}, "angular_velocity": [0, 0, 20.0]},
        {"name": "lid", "kind": "mesh", "material": "grain", "file": str(Path(out_dir) / "lid.stl"),
         "velocity": [0, 0, -2.5], "center": [0.1, 0.1, 0.0485], "angular_velocity": [0, 0, 5.0]}]
    return scene
