"""Particle and solid XDMF/HDF5 output: what any rank count writes reads back exactly.

The MPI case tests/mpi_cases/io_output.py writes deterministic data (tests/mpi_cases/io_data.py)
from rank-local slabs; here it is read back with h5py, meshio's TimeSeriesReader and,
when Debian's paraview is installed, ParaView's own Xdmf3 reader (pvpython).
"""
from __future__ import annotations

import shutil
import sys
import xml.etree.ElementTree as ET

import h5py
import meshio
import numpy as np
import pytest

from mpi_harness import CASES, paraview_views, run_under_mpi

sys.path.insert(0, str(CASES))
import io_data  # noqa: E402

from pdemfem.io import xdmf  # noqa: E402


@pytest.fixture(scope="module", params=[1, 2, 3])
def written(request, tmp_path_factory):
    out = tmp_path_factory.mktemp(f"io_{request.param}ranks")
    run_under_mpi(request.param, "io_output.py", out)
    return request.param, out


@pytest.mark.mpi
def test_particle_values_read_back(written):
    ranks, out = written
    with h5py.File(out / "particles.h5", "r") as handle:
        groups = sorted(k for k in handle if k.startswith("step_"))
        assert [int(handle[g].attrs["step"]) for g in groups] == [s for s, _, _ in io_data.PARTICLE_STEPS]
        for group, (step, time, count) in zip(groups, io_data.PARTICLE_STEPS):
            g = handle[group]
            assert g.attrs["time"] == time and g.attrs["count"] == count
            ids = g["ids"][()]
            assert np.array_equal(np.sort(ids), np.arange(count))
            # rows are in rank order: rank r's slab in the order it passed them
            stacked = np.concatenate([io_data.rank_particle_ids(count, r, ranks, step) for r in range(ranks)])
            assert np.array_equal(ids, stacked)
            expected = io_data.particle_arrays(ids, step)
            for name, values in expected.items():
                assert g[name].dtype == values.dtype
                assert np.array_equal(g[name][()], values), name


@pytest.mark.mpi
def test_particle_xdmf_index(written):
    _, out = written
    root = ET.parse(out / "particles.xdmf").getroot()
    grids = root.find("Domain/Grid").findall("Grid")
    assert [float(g.find("Time").get("Value")) for g in grids] == [t for _, t, _ in io_data.PARTICLE_STEPS]
    for grid, (_, _, count) in zip(grids, io_data.PARTICLE_STEPS):
        assert grid.find("Topology").get("TopologyType") == "Polyvertex"
        assert int(grid.find("Topology").get("NumberOfElements")) == count
        names = {a.get("Name") for a in grid.findall("Attribute")}
        assert names == {"velocities", "radii", "ids", "forces", "temperature"}
    assert not list(out.glob("*.tmp-*")), "temporary XDMF left behind"


@pytest.mark.mpi
def test_solid_values_read_back_with_meshio(written):
    _, out = written
    points, cells = io_data.box_tet_mesh()
    with meshio.xdmf.TimeSeriesReader(out / "block.xdmf") as reader:
        file_points, file_cells = reader.read_points_cells()
        assert np.array_equal(file_points, points)
        assert file_cells[0].type == "tetra"
        file_tets = file_cells[0].data
        # cells are stored in rank order: compare as a set of rows
        assert np.array_equal(np.unique(np.sort(file_tets, axis=1), axis=0), np.unique(np.sort(cells, axis=1), axis=0))
        assert reader.num_steps == 3
        for k, step in enumerate((0, 10, 20)):
            time, point_data, cell_data = reader.read_data(k)
            assert time == step * 1.0e-4
            for name, values in io_data.nodal_fields(points, step).items():
                assert np.array_equal(point_data[name], values), name
            expected = io_data.cell_fields(points, file_tets, step)["von_mises"]
            assert np.array_equal(cell_data["von_mises"][0], expected)


@pytest.mark.mpi
def test_resume_truncates_later_steps(tmp_path):
    run_under_mpi(2, "io_output.py", tmp_path, "--resume-check")
    with h5py.File(tmp_path / "particles.h5", "r") as handle:
        assert sorted(int(handle[k].attrs["step"]) for k in handle if k.startswith("step_")) == [0, 10, 30]
        assert handle["step_0000000030"].attrs["count"] == 99
    with meshio.xdmf.TimeSeriesReader(tmp_path / "block.xdmf") as reader:
        reader.read_points_cells()
        assert [reader.read_data(k)[0] for k in range(reader.num_steps)] == [0.0, 1.0e-3, 3.0e-3]
    times = [float(g.find("Time").get("Value"))
             for g in ET.parse(tmp_path / "particles.xdmf").getroot().find("Domain/Grid").findall("Grid")]
    assert times == [0.0, 1.0e-3, 3.0e-3]


