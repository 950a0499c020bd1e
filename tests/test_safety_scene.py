"""`check` refuses what `run` cannot use, with one exit-2 message and no traceback.

Non-finite numbers, true/false as a number, NaN mesh-wall vertices, insertions outside
domain.box, periodic lengths below the cutoff, coordinates beyond float64 resolution,
out-of-range magnitudes and empty output directories.  Each case runs `pdemfem.cli.main`
in this process (same code path as the console script).
"""
from __future__ import annotations

from pathlib import Path

import pytest

from pdemfem import cli

SCENE = """\
time: {end: 0.002, dt: auto, dt_factor: 0.1}
materials:
  glass: {density: 2500, youngs_modulus: 5.0e6, poisson_ratio: 0.3}
particles:
  - name: grains
    material: glass
    radius: 0.001
    insert:
      kind: list
      positions: [[0, 0, 0.005], [0.01, 0, 0.005]]
      velocities: [[0, 0, 0], [0, 0, 0]]
walls:
  - {name: floor, kind: plane, point: [0, 0, 0], normal: [0, 0, 1], material: glass}
output: {dir: results, every: 0.001}
"""

MESH_WALL = "  - {name: floor, kind: mesh, file: floor.stl, material: glass}\n"
PLANE_WALL = "  - {name: floor, kind: plane, point: [0, 0, 0], normal: [0, 0, 1], material: glass}\n"

STL = """solid floor
facet normal 0 0 1
outer loop
vertex -1 -1 0
vertex 1 -1 0
vertex 1 1 {z}
endloop
endfacet
facet normal 0 0 1
outer loop
vertex -1 -1 0
vertex 1 1 0
vertex -1 1 0
endloop
endfacet
endsolid floor
"""


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


def write_scene(folder: Path, text: str) -> Path:
    path = folder / "scene.yaml"
    path.write_text(text)
    return path


def run_main(capsys, *argv):
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def assert_refused(code, err, *expected):
    assert code == 2, err
    assert err.startswith("error: "), err
    assert "Traceback" not in err
    for text in expected:
        assert text in err, err


@pytest.mark.parametrize("old, new, key", [
    ("youngs_modulus: 5.0e6", "youngs_modulus: .inf", "materials.glass.youngs_modulus"),
    ("density: 2500", "density: .nan", "materials.glass.density"),
    ("velocities: [[0, 0, 0], [0, 0, 0]]", "velocities: [[0, 0, 0], [0, .nan, 0]]",
     "particles[0].insert.velocities[1][1]"),
    ("point: [0, 0, 0]", "point: [0, 0, -.inf]", "walls[0].point[2]"),
    ("time: {end: 0.002", "gravity: [0, 0, 1.0e999]\ntime: {end: 0.002", "gravity[2]"),  # YAML reads 1e999 as inf
])
def test_non_finite_number_is_refused_by_check(workdir, capsys, old, new, key):
    path = write_scene(workdir, SCENE.replace(old, new))
    code, _, err = run_main(capsys, "check", path)
    assert_refused(code, err, key, "expected a finite number")


@pytest.mark.parametrize("old, new, key", [
    ("positions: [[0, 0, 0.005], [0.01, 0, 0.005]]\n      velocities: [[0, 0, 0], [0, 0, 0]]",
     "region: {box: [[0, 0, 0], [0.01, 0.01, 0.01]]}\n      count: true", "particles[0].insert.count"),
    ("youngs_modulus: 5.0e6", "youngs_modulus: true", "materials.glass.youngs_modulus"),
    ("point: [0, 0, 0]", "point: [0, false, 0]", "walls[0].point"),
])
def test_true_false_is_not_a_number(workdir, capsys, old, new, key):
    path = write_scene(workdir, SCENE.replace("kind: list", "kind: lattice" if "count" in new else "kind: list")
                       .replace(old, new))
    code, _, err = run_main(capsys, "check", path)
    assert_refused(code, err, key, "true/false is not a number")


@pytest.mark.parametrize("command", ["check", "run"])
def test_nan_mesh_wall_vertex_is_refused(workdir, capsys, command):
    # Before: the NaN vertex made the wall's bounds NaN, the wall held nothing, check said OK
    # and run exited 0 with every particle falling through.
    (workdir / "floor.stl").write_text(STL.format(z="nan"))
    path = write_scene(workdir, SCENE.replace(PLANE_WALL, MESH_WALL))
    code, _, err = run_main(capsys, command, path, *(["--quiet"] if command == "run" else []))
    assert_refused(code, err, "walls[0].file", "floor.stl", "NaN or infinite coordinate", "vertex 2")
    assert not (workdir / "results").exists()


def test_finite_mesh_wall_passes_check(workdir, capsys):
    (workdir / "floor.stl").write_text(STL.format(z="0"))
    path = write_scene(workdir, SCENE.replace(PLANE_WALL, MESH_WALL))
    code, out, err = run_main(capsys, "check", path)
    assert code == 0, err
    assert "scene OK" in out


