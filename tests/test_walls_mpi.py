"""Mesh and cylinder walls on 1 and 2 ranks: each particle's wall contacts are computed by the rank that
owns it, and the wall totals (force, torque) are summed over ranks exactly once."""
from __future__ import annotations

import textwrap

import numpy as np
import pytest

from mpi_harness import run_under_mpi

SCRIPT = textwrap.dedent('''
    import sys
    import numpy as np
    import meshio
    from mpi4py import MPI
    from pdemfem.simulation import Simulation

    out, folder = sys.argv[1], sys.argv[2]
    comm = MPI.COMM_WORLD
    x = np.linspace(-0.12, 0.12, 9)
    xx, yy = np.meshgrid(x, x, indexing="ij")
    points = np.column_stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)])
    triangles = []
    for i in range(8):
        for j in range(8):
            a = i * 9 + j
            triangles += [[a, a + 9, a + 10], [a, a + 10, a + 1]]
    if comm.rank == 0:
        meshio.write(folder + "/floor.msh", meshio.Mesh(points, [("triangle", np.array(triangles))]),
                     file_format="gmsh22", binary=True)
    comm.Barrier()
    radius = 0.005
    # A ring of 8 spheres pressed against the drum's mantle plus one in the middle, all on the mesh
    # floor, far apart from each other: only wall contacts.
    angles = np.linspace(0.0, 2.0 * np.pi, 8, endpoint=False) + 0.1
    ring = np.column_stack([0.095002 * np.cos(angles), 0.095002 * np.sin(angles), np.full(8, radius - 2e-5)])
    positions = np.vstack([ring, [[0.013, -0.021, radius - 1e-5]]])
    velocities = np.column_stack([np.zeros(9), np.zeros(9), np.full(9, -0.05)])
    scene = {
        "time": {"end": 1.0, "dt": 1e-6},
        "materials": {"glass": {"density": 2500.0, "youngs_modulus": 1.0e8, "poisson_ratio": 0.25},
                      "steel": {"density": 7800.0, "youngs_modulus": 2.0e11, "poisson_ratio": 0.3}},
        "particles": [{"name": "p", "material": "glass", "radius": radius,
                       "insert": {"kind": "list", "positions": positions.tolist(),
                                  "velocities": velocities.tolist()}}],
        "walls": [{"name": "floor", "kind": "mesh", "material": "steel", "file": "floor.msh",
                   "angular_velocity": [0, 0, 1.0]},
                  {"name": "drum", "kind": "cylinder", "material": "steel", "radius": 0.1,
                   "axis": {"point": [0, 0, 0], "direction": [0, 0, 1]}, "angular_velocity": [0, 0, 2.0]}],
    }
    sim = Simulation.from_dict(scene, base_dir=folder, output_dir=folder + "/out")
    sim.step(100)
    mine = sim.particles
    gathered = comm.gather((mine.ids, mine.positions), root=0)
    about = np.array([0.01, 0.02, 0.03])
    totals = np.concatenate([sim.wall_force("floor"), sim.wall_torque("floor", about),
                             sim.wall_force("drum"), sim.wall_torque("drum", about)])
    everywhere = comm.allgather(totals)
    assert all(np.array_equal(everywhere[0], t) for t in everywhere), "ranks disagree on wall totals"
    if comm.rank == 0:
        ids = np.concatenate([g[0] for g in gathered])
        order = np.argsort(ids)
        np.savez(out, ids=ids[order], positions=np.concatenate([g[1] for g in gathered])[order], totals=totals,
                 contacts=sim.contact_count())
''')


@pytest.mark.mpi
def test_wall_totals_agree_on_one_and_two_ranks(tmp_path):
    script = tmp_path / "walls_case.py"
    script.write_text(SCRIPT)
    results = {}
    for ranks in (1, 2):
        out = tmp_path / f"walls_{ranks}.npz"
        run_under_mpi(ranks, script, str(out), str(tmp_path))
        results[ranks] = np.load(out)
    serial, parallel = results[1], results[2]
    assert int(serial["contacts"]) == int(parallel["contacts"]) >= 17  # 9 on the floor, 8 on the drum
    assert np.array_equal(serial["ids"], parallel["ids"])
    # The particles never touch each other, so each one's force is computed identically on any rank:
    # positions agree to round-off (1e-15 m on 0.1 m; measured identical).  The totals are sums of the n
    # contact terms in a different order (per-rank partial sums): the recursive-summation bound is
    # (n - 1) eps sum |term| <= (n - 1) n eps x the largest total (each term is at most the floor's total,
    # whose contacts all push the same way), 6e-14 for n = 17; measured 1.7e-17.
    np.testing.assert_allclose(parallel["positions"], serial["positions"], rtol=0, atol=1e-15)
    scale = np.abs(serial["totals"]).max()
    terms = int(serial["contacts"])
    np.testing.assert_allclose(parallel["totals"], serial["totals"], rtol=0,
                               atol=(terms - 1) * terms * np.finfo(float).eps * scale)
