"""MPI case: coupled scenes on any rank count, gathered by particle id (tests/test_coupling_parallel.py).

usage: coupling_agreement.py OUT.npz CASE STEPS [ulp]
CASE: ball (ball on block, P1), pile (pile on plate, P2), pile_blended (the same with the blended gap) or
pile_window (fem_every 3).  Writes (rank 0) particle positions and
velocities by id, the surface force, the support reaction and the solid's surface node positions.
"ulp" (serial) shifts every particle's x by one unit in the last place of the largest coordinate: the
round-off growth reference.
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import pdemfem  # noqa: F401,E402  (environment first)
from mpi4py import MPI  # noqa: E402

from coupling_scenes import ball_on_block, pile_on_plate  # noqa: E402
from pdemfem import Simulation  # noqa: E402


def main():
    out, case, steps = sys.argv[1], sys.argv[2], int(sys.argv[3])
    perturb = len(sys.argv) > 4 and sys.argv[4] == "ulp"
    comm = MPI.COMM_WORLD
    if case == "ball":
        scene, name, supports = ball_on_block(height=0.701, speed=2.4, cells=(3, 3, 2)), "block", ["zmin"]
    elif case == "pile_window":
        # Sub-cycling: the contact dashpots of a 3-step window reach the solid at its end, and those of
        # particles that changed rank within the window are balanced on their new rank.
        import restart_scenes

        scene = restart_scenes.pile_scene(Path(out).parent / "unused", steps, steps, fem_every=3)
        scene.pop("checkpoint", None)
        name, supports = "plate", ["xmin", "xmax", "ymin", "ymax"]
    else:
        scene, name, supports = pile_on_plate(element="P2", count=120, cells=(3, 3, 1)), "plate", ["xmin", "xmax"]
        if case == "pile_blended":
            # The blended gap: its contact springs over the plate's FE sub-steps are balanced on their particles.
            scene.setdefault("coupling", {})["transfer"] = "blended"
    from petsc4py import PETSc

    # The solids' static start converged far below the default rtol 1e-10 (a decade above the residual's
    # round-off floor), so that partitions do not stop at different points within it: the FE-derived results
    # then differ between rank counts by round-off, as the particles do.
    PETSc.Options().setValue("fem_ksp_rtol", "1e-13")
    sim = Simulation.from_dict(scene, comm=comm, output_dir=str(Path(out).parent / "unused"))
    if perturb:
        state = sim.particle_system.state
        # Every particle by one unit in the last place of the scene's coordinates: shifting particle 0 alone left
        # the pile's forces and velocities unchanged bit for bit (it touched nothing in the window), an empty
        # reference.
        owned = state.owned_count
        state.positions[:owned, 0] += np.spacing(np.abs(state.positions[:owned]).max())
    forces = []
    for _ in range(steps):
        sim.step()
        forces.append(sim.wall_force(name))
    p = sim.particles
    ids = comm.gather(p.ids, root=0)
    positions = comm.gather(p.positions, root=0)
    velocities = comm.gather(p.velocities, root=0)
    reaction = sum(sim.solid_reaction(name, group) for group in supports)
    _, surface, _ = sim.solids[name].surface_state()  # identical on every rank
    reference = sim.solids[name].contact_surface().reference_positions
    # Node numbers depend on the partition: order the surface nodes by their reference position.
    order = np.lexsort(np.round(reference, 9).T[::-1])
    surface = (surface - reference)[order]
    if comm.rank == 0:
        ids = np.concatenate(ids)
        order = np.argsort(ids)
        np.savez(out, ids=ids[order], positions=np.concatenate(positions)[order],
                 velocities=np.concatenate(velocities)[order], forces=np.array(forces), reaction=reaction,
                 surface=surface, substeps=sim.coupling.fem_substeps[name])


if __name__ == "__main__":
    main()
