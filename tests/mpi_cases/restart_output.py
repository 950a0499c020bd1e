"""MPI case: run restart_scenes.pile_scene with field output, dump the in-memory state.

    restart_output.py OUT STEPS ELEMENT RESULT.npz [PLATE_TEMPERATURE]

Output every STEPS/2 steps; rank 0 writes the final in-memory state to RESULT.npz:
particles sorted by id, the solid's nodes (reference coordinates, u, v, T) and cells
(centroid of the corners, von Mises), for tests/test_output_scene.py to compare with
what particles.h5 and plate.xdmf hold.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
import pdemfem  # noqa: E402,F401
import numpy as np  # noqa: E402
from mpi4py import MPI  # noqa: E402

import restart_scenes  # noqa: E402
from pdemfem.simulation import Simulation  # noqa: E402


def dump(simulation) -> dict | None:
    comm = simulation.comm
    state = simulation.particle_system.state
    n = state.owned_count
    local = {"ids": state.ids[:n], "positions": state.positions[:n], "velocities": state.velocities[:n],
             "radii": state.radii[:n], "forces": state.forces[:n], "temperature": state.temperatures[:n]}
    solid = simulation.solids["plate"]
    mesh = solid.mesh
    owned = solid.n_owned_nodes
    corners = mesh.points[mesh.cells[: mesh.n_owned_cells, :4]]
    local.update({"node_points": mesh.points[:owned], "node_u": solid.displacements, "node_v": solid.velocities,
                  "node_T": solid.temperatures, "cell_centroids": corners.mean(axis=1),
                  "cell_von_mises": solid.von_mises})
    gathered = comm.gather(local, root=0)
    if comm.rank != 0:
        return None
    result = {key: np.concatenate([g[key] for g in gathered]) for key in gathered[0]}
    order = np.argsort(result["ids"])
    for key in ("ids", "positions", "velocities", "radii", "forces", "temperature"):
        result[key] = result[key][order]
    result["time"] = np.array([simulation.time, simulation.step_count])
    return result


if __name__ == "__main__":
    comm = MPI.COMM_WORLD
    out, steps, element, result = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
    scene = restart_scenes.heated(restart_scenes.pile_scene(out, steps, steps // 2, element=element))
    if len(sys.argv) > 5:  # the plate's initial temperature (no thermal load: the reference defaults to it)
        scene["solids"][0]["initial_temperature"] = float(sys.argv[5])
    simulation = Simulation.from_dict(scene, comm=comm, base_dir=out)
    simulation.run(progress=False)
    data = dump(simulation)
    if comm.rank == 0:
        np.savez(result, **data)
