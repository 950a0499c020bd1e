"""gmsh .geo files wherever a mesh file is accepted: solids[].mesh (meshed in 3-D) and walls[].file (2-D).

* the mesh made in memory is the same, bit for bit, on every read, and the same as the .msh gmsh saves
  from that .geo file read back (points, cells, groups); a wall's triangles likewise;
* gmsh prints nothing; a .geo gmsh cannot read or mesh is a MeshError naming the file and gmsh's message;
* the examples' .geo files: the belt and the hopper panel are the scenes' former box meshes exactly, the
  hopper's wall files are what the benchmark writes, and the tread wheel loads as a solid whose tread
  faces point outward.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pdemfem.errors import MeshError
from pdemfem.fem.config import BoxMeshConfig
from pdemfem.fem.mesh import boundary_faces, load_mesh
from pdemfem.walls.readers import read_surface

ROOT = Path(__file__).resolve().parent.parent
MESHES = ROOT / "examples" / "meshes"

# An unstructured solid (Delaunay tetrahedra, so the mesh depends on gmsh's seed and threads), with two
# named surface groups, one of them overlapping the other, and a volume group.
HOLED_BLOCK = """\
SetFactory("OpenCASCADE");
Box(1) = {0, 0, 0, 1, 0.6, 0.5};
Sphere(2) = {0.5, 0.3, 0.25, 0.15};
block() = BooleanDifference{ Volume{1}; Delete; }{ Volume{2}; Delete; };
Mesh.CharacteristicLengthMax = 0.2;
eps = 1e-6;
Physical Surface("bottom") = {Surface In BoundingBox{-eps, -eps, -eps, 1 + eps, 0.6 + eps, eps}};
Physical Surface("outside") = {Surface In BoundingBox{-eps, -eps, -eps, 1 + eps, 0.6 + eps, 0.5 + eps}};
Physical Volume("block") = {block()};
"""

# A surface wall: a disc with a hole, meshed with triangles, no groups (every surface is the wall).
ANNULUS = """\
SetFactory("OpenCASCADE");
Disk(1) = {0, 0, 0, 0.05};
Disk(2) = {0, 0, 0, 0.02};
BooleanDifference{ Surface{1}; Delete; }{ Surface{2}; Delete; }
Mesh.CharacteristicLengthMax = 0.006;
"""

# A box whose 2-D physical group names only its bottom: a .msh saved from it holds only the bottom's
# triangles, and so must the wall read from the .geo.
BOX_WITH_GROUPED_BOTTOM = """\
SetFactory("OpenCASCADE");
Box(1) = {0, 0, 0, 1, 1, 1};
Mesh.CharacteristicLengthMax = 0.3;
Physical Surface("floor") = {Surface In BoundingBox{-0.1, -0.1, -0.1, 1.1, 1.1, 0.1}};
"""


def _write(folder: Path, name: str, text: str) -> Path:
    path = folder / name
    path.write_text(text)
    return path


def _msh_from_geo(geo: Path, dimension: int) -> Path:
    """What a user does in gmsh: open the .geo, mesh, save a (binary, so exact) .msh beside it.  In a fresh
    process: gmsh's .geo parser keeps the state of a file it failed on (the error tests here)."""
    msh = geo.with_suffix(".msh")
    script = ("import sys, gmsh\n"
              "gmsh.initialize(readConfigFiles=False, interruptible=False)\n"
              "gmsh.option.setNumber('General.Terminal', 0)\n"
              "gmsh.open(sys.argv[1])\n"
              "gmsh.model.mesh.generate(int(sys.argv[3]))\n"
              "gmsh.option.setNumber('Mesh.Binary', 1)\n"
              "gmsh.write(sys.argv[2])\n"
              "gmsh.finalize()\n")
    subprocess.run([sys.executable, "-c", script, str(geo), str(msh), str(dimension)], check=True, timeout=120)
    return msh


def _assert_same_solid_mesh(first, second):
    assert np.array_equal(first.points, second.points)
    assert np.array_equal(first.tets, second.tets)
    assert sorted(first.face_groups) == sorted(second.face_groups)
    for name in first.face_groups:
        assert np.array_equal(first.face_groups[name], second.face_groups[name]), name


# ------------------------------------------------------------------------------------------ solids
def test_a_solid_geo_gives_the_same_mesh_every_time_and_the_msh_made_from_it(tmp_path, capfd):
    geo = _write(tmp_path, "block.geo", HOLED_BLOCK)
    first = load_mesh("block.geo", tmp_path)
    second = load_mesh(geo, tmp_path)
    assert capfd.readouterr() == ("", "")  # gmsh kept quiet
    _assert_same_solid_mesh(first, second)
    assert len(first.tets) > 100 and sorted(first.face_groups) == ["bottom", "outside"]
    # The bottom is one face of the 'outside' group too: each group keeps its triangles.
    assert len(first.face_groups["outside"]) > len(first.face_groups["bottom"]) > 0

    from_msh = load_mesh(_msh_from_geo(geo, 3), tmp_path)
    _assert_same_solid_mesh(first, from_msh)
    assert from_msh.source.endswith("block.msh") and first.source.endswith("block.geo")


