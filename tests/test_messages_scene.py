"""One clear message per mistake (file, key path, fix; exit 2; no output directory), for the scene
mistakes a tester found passing or badly reported: particles starting behind a floor or inside a
solid, misnamed groups of a generated box mesh, list entries out of bounds, unusable mesh paths and
output directories, warnings repeated per wall, a history cut short by a killed run.
"""
from __future__ import annotations

import struct
from pathlib import Path

import pytest

from pdemfem import cli

# 20 grains on a floor, with an elastic plate under the floor (its top at z = 0, contact on top).
PLATE_SCENE = """\
time: {end: 0.002, dt: auto, dt_factor: 0.1}
materials:
  glass: {density: 2500, youngs_modulus: 5.0e6, poisson_ratio: 0.3}
  steel: {density: 7800, youngs_modulus: 2.0e8, poisson_ratio: 0.3}
particles:
  - name: beads
    material: glass
    radius: 0.001
    insert:
      kind: lattice
      region: {box: [[0, 0, 0], [0.01, 0.01, 0.01]]}
      count: 20
walls:
  - {name: floor, kind: plane, point: [0, 0, 0], normal: [0, 0, 1], material: glass}
solids:
  - name: plate
    mesh: {box: [[-0.005, -0.005, -0.004], [0.015, 0.015, 0.0]], cells: [4, 4, 1]}
    material: steel
    fixed: [zmin]
    contact: [zmax]
output: {dir: results, every: 0.001}
"""

NO_FLOOR = PLATE_SCENE.replace(
    "walls:\n  - {name: floor, kind: plane, point: [0, 0, 0], normal: [0, 0, 1], material: glass}\n", "")


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


def check(capsys, folder: Path, text: str, command: str = "check"):
    (folder / "scene.yaml").write_text(text)
    argv = [command, "scene.yaml"] + (["--quiet", "-o", "out"] if command == "run" else [])
    code = cli.main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_error(code, err, *texts):
    assert code == 2, err
    assert err.count("error:") == 1 and "Traceback" not in err, err
    assert "fix:" in err, err
    for text in texts:
        assert text in err, (text, err)


# ----------------------------------------------------------------- 1. impossible starting geometry

def test_particles_behind_a_raised_floor_are_a_scene_error(workdir, capsys):
    raised = PLATE_SCENE.replace("point: [0, 0, 0], normal", "point: [0, 0, 0.02], normal")
    code, out, err = check(capsys, workdir, raised)
    assert_one_error(code, err, "scene.yaml: line", "particles[0].insert.region.box",
                     "20 of the 20 particles of group 'beads' start behind plane wall 'floor' (walls[0]",
                     "walls[0].point")
    assert "scene OK" not in out
    code, _, err = check(capsys, workdir, raised, command="run")
    assert_one_error(code, err, "start behind plane wall 'floor'")
    assert not (workdir / "out").exists()


def test_particles_overlapping_a_floor_by_more_than_the_tolerance(workdir, capsys):
    listed = PLATE_SCENE.replace(
        "      kind: lattice\n      region: {box: [[0, 0, 0], [0.01, 0.01, 0.01]]}\n      count: 20\n",
        "      kind: list\n      positions: [[0.005, 0.005, 0.0008], [0.008, 0.008, 0.005]]\n")
    code, _, err = check(capsys, workdir, listed)
    assert_one_error(code, err, "particles[0].insert.positions", "1 of the 2 particles", "overlap it by more than 0.05")
    # Resting on the floor (a tiny overlap) is fine.
    resting = listed.replace("0.0008]", "0.00099]")
    code, out, err = check(capsys, workdir, resting)
    assert code == 0 and "scene OK" in out, err


