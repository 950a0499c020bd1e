"""Field output of a running simulation: particles.h5/.xdmf and <solid>.h5/.xdmf written by
Simulation.run every output interval hold exactly the in-memory state, on 1 and 2 ranks (P1 and P2)."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from mpi_harness import run_under_mpi

sys.path.insert(0, str(Path(__file__).parent / "mpi_cases"))

STEPS = 40


def check_files(out: Path, data, plate_temperature: bool) -> None:
    """plate_temperature: the plate was given an initial temperature, so its series has a temperature field
    (a solid that neither conducts nor has a temperature writes none: it was a constant 293.15 K)."""
    import h5py
    import meshio

    time, step = float(data["time"][0]), int(data["time"][1])
    with h5py.File(out / "particles.h5", "r") as handle:
        steps = sorted(int(handle[name].attrs["step"]) for name in handle if name.startswith("step_"))
        assert steps == [0, STEPS // 2, STEPS]
        group = handle[f"step_{step:010d}"]
        assert group.attrs["time"] == time and group.attrs["count"] == len(data["ids"])
        order = np.argsort(group["ids"][()])
        assert np.array_equal(group["ids"][()][order], data["ids"])
        for name in ("positions", "velocities", "radii", "forces", "temperature"):
            assert np.array_equal(group[name][()][order], data[name]), name
    xdmf_text = (out / "particles.xdmf").read_text()
    assert xdmf_text.count("<Grid Name=\"step_") == 3 and "Polyvertex" in xdmf_text

    with meshio.xdmf.TimeSeriesReader(str(out / "plate.xdmf")) as reader:
        points, cells = reader.read_points_cells()
        assert reader.num_steps == 3
        stored_time, point_data, cell_data = reader.read_data(reader.num_steps - 1)
    assert stored_time == pytest.approx(time, rel=1e-15)
    assert [block.type for block in cells] == ["tetra"]
    # Output vertices are the mesh's corner nodes: match them to the solid's nodes by position.
    node_points = data["node_points"]
    lookup = {tuple(p): k for k, p in enumerate(node_points)}
    rows = np.array([lookup[tuple(p)] for p in points])
    assert len(set(rows)) == len(points)
    assert ("temperature" in point_data) == plate_temperature, sorted(point_data)
    nodal = [("displacements", "node_u"), ("velocities", "node_v")]
    for name, key in nodal + ([("temperature", "node_T")] if plate_temperature else []):
        assert np.array_equal(np.asarray(point_data[name]).reshape(len(points), -1),
                              data[key][rows].reshape(len(points), -1)), name
    assert np.abs(data["node_u"]).max() > 0  # the plate moved: the comparison is not 0 == 0
    centroids = points[cells[0].data].mean(axis=1)
    lookup = {tuple(np.round(c, 12)): k for k, c in enumerate(data["cell_centroids"])}
    cell_rows = np.array([lookup[tuple(np.round(c, 12))] for c in centroids])
    assert np.array_equal(cell_data["von_mises"][0], data["cell_von_mises"][cell_rows])


def test_output_serial_p1(tmp_path):
    from mpi4py import MPI

    import restart_output
    import restart_scenes
    from pdemfem.simulation import Simulation

    scene = restart_scenes.heated(restart_scenes.pile_scene(tmp_path, STEPS, STEPS // 2, element="P1"))
    simulation = Simulation.from_dict(scene, comm=MPI.COMM_WORLD, base_dir=tmp_path)
    simulation.run(progress=False)
    check_files(tmp_path, restart_output.dump(simulation), plate_temperature=False)
    assert (tmp_path / "history.csv").read_text().count("\n") == 4


@pytest.mark.mpi
def test_output_two_ranks_p2(tmp_path):
    run_under_mpi(2, "restart_output.py", tmp_path, STEPS, "P2", tmp_path / "state.npz", 310.0)
    data = np.load(tmp_path / "state.npz")
    assert np.all(data["node_T"] == 310.0)
    check_files(tmp_path, data, plate_temperature=True)
