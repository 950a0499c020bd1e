"""MPI case: write the particle and solid series from rank-local data.

    io_output.py OUT_DIR [--resume-check]

Writes PARTICLE_STEPS of io_data into OUT_DIR/particles.{h5,xdmf} and three steps of
the box tet mesh into OUT_DIR/block.{h5,xdmf}; tests/test_io_output.py reads them back.
With --resume-check it then reopens both series with resume_step=10 and writes step 30,
so the files must hold steps 0, 10, 30.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
import pdemfem  # noqa: E402,F401
from mpi4py import MPI  # noqa: E402

import io_data  # noqa: E402
from pdemfem.io.particle_output import DEFAULT_FIELDS, ParticleOutput  # noqa: E402
from pdemfem.io.solid_output import SolidOutput  # noqa: E402

comm = MPI.COMM_WORLD
out = Path(sys.argv[1])
resume_check = "--resume-check" in sys.argv

particles = ParticleOutput(out, comm, DEFAULT_FIELDS)
for step, time, count in io_data.PARTICLE_STEPS:
    ids = io_data.rank_particle_ids(count, comm.rank, comm.size, step)
    particles.write(time, step, io_data.particle_arrays(ids, step))
particles.close()  # the index up to the last step (rewritten after a step only now and then)

points, cells = io_data.box_tet_mesh()
owned_points, owned_cells, first = io_data.split_mesh(points, cells, comm.rank, comm.size)
solid = SolidOutput(out, "block", comm, owned_points, owned_cells, first)
for step in (0, 10, 20):
    solid.write(step * 1.0e-4, step, io_data.nodal_fields(owned_points, step),
                io_data.cell_fields(points, owned_cells, step))
solid.close()

if resume_check:
    particles = ParticleOutput(out, comm, DEFAULT_FIELDS, resume_step=10)
    ids = io_data.rank_particle_ids(99, comm.rank, comm.size, 30)
    particles.write(3.0e-3, 30, io_data.particle_arrays(ids, 30))
    particles.close()
    solid = SolidOutput(out, "block", comm, owned_points, owned_cells, first, resume_step=10)
    solid.write(3.0e-3, 30, io_data.nodal_fields(owned_points, 30), io_data.cell_fields(points, owned_cells, 30))
    solid.close()
