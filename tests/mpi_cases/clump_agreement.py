"""MPI case: clumps thrown at each other across the rank cuts (tests/test_clumps_parallel.py).

usage: clump_agreement.py OUT.npz STEPS [ulp] [checkpoint EVERY] [restart FILE]
Writes (rank 0) the bodies' state and the member spheres' positions sorted by id after STEPS
steps (output folder: OUT's name beside it).  "ulp" (serial only) shifts every body by one unit in
the last place of its x coordinate before the run: the round-off growth reference.  "checkpoint
EVERY": the run writes a checkpoint every EVERY steps; "restart FILE" continues from that checkpoint.
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import pdemfem  # noqa: F401,E402  (environment first)
from mpi4py import MPI  # noqa: E402

from pdemfem import Simulation  # noqa: E402

RADIUS = 1e-3


def clump_scene(steps_end=None):
    """24 three-sphere clumps in a long box (x), thrown towards the middle, falling onto a floor:
    the RCB cuts along x run through clumps and their contacts."""
    spheres = [{"position": [0, 0, 0], "radius": RADIUS}, {"position": [1.4 * RADIUS, 0, 0], "radius": 0.8 * RADIUS},
               {"position": [0, 0, 1.3 * RADIUS], "radius": 0.7 * RADIUS}]
    groups = [{"name": f"side{k}", "material": "glass", "clump": {"spheres": spheres},
               "insert": {"kind": "random", "count": 12, "seed": 3 + k, "velocity": [velocity, 0, -0.3],
                          "region": {"box": [[x0, -4e-3, 0], [x0 + 0.012, 4e-3, 8e-3]]}}}
              for k, (x0, velocity) in enumerate([(-0.013, 0.6), (0.001, -0.6)])]
    return {"time": {"end": 1.0, "dt": "auto"}, "gravity": [0, 0, -9.81],
            "materials": {"glass": {"density": 2500, "youngs_modulus": 1e7, "poisson_ratio": 0.25}},
            "interactions": {"default": {"model": "hertz_mindlin", "restitution": 0.5, "friction": 0.5}},
            "particles": groups,
            "walls": [{"name": "floor", "kind": "plane", "point": [0, 0, 0], "normal": [0, 0, 1], "material": "glass"},
                      {"name": "south", "kind": "plane", "point": [0, -5e-3, 0], "normal": [0, 1, 0],
                       "material": "glass"},
                      {"name": "north", "kind": "plane", "point": [0, 5e-3, 0], "normal": [0, -1, 0],
                       "material": "glass"}],
            "output": {"dir": "out", "every": 1.0, "particles": []}}


def main():
    out, steps = Path(sys.argv[1]), int(sys.argv[2])
    options = sys.argv[3:]
    comm = MPI.COMM_WORLD
    scene = clump_scene()
    restart = None
    if "restart" in options:
        restart = options[options.index("restart") + 1]
    if "checkpoint" in options:  # run to STEPS, a checkpoint every EVERY steps
        every = int(options[options.index("checkpoint") + 1])
        dt = Simulation.from_dict(scene, comm=comm, output_dir=str(out.parent / "probe")).dt
        scene["time"]["end"] = steps * dt
        scene["checkpoint"] = {"every": every * dt, "keep": 10}
    sim = Simulation.from_dict(scene, comm=comm, output_dir=str(out.parent / out.stem), restart=restart)
    if "ulp" in options:
        bodies = sim.particle_system.clumps
        bodies.positions[:, 0] += np.spacing(bodies.positions[:, 0])
    if "checkpoint" in options:
        sim.run(progress=False)
    else:
        sim.step(steps - sim.step_count)
    c, p = sim.clumps, sim.particles
    gathered = {name: comm.gather(getattr(c, name), root=0)
                for name in ("ids", "positions", "orientations", "velocities", "angular_velocities")}
    member_ids, member_positions = comm.gather(p.ids, root=0), comm.gather(p.positions, root=0)
    contacts = sim.contact_count()
    energies = sim.energies()
    state = sim.particle_system.state
    # Members held as ghosts (their body is on another rank) and bodies whose members stick out of
    # this rank's box: the cuts run through clumps.
    ghost_members = comm.allreduce(int((state.fields["clump_body"][state.owned_count:] >= 0).sum()))
    lower, upper = sim.particle_system.decomposition.boxes[comm.rank] if comm.size > 1 else (None, None)
    outside = (0 if lower is None else
               int(np.any((p.positions < lower) | (p.positions > upper), axis=1).sum()))
    members_outside = comm.allreduce(outside)
    if comm.rank == 0:
        order = np.argsort(np.concatenate(gathered["ids"]))
        member_order = np.argsort(np.concatenate(member_ids))
        np.savez(out, **{name: np.concatenate(values)[order] for name, values in gathered.items()},
                 member_ids=np.concatenate(member_ids)[member_order],
                 member_positions=np.concatenate(member_positions)[member_order], contacts=contacts,
                 kinetic=energies["kinetic_energy"], rotational=energies["rotational_energy"], ranks=comm.size,
                 ghost_members=ghost_members, members_outside=members_outside,
                 dt=sim.dt, step=sim.step_count)


if __name__ == "__main__":
    main()