@pytest.mark.mpi
def test_paraview_opens_both_series(written):
    pvpython = shutil.which("pvpython")
    if pvpython is None:
        pytest.skip("pvpython not on PATH (Debian package paraview)")
    ranks, out = written
    if ranks != 2:
        pytest.skip("ParaView is checked on the 2-rank files only (5 s per run)")
    particles, block = paraview_views(pvpython, out / "particles.xdmf", out / "block.xdmf")
    assert particles["points"] == [c for _, _, c in io_data.PARTICLE_STEPS]
    assert particles["cells"] == particles["points"]  # one vertex cell per particle: drawable
    assert particles["times"] == pytest.approx([t for _, t, _ in io_data.PARTICLE_STEPS])
    for k, (step, _, count) in enumerate(io_data.PARTICLE_STEPS):
        expected = io_data.particle_arrays(np.arange(count), step)
        assert particles["sums"]["temperature"][k] == pytest.approx(expected["temperature"].sum(), rel=1e-12)
    points, cells = io_data.box_tet_mesh()
    assert block["points"] == [len(points)] * 3 and block["cells"] == [len(cells)] * 3
    assert set(block["arrays"]) == {"displacements", "velocities", "temperature", "von_mises"}


def test_xdmf_pieces():
    assert xdmf.attribute_type(()) == "Scalar"
    assert xdmf.attribute_type((3,)) == "Vector"
    assert xdmf.attribute_type((3, 3)) == "Tensor"
    assert xdmf.number_type(np.int64) == ("Int", 8)
    assert xdmf.number_type(np.float32) == ("Float", 4)


def test_write_atomic_replaces_whole_file(tmp_path):
    target = tmp_path / "a.xdmf"
    xdmf.write_atomic(target, "one")
    xdmf.write_atomic(target, "two")
    assert target.read_text() == "two"
    assert [p.name for p in tmp_path.iterdir()] == ["a.xdmf"]