def test_a_solid_geo_with_a_physical_volume_gives_only_its_cells_as_its_msh_does(tmp_path):
    # Two separate blocks, only the first one a physical volume: gmsh saves only its cells in the .msh.
    geo = _write(tmp_path, "two_blocks.geo", 'SetFactory("OpenCASCADE");\nBox(1) = {0, 0, 0, 1, 1, 1};\n'
                                             'Box(2) = {2, 0, 0, 1, 1, 1};\nMesh.CharacteristicLengthMax = 0.5;\n'
                                             'Physical Volume("first") = {1};\n')
    from_geo = load_mesh(geo, tmp_path)
    assert from_geo.points[:, 0].max() == 1.0
    _assert_same_solid_mesh(from_geo, load_mesh(_msh_from_geo(geo, 3), tmp_path))


def test_a_solid_geo_with_a_syntax_error_names_the_file_and_gmsh_message(tmp_path, capfd):
    _write(tmp_path, "broken.geo", 'SetFactory("OpenCASCADE");\nBox(1) = {0, 0, 0, 1, 1, 1;\n')
    with pytest.raises(MeshError) as caught:
        load_mesh("broken.geo", tmp_path)
    message = str(caught.value)
    assert str(tmp_path / "broken.geo") in message
    assert "line 2: syntax error" in message and "gmsh cannot read the .geo file" in message
    assert "fix: correct the .geo file" in message
    assert capfd.readouterr() == ("", "")


def test_a_solid_geo_gmsh_cannot_mesh_names_the_file_and_gmsh_message(tmp_path):
    # Opposite edges of a transfinite face with different node counts: gmsh reads it, then fails in 3-D.
    _write(tmp_path, "uneven.geo", 'SetFactory("OpenCASCADE");\nBox(1) = {0, 0, 0, 1, 1, 1};\n'
                                   'Transfinite Curve{1} = 3;\nTransfinite Curve{2:12} = 5;\n'
                                   'Transfinite Surface{:};\nTransfinite Volume{1};\n')
    with pytest.raises(MeshError) as caught:
        load_mesh("uneven.geo", tmp_path)
    message = str(caught.value)
    assert str(tmp_path / "uneven.geo") in message and "gmsh cannot mesh the volume" in message
    assert "transfinite volume 1" in message


def test_a_solid_geo_without_a_volume_says_to_define_one(tmp_path):
    _write(tmp_path, "sheet.geo", 'SetFactory("OpenCASCADE");\nRectangle(1) = {0, 0, 0, 1, 1};\n')
    with pytest.raises(MeshError) as caught:
        load_mesh("sheet.geo", tmp_path)
    assert "no volume cells" in caught.value.problem and "define the solid's volume in the .geo file" in caught.value.fix


def _broken_solid_scene(folder):
    """A scene whose solid is meshed from a .geo file with a syntax error."""
    _write(folder, "broken.geo", "Point(1) = {0, 0, 0};\nLine(1) = {1, 2\n")
    return _write(folder, "scene.yaml", """\
time: {end: 0.001, dt: 1.0e-4}
materials:
  steel: {density: 7800, youngs_modulus: 2.0e8, poisson_ratio: 0.3}
solids:
  - {name: block, mesh: broken.geo, material: steel, fixed: [zmin]}
""")


def test_a_bad_solid_geo_stops_the_run_with_exit_2_and_no_traceback(tmp_path, capsys):
    from pdemfem import cli

    scene = _broken_solid_scene(tmp_path)
    code = cli.main(["run", str(scene), "--quiet", "-o", str(tmp_path / "out")])
    _, err = capsys.readouterr()
    assert code == 2, err
    assert err.count("error: ") == 1 and "Traceback" not in err
    assert "broken.geo" in err and "syntax error" in err