LATTICE = SCENE.replace(
    "      kind: list\n      positions: [[0, 0, 0.005], [0.01, 0, 0.005]]\n      velocities: [[0, 0, 0], [0, 0, 0]]\n",
    "      kind: lattice\n      region: {box: [[0, 0, 0.02], [0.01, 0.01, 0.03]]}\n      count: 20\n")


@pytest.mark.parametrize("command", ["check", "run"])
def test_insertion_outside_domain_box_is_refused(workdir, capsys, command):
    # Before: check said OK and run removed all 20 particles as lost at step 0, exit 0.
    path = write_scene(workdir, LATTICE + "domain: {box: [[0, 0, 0], [0.01, 0.01, 0.015]]}\n")
    code, _, err = run_main(capsys, command, path, *(["--quiet"] if command == "run" else []))
    assert_refused(code, err, "particles[0].insert.region.box", "20 of the 20 particles", "outside domain.box")


def test_insertion_inside_domain_box_passes(workdir, capsys):
    path = write_scene(workdir, LATTICE + "domain: {box: [[0, 0, 0], [0.01, 0.01, 0.04]]}\n")
    code, out, err = run_main(capsys, "check", path)
    assert code == 0, err


def test_periodic_length_below_twice_the_cutoff_is_refused_by_check(workdir, capsys):
    # Cutoff = largest diameter 2 mm + skin 0.3 mm = 2.3 mm; a 4 mm period is below 2 x 2.3 mm.
    # Before: check said OK (only run refused it).
    path = write_scene(workdir, LATTICE + "domain: {box: [[0, 0, 0], [0.004, 0.01, 0.04]], periodic: [x]}\n")
    code, _, err = run_main(capsys, "check", path)
    assert_refused(code, err, "domain.box (x, periodic)", "periodic length 0.004 m", "cutoff 0.0023 m")


@pytest.mark.parametrize("old, new, key", [
    ("[0.01, 0, 0.005]]", "[1.0e18, 0, 0.005]]", "particles[0].insert.positions"),
    ("point: [0, 0, 0]", "point: [0, 0, -1.0e300]", "walls[0].point"),
    ("output:", "domain: {box: [[-1.0e13, -1, -1], [1, 1, 1]]}\noutput:", "domain.box"),
])
@pytest.mark.parametrize("command", ["check", "run"])
def test_huge_coordinates_are_refused(workdir, capsys, command, old, new, key):
    # 1e9 smallest radii = 1e6 m here; beyond it float64 cannot resolve the contact overlaps.
    path = write_scene(workdir, SCENE.replace(old, new))
    code, _, err = run_main(capsys, command, path, *(["--quiet"] if command == "run" else []))
    assert_refused(code, err, key, "smallest radii", "cannot resolve the contact overlaps")


def test_huge_mesh_wall_scale_is_refused(workdir, capsys):
    (workdir / "floor.stl").write_text(STL.format(z="0"))
    path = write_scene(workdir, SCENE.replace(PLANE_WALL, MESH_WALL.replace("file: floor.stl",
                                                                            "file: floor.stl, scale: 1.0e12")))
    code, _, err = run_main(capsys, "check", path)
    assert_refused(code, err, "walls[0].file", "smallest radii")


def test_huge_modulus_is_a_scene_error_not_a_traceback(workdir, capsys):
    # 1e308 Pa is finite, but the contact duration (E^2) overflows; before: OverflowError traceback.
    path = write_scene(workdir, SCENE.replace("youngs_modulus: 5.0e6", "youngs_modulus: 1.0e308"))
    code, _, err = run_main(capsys, "check", path)
    assert_refused(code, err, "out of range")


def test_empty_output_directory_is_an_error(workdir, capsys):
    # Before: `-o ""` wrote the results into the current directory.
    path = write_scene(workdir, SCENE)
    code, _, err = run_main(capsys, "run", path, "-o", "", "--quiet")
    assert_refused(code, err, "-o", "is empty")
    assert sorted(p.name for p in workdir.iterdir()) == ["scene.yaml"]
    path = write_scene(workdir, SCENE.replace("dir: results", 'dir: ""'))
    code, _, err = run_main(capsys, "check", path)
    assert_refused(code, err, "output.dir: is empty")


def test_nan_node_in_a_solid_mesh_is_refused(workdir, capsys):
    import meshio
    import numpy as np

    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, np.nan]], dtype=float)
    cells = [("tetra", np.array([[0, 1, 2, 3], [1, 2, 3, 4]]))]
    meshio.write_points_cells(str(workdir / "block.vtu"), points, cells)
    path = write_scene(workdir, SCENE.replace("output:", "solids:\n  - {name: block, mesh: block.vtu, material: glass}\n"
                                                         "output:"))
    code, _, err = run_main(capsys, "check", path)
    assert_refused(code, err, "block.vtu", "NaN or infinite coordinate", "node 4")