def test_a_solid_output_killed_mid_write_is_set_aside_on_restart(tmp_path, caplog):
    """A run killed while writing <solid>.h5 leaves it unreadable (HDF5 is not crash-safe); the restart
    from its checkpoint moved it to .previous and stopped with an error before ("does not hold this
    mesh"), so the checkpoint could not be used.  Now, as particles.h5 is: the file goes to
    .unreadable, a new one with the mesh is started, and the series goes on."""
    from mpi4py import MPI

    from pdemfem.io.solid_output import SolidOutput

    points, cells = io_data.box_tet_mesh()
    nodal = {"displacements": np.zeros((len(points), 3))}
    output = SolidOutput(tmp_path, "block", MPI.COMM_SELF, points, cells, 0)
    output.write(0.0, 0, point_data=nodal)
    output.write(1.0e-3, 10, point_data=nodal)
    path = tmp_path / "block.h5"
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 3])  # cut short, as a kill in the middle of a write leaves it
    with caplog.at_level("WARNING", logger="pdemfem"):
        resumed = SolidOutput(tmp_path, "block", MPI.COMM_SELF, points, cells, 0, resume_step=10)
    assert (tmp_path / "block.h5.unreadable").read_bytes() == data[: len(data) // 3]
    assert any("was unreadable" in record.getMessage() for record in caplog.records)
    resumed.write(2.0e-3, 20, point_data=nodal)
    with h5py.File(path, "r") as handle:
        assert handle["mesh/points"].shape == (len(points), 3) and handle["mesh/cells"].shape == (len(cells), 4)
        assert [key for key in handle if key.startswith("step_")] == ["step_0000000020"]
    # A readable file of another mesh is still refused (a different scene must not append to it).
    other_points = np.vstack([points, points[:1] + 1.0])
    with pytest.raises(ValueError, match="does not hold this mesh"):
        SolidOutput(tmp_path, "block", MPI.COMM_SELF, other_points, cells, 0, resume_step=20)


def test_a_history_row_cut_short_by_a_kill_is_dropped_on_restart(tmp_path):
    """history.csv keeps the header and the whole rows up to the restart step.  A last row cut inside its
    step field ("0.012,12" of step 120) read as step 12 and was kept; one cut right after a comma raised
    ValueError from float('') (a traceback on restart)."""
    from pdemfem.io.simulation_io import _truncate_history

    for cut in ("0.012,12", "0.012,", "0.012,120,3"):
        path = tmp_path / "history.csv"
        path.write_text("time,step,particles\n0.0,0,3\n0.001,10,3\n" + cut)
        _truncate_history(path, 100, ["time", "step", "particles"])
        assert path.read_text().splitlines() == ["time,step,particles", "0.0,0,3", "0.001,10,3"], cut


def test_a_restart_that_writes_other_columns_continues_a_table_with_all_of_them(tmp_path):
    """A checkpoint of an earlier version (or a scene changed with --force) continued under the old header: the
    new rows had a field more than the header, which a csv reader put under no name."""
    from pdemfem.io.history import HistoryWriter
    from pdemfem.io.simulation_io import _truncate_history
    from pdemfem.plot import read_history

    path = tmp_path / "history.csv"
    path.write_text("time,step,gone\n0.0,0,1.0\n0.001,10,2.0\n0.002,20,3.0\n")
    has_row, columns = _truncate_history(path, 10, ["time", "step", "lost_energy"])
    assert has_row and columns == ["time", "step", "lost_energy", "gone"]
    writer = HistoryWriter(path, columns, True, append=True)
    writer.write({"time": 0.002, "step": 20, "lost_energy": 0.5})
    writer.close()
    table = read_history(path)
    np.testing.assert_array_equal(table["step"], [0, 10, 20])
    np.testing.assert_array_equal(table["lost_energy"], [np.nan, np.nan, 0.5])
    np.testing.assert_array_equal(table["gone"], [1.0, 2.0, np.nan])


def test_a_field_list_without_positions_writes_them_with_the_fields(tmp_path):
    """`output.particles: [velocities, ids]` ran into a KeyError at the first write (the writer adds the
    geometry, the arrays handed to it did not): positions are written with any particle field."""
    from pdemfem import Simulation

    scene = {"time": {"end": 1.0e-4, "dt": 1.0e-5}, "gravity": [0, 0, -9.81],
             "materials": {"glass": {"density": 2500.0, "youngs_modulus": 5.0e6, "poisson_ratio": 0.3}},
             "particles": [{"name": "p", "material": "glass", "radius": 0.001,
                            "insert": {"kind": "list", "positions": [[0, 0, 0.01], [0.003, 0, 0.01]]}}],
             "output": {"every": 5.0e-5, "particles": ["velocities", "ids"]}}
    simulation = Simulation.from_dict(scene, base_dir=tmp_path, output_dir=tmp_path / "out")
    simulation.run(progress=False)
    with h5py.File(tmp_path / "out" / "particles.h5", "r") as handle:
        steps = sorted(name for name in handle.keys() if name.startswith("step_"))
        assert len(steps) == 3
        last = handle[steps[-1]]
        assert sorted(last.keys()) == ["ids", "positions", "velocities"]
        np.testing.assert_allclose(np.sort(last["positions"][:, 0]), [0.0, 0.003])


def test_the_last_interval_ending_at_the_end_is_written_once(tmp_path):
    """end = 4 output (and checkpoint) intervals, dt not dividing them (83.3 steps each): the end is at step 334,
    the fourth interval's time.  When the intervals were rounded to 83 steps, the fourth interval's write fell 2
    steps before the end's and the same moment was written twice (history rows 0.00996 and 0.01002 s; with keep
    2 the checkpoint of step 249 was pruned for it).  Each write is now at the step nearest its time (83, 167,
    250) and the fourth is the end's."""
    from pdemfem import Simulation
    from pdemfem.plot import read_history

    scene = {"time": {"end": 0.01, "dt": 3.0e-5}, "gravity": [0, 0, -9.81],
             "materials": {"glass": {"density": 2500.0, "youngs_modulus": 5.0e6, "poisson_ratio": 0.3}},
             "particles": [{"name": "p", "material": "glass", "radius": 0.001,
                            "insert": {"kind": "list", "positions": [[0, 0, 0.01]]}}],
             "output": {"every": 0.0025, "particles": []}, "checkpoint": {"every": 0.0025, "keep": 2}}
    simulation = Simulation.from_dict(scene, base_dir=tmp_path, output_dir=tmp_path / "out")
    simulation.run(progress=False)
    assert list(read_history(tmp_path / "out" / "history.csv")["step"]) == [0, 83, 167, 250, 334]
    kept = sorted(int(path.stem.split("_")[1]) for path in (tmp_path / "out" / "checkpoints").glob("checkpoint_*.h5"))
    assert kept == [250, 334], kept


def test_the_index_is_rewritten_now_and_then_and_whole_at_close(tmp_path, monkeypatch):
    """The XDMF index grows with the steps, so it is rewritten after a step only when the time since its last
    rewrite is INDEX_REWRITE_RATIO times what that took (2000 outputs of 27 particles spent 37 of 65 s on it
    when it was rewritten every time).  Made to wait for ever, it stays as it was (naming whole steps only),
    and `close` writes it with every step."""
    from mpi4py import MPI

    from pdemfem.io.particle_output import DEFAULT_FIELDS, ParticleOutput

    monkeypatch.setattr(xdmf, "INDEX_REWRITE_RATIO", 1e12)
    output = ParticleOutput(tmp_path, MPI.COMM_SELF, DEFAULT_FIELDS)
    ids = np.arange(5)
    for step in range(4):
        output.write(step * 1e-3, step, io_data.particle_arrays(ids, step))

    def listed():
        grid = ET.parse(tmp_path / "particles.xdmf").getroot().find("Domain/Grid")
        return [g.get("Name") for g in grid.findall("Grid")]

    assert listed() == []  # the index written at the start; every step since waits
    output.close()
    assert listed() == [f"step_{step:010d}" for step in range(4)]
    monkeypatch.setattr(xdmf, "INDEX_REWRITE_RATIO", 0.0)  # rewritten after every step
    output.write(4e-3, 4, io_data.particle_arrays(ids, 4))
    assert listed()[-1] == "step_0000000004"