@pytest.mark.mpi
def test_a_bad_solid_geo_stops_both_ranks_together(tmp_path):
    scene = _broken_solid_scene(tmp_path)
    ran = subprocess.run([sys.executable, "-m", "pdemfem.launch", "-n", "2", "--", sys.executable, "-m", "pdemfem.cli",
                          "run", str(scene), "--quiet", "-o", str(tmp_path / "out")],
                         capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert ran.returncode == 2, (ran.stdout, ran.stderr)
    assert ran.stderr.count("error: ") == 1 and "Traceback" not in ran.stderr, ran.stderr
    assert "broken.geo" in ran.stderr and "syntax error" in ran.stderr


AFTER_A_BROKEN_FILE = """\
import sys
from pathlib import Path
import numpy as np
from pdemfem.errors import MeshError
from pdemfem.fem.mesh import load_mesh
from pdemfem.walls.readers import read_surface
folder = Path(sys.argv[1])
before = load_mesh(folder / "block.geo", folder)             # in this process: gmsh's parser is fresh
wall_before = read_surface(folder / "annulus.geo")
try:
    load_mesh(folder / "broken.geo", folder)
except MeshError as error:
    print("error:", error.problem)
after = load_mesh(folder / "block.geo", folder)              # now in a child process
wall_after = read_surface(folder / "annulus.geo")
same = (np.array_equal(before.points, after.points) and np.array_equal(before.tets, after.tets)
        and sorted(before.face_groups) == sorted(after.face_groups)
        and all(np.array_equal(before.face_groups[k], after.face_groups[k]) for k in before.face_groups)
        and all(np.array_equal(a, b) for a, b in zip(wall_before, wall_after)))
print("same" if same else "different", len(before.tets), len(after.tets))
"""


def test_a_geo_read_after_a_file_gmsh_stopped_reading_midway_is_the_same_mesh(tmp_path):
    """gmsh's .geo parser keeps the state of a file it stopped reading in the middle of a statement (here an
    unknown variable), even across gmsh sessions: the next .geo files used to be misread or read as empty.
    The same files read before and after such a failure give the same mesh (in a fresh Python process, so
    the first read is in a fresh gmsh)."""
    import os

    _write(tmp_path, "block.geo", HOLED_BLOCK)
    _write(tmp_path, "annulus.geo", ANNULUS)
    _write(tmp_path, "broken.geo", 'SetFactory("OpenCASCADE");\nBox(1) = {0, 0, 0, 1, 1, 1};\nx = y + 1;\n')
    environment = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    ran = subprocess.run([sys.executable, "-c", AFTER_A_BROKEN_FILE, str(tmp_path)], capture_output=True, text=True,
                         env=environment, timeout=300)
    assert ran.returncode == 0, ran.stderr
    assert "error: gmsh cannot read the .geo file" in ran.stdout and "Unknown variable 'y'" in ran.stdout
    assert ran.stdout.splitlines()[-1].startswith("same "), ran.stdout


# ------------------------------------------------------------------------------------------ walls
def test_a_wall_geo_gives_the_same_triangles_every_time_and_the_msh_made_from_it(tmp_path, capfd):
    geo = _write(tmp_path, "annulus.geo", ANNULUS)
    vertices, triangles = read_surface(geo)
    again = read_surface(geo)
    assert capfd.readouterr() == ("", "")
    assert np.array_equal(vertices, again[0]) and np.array_equal(triangles, again[1])
    from_msh = read_surface(_msh_from_geo(geo, 2))
    assert np.array_equal(vertices, from_msh[0]) and np.array_equal(triangles, from_msh[1])
    # The annulus's area: gmsh's polygonal edges cut it by at most the segment areas (~0.3 % at this size).
    area = 0.5 * np.linalg.norm(np.cross(vertices[triangles[:, 1]] - vertices[triangles[:, 0]],
                                         vertices[triangles[:, 2]] - vertices[triangles[:, 0]]), axis=1).sum()
    assert area == pytest.approx(np.pi * (0.05 ** 2 - 0.02 ** 2), rel=5e-3)


def test_a_wall_geo_with_surface_groups_is_those_surfaces_as_in_its_msh(tmp_path):
    geo = _write(tmp_path, "floor.geo", BOX_WITH_GROUPED_BOTTOM)
    vertices, triangles = read_surface(geo)
    assert np.all(vertices[:, 2] == 0.0)  # only the grouped bottom face, not the box's other five
    from_msh = read_surface(_msh_from_geo(geo, 2))
    assert np.array_equal(vertices, from_msh[0]) and np.array_equal(triangles, from_msh[1])


def test_a_bad_wall_geo_names_the_file_and_gmsh_message(tmp_path, capfd):
    path = _write(tmp_path, "broken.geo", "Point(1) = {0, 0, 0};\nLine(1) = {1, 2};\n")
    with pytest.raises(MeshError) as caught:
        read_surface(path)
    assert str(path) in str(caught.value) and "Unknown control point 2" in str(caught.value)
    assert capfd.readouterr() == ("", "")


# ------------------------------------------------------------------------------------------ the examples' meshes
@pytest.mark.parametrize("geo, box, cells, groups", [
    ("belt.geo", [[0.0, -0.04, -0.006], [0.6, 0.04, 0.0]], [24, 2, 1], {"carrying_side": ["zmax"]}),
    ("hopper_panel.geo", [[-0.004, 0.0, 0.0], [0.0, 0.03, 0.13]], [1, 3, 13],
     {"grain_side": ["xmax"], "edges": ["ymin", "ymax", "zmin", "zmax"]}),
])
def test_the_examples_structured_geo_files_are_their_former_box_meshes(geo, box, cells, groups):
    """examples/belt.yaml and hopper_discharge.yaml meshed these solids as `mesh: {box, cells}`: the .geo
    files give the same nodes and cells, and their named groups are the box faces the scenes used."""
    from_geo = load_mesh(MESHES / geo, MESHES)
    from_box = load_mesh(BoxMeshConfig(box=box, cells=cells), MESHES)
    assert np.array_equal(from_geo.points, from_box.points) and np.array_equal(from_geo.tets, from_box.tets)
    assert sorted(from_geo.face_groups) == sorted(groups)
    for name, faces in groups.items():
        expected = np.vstack([from_box.group_faces(face) for face in faces])
        # Same triangles with the same (outward) corner order; only their order in the list may differ.
        assert sorted(map(tuple, from_geo.face_groups[name].tolist())) == sorted(map(tuple, expected.tolist()))


def test_the_hopper_wall_geo_files_are_what_the_benchmark_writes(tmp_path):
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        import hopper_discharge
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    hopper_discharge.write_example_meshes(tmp_path)
    written = sorted(path.name for path in tmp_path.iterdir())
    assert written == ["hopper_bottom.geo"] + [f"hopper_strip_{k}.geo" for k in range(9)]
    for name in written:
        assert (tmp_path / name).read_text() == (MESHES / name).read_text(), name
    # The floor: two 20 x 30 mm plates at z = 0 (a 20 mm slot between), normals up, into the bin.
    vertices, triangles = read_surface(MESHES / "hopper_bottom.geo")
    normals = np.cross(vertices[triangles[:, 1]] - vertices[triangles[:, 0]],
                       vertices[triangles[:, 2]] - vertices[triangles[:, 0]])
    assert len(triangles) == 4 and np.all(vertices[:, 2] == 0.0) and np.all(normals[:, 2] > 0)
    assert 0.5 * normals[:, 2].sum() == pytest.approx(2 * 0.02 * 0.03, rel=1e-12)  # round-off of the corners


def test_the_tread_wheel_loads_as_a_solid_with_its_tread_facing_outward():
    from mpi4py import MPI

    from pdemfem.fem import Solid, SolidConfig
    from pdemfem.scene.schema import MaterialConfig

    mesh = load_mesh(MESHES / "tread_wheel.geo", MESHES)
    assert len(mesh.points) <= 3000  # small enough for a quick application run (P1)
    assert sorted(mesh.face_groups) == ["rim", "sides", "tread"]
    # rim, tread and sides are the whole boundary, each boundary face in exactly one of them.
    grouped = np.vstack([mesh.face_groups[name] for name in ("rim", "tread", "sides")])
    keys = {tuple(sorted(face)) for face in grouped.tolist()}
    assert len(keys) == len(grouped) == len(boundary_faces(mesh.tets))
    assert keys == {tuple(sorted(face)) for face in boundary_faces(mesh.tets).tolist()}
    radius = np.hypot(mesh.points[:, 0], mesh.points[:, 2])
    assert radius.min() == pytest.approx(0.06, rel=1e-9) and np.abs(mesh.points[:, 1]).max() == pytest.approx(0.02)
    assert radius.max() == pytest.approx(np.hypot(0.088, 0.005), rel=1e-9)  # a lug's outer corner

    config = SolidConfig(name="wheel", mesh=str(MESHES / "tread_wheel.geo"), material="rubber", element="P1",
                         fixed=["rim"], contact=["tread"])
    rubber = MaterialConfig(density=1100.0, youngs_modulus=1.0e7, poisson_ratio=0.45)
    solid = Solid(config, rubber, gravity=(0.0, 0.0, 0.0), comm=MPI.COMM_WORLD)
    surface = solid.contact_surface()
    corners = surface.reference_positions[surface.triangles]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    centroids = corners.mean(axis=1)
    radial = centroids * np.array([1.0, 0.0, 1.0])
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    outward = np.einsum("ij,ij->i", normals, radial) / np.linalg.norm(normals, axis=1)
    # Every tread face looks away from the axis: the ring and the lugs' tops (n.r ~ 1) and the lugs'
    # flanks, parallel to the lug's centre plane 5 mm off it: n.r = 0.005 / r >= 0.005 / 0.0885 = 0.056.
    assert outward.min() > 0.05
    assert len(surface.triangles) == len(mesh.face_groups["tread"])
