"""Scene keys of a solid, and one clear MeshError per kind of unusable mesh."""
import meshio
import numpy as np
import pytest
from pydantic import ValidationError

from fem_helpers import material, unstructured_box_msh
from pdemfem.errors import MeshError
from pdemfem.fem import Solid, SolidConfig

ISSUE_EXAMPLE = {
    "name": "block",
    "mesh": "block.msh",
    "material": "steel",
    "element": "P1",
    "mass": "lumped",
    "damping": {"alpha": 0.0, "beta": 0.0},
    "fixed": ["bottom"],
    "prescribed": [{"group": "roller", "velocity": [0.1, 0, 0]}],
    "contact": ["top"],
    "initial_temperature": 293.15,
    "reference_temperature": 293.15,
}


def test_issue_example_validates_and_unknown_keys_are_rejected():
    config = SolidConfig(**ISSUE_EXAMPLE)
    assert config.prescribed[0].velocity == (0.1, 0.0, 0.0)
    SolidConfig(**{**ISSUE_EXAMPLE, "mesh": {"box": [[0, 0, 0], [1, 1, 1]], "cells": [2, 2, 2]}})
    with pytest.raises(ValidationError, match="extra"):
        SolidConfig(**{**ISSUE_EXAMPLE, "elemnt": "P2"})
    with pytest.raises(ValidationError, match="exactly one"):
        SolidConfig(**{**ISSUE_EXAMPLE, "prescribed": [{"group": "roller", "velocity": [1, 0, 0], "displacement": [0, 0, 0]}]})
    with pytest.raises(ValidationError, match="P1"):
        SolidConfig(**{**ISSUE_EXAMPLE, "element": "P3"})
    with pytest.raises(ValidationError, match="every max > min"):
        SolidConfig(**{**ISSUE_EXAMPLE, "mesh": {"box": [[0, 0, 0], [1, 0, 1]], "cells": [2, 2, 2]}})


def _config(mesh, **keys):
    return SolidConfig(name="s", mesh=mesh, material="m", **keys)


def _write(path, points, cells):
    meshio.write(str(path), meshio.Mesh(np.asarray(points, float), cells))
    return str(path)


UNIT_TET = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]]


def test_unreadable_and_missing_files(tmp_path):
    garbage = tmp_path / "garbage.msh"
    garbage.write_text("this is not a mesh\n")
    with pytest.raises(MeshError, match="garbage.msh") as error:
        Solid(_config(str(garbage)), material())
    assert "cannot read" in error.value.problem
    with pytest.raises(MeshError, match="not found"):
        Solid(_config("absent.msh"), material(), base_dir=tmp_path)


def test_no_volume_cells(tmp_path):
    path = _write(tmp_path / "surface.vtu", UNIT_TET[:3], [("triangle", [[0, 1, 2]])])
    with pytest.raises(MeshError, match="no volume cells") as error:
        Solid(_config(path), material())
    assert error.value.where == path


def test_a_mesh_mixing_tetrahedra_with_other_cells_is_refused(tmp_path):
    """Only tetrahedra are supported: the hexahedron of a mixed mesh was dropped without a word, and half a
    block went missing (its mass, stiffness and supports) while check said OK."""
    points = UNIT_TET + [[1, 1, 0], [1, 0, 1], [0, 1, 1], [1, 1, 1], [2, 0, 0], [2, 1, 0], [2, 0, 1], [2, 1, 1]]
    hexahedron = [1, 9, 10, 5, 6, 11, 12, 8]  # the unit cube x in [1, 2], beside the tetrahedron
    path = _write(tmp_path / "mixed.vtu", points, [("tetra", [[0, 1, 2, 3]]), ("hexahedron", [hexahedron])])
    with pytest.raises(MeshError, match="mixes tetrahedra with other volume cells") as error:
        Solid(_config(path), material())
    assert error.value.where == path and "hexahedron" in error.value.problem


