"""Node groups chosen by a region of space (solids[].regions): box and cylinder, used as supports."""
from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from fem_helpers import box_solid, direct_solver, material
from pdemfem.errors import SceneError
from pdemfem.fem import SolidConfig
from pdemfem.fem.regions import REGION_TOLERANCE
from pdemfem.scene.loader import load_scene

BEAM = dict(low=(0.0, 0.0, 0.0), high=(1.0, 0.1, 0.1), cells=(10, 1, 1))
GRAVITY = (0.0, 0.0, -9.81)


def cantilever(**keys):
    with direct_solver():
        solid = box_solid(BEAM["low"], BEAM["high"], BEAM["cells"], material(E=1e6, rho=1000.0), gravity=GRAVITY,
                          comm=MPI.COMM_SELF, element="P2", **keys)
        solid.static_solve()
    return solid


def sorted_state(solid):
    order = np.argsort(solid.original_node_ids)
    return solid.displacements[order]


def test_cantilever_clamped_by_a_box_region_equals_the_face_group():
    # The region's box is the plane x = 0 exactly: the tolerance takes the face's nodes (corners and P2
    # midsides) and nothing of the next row, 0.05 m (half a cell, P2) away.
    by_face = cantilever(fixed=["xmin"])
    by_region = cantilever(regions={"clamp": {"box": [[0.0, -1.0, -1.0], [0.0, 1.0, 1.0]]}}, fixed=["clamp"])
    face_nodes = np.sort(by_face.original_node_ids[by_face.group_node_numbers("xmin")])
    region_nodes = np.sort(by_region.original_node_ids[by_region.group_node_numbers("clamp")])
    np.testing.assert_array_equal(region_nodes, face_nodes)
    tip = np.abs(sorted_state(by_face)).max()
    assert tip > 1e-3  # a real bending load (the comparison below is not between zeros)
    # Same constraints, same matrix, same direct solve: identical to round-off (a few ulps of the tip value).
    np.testing.assert_allclose(sorted_state(by_region), sorted_state(by_face), rtol=0, atol=1e-12 * tip)
    # The reaction on the region balances the beam's weight like the face group's (to round-off of K u - f).
    weight = 1000.0 * 9.81 * 1.0 * 0.1 * 0.1
    np.testing.assert_allclose(by_region.reaction("clamp"), by_face.reaction("xmin"), rtol=0, atol=1e-9 * weight)
    np.testing.assert_allclose(by_region.reaction("clamp")[2], weight, rtol=1e-9)


def test_cylinder_region_picks_the_line_of_nodes_on_its_axis():
    # An idler under a belt: the axis along y through (0.5, *, 0) takes the bottom nodes at x = 0.5 only.
    solid = box_solid((0.0, 0.0, 0.0), (1.0, 0.2, 0.1), (10, 2, 2), material(), comm=MPI.COMM_SELF,
                      regions={"idler": {"cylinder": {"point": [0.5, 0.0, 0.0], "direction": [0.0, 2.0, 0.0],
                                                      "radius": 0.01}}},
                      fixed=["idler"])
    points = solid.reference_positions[solid.group_node_numbers("idler")]
    expected = solid.reference_positions
    expected = expected[(np.abs(expected[:, 0] - 0.5) < 1e-9) & (np.abs(expected[:, 2]) < 1e-9)]
    assert len(points) == 3  # y = 0, 0.1, 0.2 (2 cells across)
    np.testing.assert_allclose(np.sort(points[:, 1]), np.sort(expected[:, 1]), atol=1e-12)
    np.testing.assert_allclose(points[:, [0, 2]], np.tile([0.5, 0.0], (3, 1)), atol=1e-12)


def test_region_tolerance_is_relative_to_the_shortest_edge():
    # A box ending 0.5e-3 cells short of the x = 0.1 node row still takes it; 2e-3 cells short does not.
    def count(gap):
        solid = box_solid((0.0, 0.0, 0.0), (1.0, 0.1, 0.1), (10, 1, 1), material(), comm=MPI.COMM_SELF,
                          regions={"end": {"box": [[-1.0, -1.0, -1.0], [0.1 - gap, 1.0, 1.0]]}}, fixed=["end"])
        return len(solid.group_node_numbers("end"))
    edge = 0.1  # the shortest edge of this mesh
    assert count(0.5 * REGION_TOLERANCE * edge) == 8   # rows x = 0 and x = 0.1, 4 nodes each
    assert count(2.0 * REGION_TOLERANCE * edge) == 4


def test_empty_region_names_the_key():
    with pytest.raises(SceneError) as error:
        box_solid((0, 0, 0), (1, 1, 1), (1, 1, 1), material(), comm=MPI.COMM_SELF, name="belt",
                  regions={"idler": {"box": [[2.0, 0.0, 0.0], [3.0, 1.0, 1.0]]}}, fixed=["idler"])
    assert "solids (belt).regions.idler" in str(error.value)
    assert "no mesh node lies in the region" in str(error.value)


@pytest.mark.parametrize("keys, named", [
    (dict(tractions=[{"group": "r", "traction": [0, 0, 1]}]), "tractions[0].group"),
    (dict(contact=["zmax", "r"]), "contact[1]"),
    (dict(thermal={"fixed": [{"group": "r", "temperature": 300}]}), "thermal.fixed[0].group"),
])
def test_region_refused_where_faces_are_needed(keys, named):
    scene = {"time": {"end": 0.1, "dt": 1e-3}, "materials": {"m": {"density": 1, "youngs_modulus": 1, "poisson_ratio": 0.3}},
             "solids": [{"name": "s", "mesh": {"box": [[0, 0, 0], [1, 1, 1]], "cells": [1, 1, 1]}, "material": "m",
                         "regions": {"r": {"box": [[0, 0, 0], [1, 1, 0]]}}, "fixed": ["r"], **keys}]}
    with pytest.raises(SceneError) as error:
        load_scene(scene)
    assert named in str(error.value) and "is a region" in str(error.value)


@pytest.mark.parametrize("region, words", [
    ({"box": [[0, 0, 0], [1, 1, 0]], "cylinder": {"point": [0, 0, 0], "direction": [0, 1, 0], "radius": 1}},
     "exactly one of box"),
    ({}, "exactly one of box"),
    ({"cylinder": {"point": [0, 0, 0], "direction": [0, 0, 0], "radius": 1}}, "zero vector"),
])
def test_region_shape_errors(region, words):
    with pytest.raises(ValueError, match=words):
        SolidConfig(name="s", mesh={"box": [[0, 0, 0], [1, 1, 1]], "cells": [1, 1, 1]}, material="m",
                    regions={"r": region})


def test_region_named_like_a_box_face_or_a_mesh_group_is_refused(tmp_path):
    with pytest.raises(ValueError, match="named like box faces"):
        SolidConfig(name="s", mesh={"box": [[0, 0, 0], [1, 1, 1]], "cells": [1, 1, 1]}, material="m",
                    regions={"xmin": {"box": [[0, 0, 0], [0, 1, 1]]}})
    from fem_helpers import unstructured_box_msh
    from pdemfem.fem import Solid

    path = unstructured_box_msh(tmp_path / "box.msh", size=0.5)
    config = SolidConfig(name="s", mesh=path, material="m", regions={"bottom": {"box": [[0, 0, 0], [1, 1, 0]]}},
                         fixed=["bottom"])
    with pytest.raises(SceneError, match="physical group of the same name"):
        Solid(config, material(), comm=MPI.COMM_SELF)
