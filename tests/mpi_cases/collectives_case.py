"""MPI case: count the collective calls each step makes (tests/test_collectives.py).

usage: collectives_case.py KIND OUT.json STEPS
KIND: planes (a dense pile in a box of plane walls), walls (grains thrown at a spinning
cylinder drum and a moving mesh lid, plane side walls) or coupled (the same grains onto a
clamped FE plate, fem_every 1).

The simulation runs on a communicator whose class counts every mpi4py collective call
(`Dup` keeps the subclass, so the simulation's private duplicates count too).  PETSc's own
communication (the FE solid's Vec scatters and norms) does not pass through mpi4py: it is
counted from PETSc's event log.  Rank 0 writes, per step, the mpi4py collectives by name and
the PETSc scatter/reduction events.  `Simulation.step` is called one step at a time: the
run loop's stop checks (every STOP_CHECK_EVERY steps) and output steps are not part of it.
"""
import collections
import json
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
import pdemfem  # noqa: F401,E402  (environment first)
from mpi4py import MPI  # noqa: E402

COLLECTIVES = ("allreduce", "Allreduce", "Iallreduce", "allgather", "Allgather", "Allgatherv", "alltoall",
               "Alltoall", "Alltoallv", "bcast", "Bcast", "gather", "Gather", "Gatherv", "scatter", "Scatter",
               "Scatterv", "reduce", "Reduce", "Barrier", "Ibarrier", "Exscan", "Scan", "exscan", "scan")
# PETSc events that communicate across ranks: scatters (ghost updates, the surface gather), the global
# reductions of norms and dot products, and assembly of off-rank additions.
PETSC_EVENTS = ("VecScatterBegin", "VecNorm", "VecDot", "VecMDot", "VecAssemblyBegin", "SFBcastBegin",
                "SFReduceBegin", "PetscSFBcastBegin", "PetscSFReduceBegin")

calls = collections.Counter()


class CountingComm(MPI.Intracomm):
    """The same communicator handle; every collective call is counted by name."""
    # petsc4py takes a communicator from mpi4py by its class's module (the solid's PETSc objects).
    __module__ = "mpi4py.MPI"


def _counted(name):
    method = getattr(MPI.Intracomm, name)

    def counted(self, *args, **kwargs):
        calls[name] += 1
        return method(self, *args, **kwargs)
    counted.__name__ = name
    return counted


for _name in COLLECTIVES:
    if hasattr(MPI.Intracomm, _name):
        setattr(CountingComm, _name, _counted(_name))


def scene(kind: str, folder: Path) -> dict:
    import restart_scenes
    from dem_scenes import dense_scene

    if kind == "planes":
        return dense_scene(count=200)
    data = restart_scenes.pile_scene(folder, 1000, 1000)
    data["output"] = {"dir": str(folder / "out"), "every": 1.0}
    if kind == "walls":
        del data["solids"], data["coupling"]
        data["walls"].append({"name": "floor", "kind": "plane", "point": [0, 0, 0.02], "normal": [0, 0, 1],
                              "material": "grain"})
        return restart_scenes.add_moving_walls(data, folder)
    if kind == "coupled":
        data["coupling"] = {"fem_every": 1}
        return data
    if kind == "heated":
        # The coupled scene with heat on: grains, a hot wall and the plate conduct (temperatures on the
        # ghosts, the walls' heat ledger, the plate's surface temperatures and nodal heat every advance).
        data = restart_scenes.heated(data)
        data["materials"]["plate"].update(conductivity=200.0, heat_capacity=900.0)
        data["coupling"] = {"fem_every": 1}
        return data
    raise SystemExit(f"unknown kind {kind}")


def petsc_counts() -> dict:
    from petsc4py import PETSc

    counts = {}
    for name in PETSC_EVENTS:
        try:
            counts[name] = int(PETSc.Log.Event(name).getPerfInfo()["count"])
        except Exception:  # an event this PETSc version does not have
            continue
    return counts


def main():
    kind, out, steps = sys.argv[1], sys.argv[2], int(sys.argv[3])
    from petsc4py import PETSc

    PETSc.Log.begin()
    from pdemfem import Simulation

    comm = CountingComm(MPI.COMM_WORLD)
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(comm.bcast(folder if comm.rank == 0 else None, root=0))
        simulation = Simulation.from_dict(scene(kind, folder), comm=comm, base_dir=folder,
                                          output_dir=str(folder / "out"))
        # Past construction and the first rebuilds; the dense pile falls 0.2 mm onto the floor first.
        simulation.step(120 if kind == "planes" else 5)
        per_step = []
        for _ in range(steps):
            calls.clear()
            before = petsc_counts()
            rebuilds_before = simulation.particle_system.state.positions_at_build
            simulation.step(1)
            after = petsc_counts()
            per_step.append({"mpi4py": dict(calls),
                             "petsc": {name: after[name] - before.get(name, 0) for name in after
                                       if after[name] != before.get(name, 0)},
                             "rebuild": simulation.particle_system.state.positions_at_build is not rebuilds_before})
        # Within one call of several steps: each ParticleSystem.step's collectives (a SUM left pending travels
        # with the next step's MAX).
        system = simulation.particle_system
        step_alone = system.step
        in_call = []

        def counted_step():
            calls.clear()
            build_before = system.state.positions_at_build
            step_alone()
            in_call.append({"mpi4py": dict(calls), "rebuild": system.state.positions_at_build is not build_before})
        system.step = counted_step
        simulation.step(steps)
        system.step = step_alone
        contacts = simulation.contact_count()
        comm.Barrier()
    if comm.rank == 0:
        Path(out).write_text(json.dumps({"kind": kind, "ranks": comm.size, "contacts": contacts,
                                         "steps": per_step, "steps_in_one_call": in_call}, indent=1))


if __name__ == "__main__":
    main()