def test_particles_inside_a_solid_are_a_scene_error(workdir, capsys):
    inside = NO_FLOOR.replace(
        "      kind: lattice\n      region: {box: [[0, 0, 0], [0.01, 0.01, 0.01]]}\n      count: 20\n",
        "      kind: list\n      positions: [[0.005, 0.005, 0.005], [0.005, 0.005, -0.002]]\n")
    code, out, err = check(capsys, workdir, inside)
    assert_one_error(code, err, "particles[0].insert.positions",
                     "1 of the 2 particles of group 'beads' start with their centre inside solid 'plate'",
                     "move the insertion")
    code, _, err = check(capsys, workdir, inside, command="run")
    assert_one_error(code, err, "inside solid 'plate'")
    assert not (workdir / "out").exists()


def test_particles_deep_in_a_solids_contact_surface_are_a_scene_error(workdir, capsys):
    touching = NO_FLOOR.replace(
        "      kind: lattice\n      region: {box: [[0, 0, 0], [0.01, 0.01, 0.01]]}\n      count: 20\n",
        "      kind: list\n      positions: [[0.005, 0.005, 0.0005]]\n")
    code, _, err = check(capsys, workdir, touching)
    assert_one_error(code, err, "overlapping the contact surface of solid 'plate' (solids[0].contact: zmax)",
                     "the deepest by 0.5 radii")


def test_a_scene_resting_on_its_plate_passes(workdir, capsys):
    code, out, err = check(capsys, workdir, NO_FLOOR)
    assert code == 0 and "scene OK" in out, err


# ----------------------------------------------------------------- 2. a box mesh's groups

def test_misspelt_group_of_a_box_mesh_names_the_key_and_the_faces(workdir, capsys):
    code, _, err = check(capsys, workdir, PLATE_SCENE.replace("fixed: [zmin]", "fixed: [zmn]"))
    assert_one_error(code, err, "scene.yaml: line", "solids[0].fixed[0]", "has no group 'zmn'",
                     "xmin, xmax, ymin, ymax, zmin, zmax", "did you mean 'zmin'?")
    assert "gmsh" not in err  # a generated box has no physical groups to add
    code, _, err = check(capsys, workdir, PLATE_SCENE.replace("contact: [zmax]", "contact: [top]"))
    assert_one_error(code, err, "solids[0].contact[0]", "has no group 'top'")


# ----------------------------------------------------------------- 3. list entries out of bounds

def test_a_list_entry_out_of_bounds_names_the_key_path(workdir, capsys):
    code, _, err = check(capsys, workdir, PLATE_SCENE.replace("cells: [4, 4, 1]", "cells: [0, 4, 1]"))
    assert_one_error(code, err, "solids[0].mesh.cells[0]: must be > 0, got 0",
                     "every entry of solids[0].mesh.cells must be positive: give solids[0].mesh.cells[0] a value > 0")
    assert "fix: 0 must be positive" not in err


# ----------------------------------------------------------------- 5. unusable paths

FUNNEL = """\
time: {end: 0.002, dt: auto, expected_impact_speed: 0.5}
materials:
  glass: {density: 2500, youngs_modulus: 5.0e6, poisson_ratio: 0.3}
particles:
  - name: beads
    material: glass
    radius: 0.001
    insert: {kind: list, positions: [[0.005, 0.005, 0.005]]}
walls:
  - {name: funnel, kind: mesh, file: FILE, material: glass}
output: {dir: results, every: 0.001}
"""


def _binary_stl(triangles: int, announced: int) -> bytes:
    body = b"".join(struct.pack("<12fH", 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0) for _ in range(triangles))
    return b"x" * 80 + struct.pack("<I", announced) + body


def test_truncated_binary_stl_says_it_is_cut_short(workdir, capsys):
    (workdir / "cut.stl").write_bytes(_binary_stl(3, 10))
    code, _, err = check(capsys, workdir, FUNNEL.replace("FILE", "cut.stl"))
    assert_one_error(code, err, "walls[0].file", "a binary STL cut short: its header announces 10 triangles",
                     "copy or export it again")
    assert "UnicodeDecodeError" not in err
    (workdir / "whole.stl").write_bytes(_binary_stl(2, 2))
    code, out, err = check(capsys, workdir, FUNNEL.replace("FILE", "whole.stl"))
    assert code == 0 and "scene OK" in out, err


