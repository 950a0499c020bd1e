"""MPI case: a step's SUM over the ranks left in flight until the next step's MAX (ParticleSystem.defer_step_sum,
what a Simulation without solids does) gives the same results, bit for bit, as the SUM finished at once
(tests/test_collectives.py).  So does the ghosts' update finished before the forces instead of while the pairs
of two owned particles are computed: a pass that read a ghost before its update arrived (a pair misplaced by
the list's split, a contributor) would read last step's ghost.

The SUM gathered with the next MAX (each rank adding the rows in rank order) and the SUM as an Iallreduce (what
more ranks use) give the same values on 2 ranks, where both add the same two numbers.

usage: deferred_sum_case.py OUT.json

The scene has every reader of the summed values: grains between a spinning cylinder drum, a moving, spinning
mesh lid and a conveyor floor (a plane whose surface moves: its work on the grains is booked from the summed
forces); between calls of Simulation.step the case reads the energies, the contact count, every wall's force,
torque and work, and the history row's mean surface forces.  A stream inserts grains every 10 steps.
"""
import json
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
import pdemfem  # noqa: F401,E402  (environment first)
from mpi4py import MPI  # noqa: E402

CALLS = 12
STEPS_PER_CALL = 7


def scene(folder: Path) -> dict:
    import restart_scenes

    data = restart_scenes.pile_scene(folder, 1000, 1000)
    data["output"] = {"dir": str(folder / "out"), "every": 1.0}
    del data["solids"], data["coupling"]
    data["walls"].append({"name": "floor", "kind": "plane", "point": [0, 0, 0.02], "normal": [0, 0, 1],
                          "material": "grain", "transport_velocity": [0.5, 0.0, 0.0]})
    # A stream inserting above the pile every few steps: its insertion (collective) runs while a step's SUM
    # would otherwise still be in flight.
    feed_box = [[0.07, 0.07, 0.052], [0.13, 0.13, 0.064]]
    data["particles"].append({"name": "feed", "material": "grain", "radius": 0.0045,
                              "insert": {"kind": "stream", "region": {"box": feed_box},
                                         "rate": 20000.0, "velocity": [0.0, 0.0, -1.0], "seed": 2,
                                         "interval": 10 * restart_scenes.DT}})
    return restart_scenes.add_moving_walls(data, folder)


def readings(simulation) -> list:
    """Everything a user or the run loop reads between steps that comes from the step's sums."""
    system = simulation.particle_system
    values = list(simulation.energies().values()) + [simulation.contact_count(), system.walls.work,
                                                     simulation.particle_count()]
    for name in ("drum", "lid"):
        values += list(simulation.wall_force(name)) + list(simulation.wall_torque(name))
    values += list(simulation.wall_force("floor"))
    values += [float(value) for value in simulation.surface_force_means.take(fallback=None).reshape(-1)]
    values += [wall.work for wall in simulation.contributor_walls]
    return [float(value) for value in values]


def run(folder: Path, defer: bool, comm, overlap: bool = True, gathered: bool = True) -> tuple:
    from pdemfem import Simulation
    from pdemfem.parallel.exchange import GhostExchange

    simulation = Simulation.from_dict(scene(folder), comm=comm, base_dir=folder, output_dir=str(folder / "out"),
                                      force=True)
    assert simulation.particle_system.defer_step_sum  # a scene without solids defers by default
    simulation.particle_system.defer_step_sum = defer
    system = simulation.particle_system
    if not gathered:  # the SUM as an Iallreduce, as on more ranks than StepReductions gathers on
        system.reductions.gathered_sum_ranks = 0
    compute_forces = system._compute_forces
    in_flight = [0]

    def counted(*arguments):  # steps whose SUM is still in flight after their force evaluation
        compute_forces(*arguments)
        in_flight[0] += system.reductions.pending
    system._compute_forces = counted
    boundary_pairs = [0]
    if not overlap:  # the whole update before the forces
        exchange = system.ghosts

        def start_and_finish(state):
            GhostExchange.start_update(exchange, state)
            GhostExchange.finish_update(exchange, state)
            boundary_pairs[0] = max(boundary_pairs[0], int(sum(system.neighbors.boundary[2] -
                                                                system.neighbors.boundary[1])))
        exchange.start_update = start_and_finish
        exchange.finish_update = lambda state: None
    rows = []
    for _ in range(CALLS):
        simulation.step(STEPS_PER_CALL)
        rows.append(readings(simulation))
    if not overlap:
        assert system.ghosts is exchange  # no rebalance replaced the patched exchange
    return rows, in_flight[0], boundary_pairs[0]


def main():
    out = sys.argv[1]
    comm = MPI.COMM_WORLD
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(comm.bcast(folder if comm.rank == 0 else None, root=0))
        deferred, deferred_steps, _ = run(folder, True, comm)
        finished, finished_steps, _ = run(folder, False, comm)
        serial_ghosts, _, boundary_pairs = run(folder, True, comm, overlap=False)
        reduced, _, _ = run(folder, True, comm, gathered=False)
        comm.Barrier()
    if comm.rank == 0:
        Path(out).write_text(json.dumps({"ranks": comm.size, "deferred": deferred, "finished": finished,
                                         "steps_in_flight": [deferred_steps, finished_steps],
                                         "serial_ghosts": serial_ghosts, "boundary_pairs": boundary_pairs,
                                         "iallreduce": reduced}))


if __name__ == "__main__":
    main()