def test_inverted_cell_is_named(tmp_path):
    # cell 1 (0,1,2,4)... is built with the opposite orientation of cell 0
    path = _write(tmp_path / "inverted.vtu", UNIT_TET, [("tetra", [[0, 1, 2, 3], [1, 2, 4, 3][::-1]])])
    cells = meshio.read(path).cells[0].data
    points = np.array(UNIT_TET, float)
    signs = np.sign(np.linalg.det(points[cells[:, 1:]] - points[cells[:, [0]]]))
    assert signs[0] != signs[1]  # the file really mixes orientations
    with pytest.raises(MeshError, match="inverted") as error:
        Solid(_config(path), material())
    assert "cells [1]" in error.value.where or "cells [0]" in error.value.where


def test_degenerate_cell_is_named(tmp_path):
    flat = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 0, 1]]
    path = _write(tmp_path / "flat.vtu", flat, [("tetra", [[0, 1, 2, 4], [0, 1, 2, 3]])])
    with pytest.raises(MeshError, match="degenerate") as error:
        Solid(_config(path), material())
    assert "cells [1]" in error.value.where


def test_missing_group_names_file_and_group(tmp_path):
    path = unstructured_box_msh(tmp_path / "box.msh", size=0.5)
    with pytest.raises(MeshError) as error:
        Solid(_config(path, fixed=["botom"]), material())
    assert error.value.where == f"{path}: group 'botom'"
    assert "bottom" in error.value.problem  # lists what the mesh has
    # the real groups and box faces are accepted
    solid = Solid(_config(path, fixed=["bottom"], contact=["boundary", "zmax"]), material())
    assert solid.surface_triangles(["zmax"]).shape[1] == 3


def test_box_mesh_counts_and_surface_orientation():
    solid = Solid(_config({"box": [[0, 0, 0], [2, 1, 1]], "cells": [2, 1, 1]}, contact=["xmin", "zmax"], element="P2"), material())
    assert solid.mesh.n_global_cells == 2 * 6  # 6 tetrahedra per hexahedron
    triangles = solid.surface_triangles(["zmax"])
    nodes, positions, velocities = solid.surface_state(["zmax"])
    assert len(triangles) == 2 * 2 * 4  # 2 squares x 2 faces x 4 sub-triangles (P2)
    local = np.searchsorted(nodes, triangles)
    normals = np.cross(positions[local[:, 1]] - positions[local[:, 0]], positions[local[:, 2]] - positions[local[:, 0]])
    assert np.all(normals[:, 2] > 0)  # outward on the top face
    assert np.isclose(0.5 * normals[:, 2].sum(), 2.0)  # covers the 2 x 1 face exactly
    assert np.all(velocities == 0.0)


def test_a_cell_with_a_repeated_node_is_named_before_the_groups_are_matched(tmp_path):
    """A tetrahedron whose fourth node repeats its third (nodes 1 2 3 3) is degenerate; the group's triangle
    that was its face no longer matches one, and that was reported first ('not faces of any tetrahedron ...
    regenerate the mesh so surface and volume meshes are conforming')."""
    cells = [meshio.CellBlock("tetra", np.array([[0, 1, 2, 3], [1, 2, 3, 3], [1, 2, 4, 0]])),
             meshio.CellBlock("triangle", np.array([[1, 3, 4]]))]
    mesh = meshio.Mesh(np.array(UNIT_TET, float), cells,
                       cell_data={"gmsh:physical": [np.array([1, 1, 1]), np.array([2])],
                                  "gmsh:geometrical": [np.array([1, 1, 1]), np.array([2])]},
                       field_data={"body": np.array([1, 3]), "top": np.array([2, 2])})
    path = str(tmp_path / "repeated.msh")
    meshio.write(path, mesh, file_format="gmsh22", binary=False)
    with pytest.raises(MeshError, match="degenerate") as error:
        Solid(_config(path), material())
    assert "cells [1]" in error.value.where