def _ascii_stl(triangles: int) -> str:
    facet = ("  facet normal 0 0 1\n    outer loop\n      vertex {x} 0 0\n      vertex {x1} 0 0\n"
             "      vertex {x} 1 0\n    endloop\n  endfacet\n")
    return "solid plate\n" + "".join(facet.format(x=k, x1=k + 1) for k in range(triangles)) + "endsolid plate\n"


def test_ascii_stl_cut_between_two_facets_says_it_is_cut_short(workdir, capsys):
    """Cut after a whole facet, meshio read the first facets as the whole surface (half a belt went missing
    without a word); the last line of an ASCII STL must close the solid."""
    whole = _ascii_stl(3)
    (workdir / "cut.stl").write_text(whole[:whole.index("endfacet") + len("endfacet\n")])
    code, _, err = check(capsys, workdir, FUNNEL.replace("FILE", "cut.stl"))
    assert_one_error(code, err, "walls[0].file", "an ASCII STL cut short: its last line is not 'endsolid'",
                     "copy or export it again")
    (workdir / "whole.stl").write_text(whole)
    code, out, err = check(capsys, workdir, FUNNEL.replace("FILE", "whole.stl"))
    assert code == 0 and "scene OK" in out, err


def test_a_mesh_wall_read_in_the_wrong_units_is_warned_about_by_check_and_run(workdir, capsys):
    """A 3-facet strip 3 m long (as exported, in metres) read with scale 0.0004 spans 1.2 mm, less than the
    2 mm bead's diameter: such a wall catches nothing, and neither check nor run said a word."""
    (workdir / "strip.stl").write_text(_ascii_stl(3))
    scene = FUNNEL.replace("FILE", "strip.stl").replace("material: glass}", "material: glass, scale: 0.0004}")
    code, out, err = check(capsys, workdir, scene)
    assert code == 0, err
    assert "walls[0] (funnel): the mesh spans only 0.0012 m (after scale 0.0004), less than the smallest " \
           "particle's diameter 0.002 m" in out, out
    code, _, err = check(capsys, workdir, scene, command="run")
    assert code == 0 and "warning: walls[0] (funnel): the mesh spans only 0.0012 m" in err, err
    code, out, err = check(capsys, workdir, FUNNEL.replace("FILE", "strip.stl"))
    assert code == 0 and "spans only" not in out, out


def test_a_mesh_path_that_is_a_directory(workdir, capsys):
    (workdir / "meshes").mkdir()
    code, _, err = check(capsys, workdir, FUNNEL.replace("FILE", "meshes"))
    assert_one_error(code, err, "walls[0].file", "is a directory, not a file")
    code, _, err = check(capsys, workdir, PLATE_SCENE.replace(
        "mesh: {box: [[-0.005, -0.005, -0.004], [0.015, 0.015, 0.0]], cells: [4, 4, 1]}", "mesh: meshes"))
    assert_one_error(code, err, "solids[0].mesh", "is a directory, not a file")
    assert "file not found" not in err


def test_output_path_that_is_a_file(workdir, capsys):
    (workdir / "scene.yaml").write_text(PLATE_SCENE)
    (workdir / "taken").write_text("a file")
    code = cli.main(["run", "scene.yaml", "--quiet", "-o", "taken"])
    _, err = capsys.readouterr()
    assert_one_error(code, err, "taken: cannot be the output directory: it is an existing file, not a directory",
                     "give -o (or output.dir) the path of a directory")
    assert "File exists" not in err
    assert (workdir / "taken").read_text() == "a file"


# ----------------------------------------------------------------- 6. one warning per cause

def test_the_same_warning_is_not_repeated_per_wall(workdir, capsys):
    box = PLATE_SCENE.split("solids:")[0] + "output: {dir: results, every: 0.001}\n"
    box = box.replace("dt_factor: 0.1}", "dt_factor: 0.1, expected_impact_speed: 5}")
    extra = "".join(f"  - {{name: {name}, kind: plane, point: {point}, normal: {normal}, material: glass}}\n"
                    for name, point, normal in (("x_low", [0, 0, 0], [1, 0, 0]), ("x_high", [0.01, 0, 0], [-1, 0, 0])))
    box = box.replace("material: glass}\noutput", "material: glass}\n" + extra + "output")
    code, out, err = check(capsys, workdir, box)
    assert code == 0, err
    lines = [line for line in out.splitlines() if "contacts glass on glass" in line]
    assert len(lines) == 1, out
    assert "(walls floor, x_low, x_high)" in lines[0]


# ----------------------------------------------------------------- 7. a history cut short

def test_plot_drops_an_incomplete_last_row(workdir, capsys, caplog):
    out = workdir / "run"
    out.mkdir()
    (out / "history.csv").write_text("time,step,particles,kinetic_energy\n0,0,10,1.0\n0.1,10,10,0.5\n"
                                     "0.2,20,9,0.25\n0.3,30,1")
    code = cli.main(["plot", str(out)])
    _, err = capsys.readouterr()
    assert code == 0, err
    notes = caplog.text  # the note goes to the "pdemfem" logger (stderr in a shell)
    assert "the last row (line 5) is incomplete" in notes and "plotting the 3 complete rows" in notes
    assert (out / "plots" / "energies.png").is_file()


# ----------------------------------------------------------------- a derived linear stiffness without a speed
RESTING_LINEAR = """\
time: {end: 0.0001, dt: auto}
gravity: [0, 0, -9.81]
materials:
  steel: {density: 7800, youngs_modulus: 2.0e11, poisson_ratio: 0.3}
interactions:
  default: {model: linear_spring_dashpot, restitution: 0.5, friction: 0.3}
particles:
  - {name: ball, material: steel, radius: 0.001, insert: {kind: list, positions: [[0, 0, 0.001]]}}
walls:
  - {name: floor, kind: plane, point: [0, 0, 0], normal: [0, 0, 1], material: steel}
"""


@pytest.mark.parametrize("command", ["check", "run"])
def test_a_resting_linear_contact_with_a_derived_stiffness_names_the_keys(workdir, capsys, command):
    """k_n = m* v^2 / delta_max^2 is 0 at an expected impact speed of 0 (a sphere placed at rest on a floor): the run
    divided by it in the plane-wall kernel (ZeroDivisionError)."""
    code, _, err = check(capsys, workdir, RESTING_LINEAR, command)
    assert_one_error(code, err, "linear_spring_dashpot", "normal_stiffness", "time.expected_impact_speed")
    assert not (workdir / "out").exists()
    # Either key makes it a valid scene.
    code, _, err = check(capsys, workdir, RESTING_LINEAR.replace("restitution: 0.5,", "restitution: 0.5, normal_stiffness: 1.0e6,"))
    assert code == 0, err


# ----------------------------------------------------------------- extreme time settings

@pytest.mark.parametrize("command", ["check", "run"])
def test_a_step_longer_than_the_run_names_time_dt(workdir, capsys, command):
    code, _, err = check(capsys, workdir, PLATE_SCENE.replace("dt: auto, dt_factor: 0.1", "dt: 1.0e300"), command)
    assert_one_error(code, err, "time: dt = 1e+300 s is longer than end = 0.002 s", "dt: auto")
    assert not (workdir / "out").exists()


@pytest.mark.parametrize("command", ["check", "run"])
def test_a_step_and_end_that_overflow_the_derived_quantities_are_a_scene_error(workdir, capsys, command):
    # Legal each, but the plate's held-force and contact checks square the step: 1e600 overflows.
    huge = PLATE_SCENE.replace("end: 0.002, dt: auto, dt_factor: 0.1", "end: 1.0e301, dt: 1.0e300")
    code, _, err = check(capsys, workdir, huge, command)
    assert_one_error(code, err, "out of range for the derived quantities", "time.dt and time.end")
    assert not (workdir / "out").exists()
