"""Reference elements and quadrature: exactness checked against closed-form integrals."""
from math import factorial

import numpy as np
import pytest

from pdemfem.fem.elements import collapsed_gauss_rule, reference_element, shape_gradients, shape_values, split_p2_faces, symmetric_rule


def monomial_integral(a, b, c):
    # int over the reference tetrahedron of x^a y^b z^c = a! b! c! / (a+b+c+3)!
    return factorial(a) * factorial(b) * factorial(c) / factorial(a + b + c + 3)


@pytest.mark.parametrize("degree", [1, 2, 3, 4, 5])
def test_rules_integrate_every_monomial_of_their_degree_exactly(degree):
    for points, weights in (collapsed_gauss_rule(degree), symmetric_rule(degree)):
        for a in range(degree + 1):
            for b in range(degree + 1 - a):
                for c in range(degree + 1 - a - b):
                    value = np.sum(weights * points[:, 0] ** a * points[:, 1] ** b * points[:, 2] ** c)
                    # round-off: a sum of at most 64 positive terms of size <= 1/6
                    assert value == pytest.approx(monomial_integral(a, b, c), rel=1e-13, abs=1e-15)


@pytest.mark.parametrize("name,nodes", [("P1", 4), ("P2", 10)])
def test_shape_functions_are_nodal_and_partition_unity(name, nodes):
    degree = {"P1": 1, "P2": 2}[name]
    corners = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    node_points = corners
    if degree == 2:
        edges = [(0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)]
        node_points = np.vstack([corners, [(corners[i] + corners[j]) / 2 for i, j in edges]])
    # Kronecker property at the nodes, exact in floating point up to one rounding
    assert np.allclose(shape_values(degree, node_points), np.eye(nodes), atol=1e-15)
    points = np.random.default_rng(0).dirichlet(np.ones(4), size=20)[:, 1:]
    assert np.allclose(shape_values(degree, points).sum(axis=1), 1.0, atol=1e-14)
    assert np.allclose(shape_gradients(degree, points).sum(axis=1), 0.0, atol=1e-13)
    element = reference_element(name)
    assert element.nodes_per_cell == nodes


def test_gradients_match_finite_differences():
    points = np.array([[0.2, 0.3, 0.1]])
    h = 1e-6
    for degree in (1, 2):
        analytic = shape_gradients(degree, points)[0]
        for k in range(3):
            step = np.zeros((1, 3))
            step[0, k] = h
            numeric = (shape_values(degree, points + step) - shape_values(degree, points - step))[0] / (2 * h)
            # central difference of a quadratic is exact up to round-off eps/h ~ 1e-10
            assert np.allclose(analytic[:, k], numeric, atol=1e-8)


def test_p2_face_split_keeps_orientation_and_area():
    corners = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    points = np.vstack([corners, (corners[[0, 1, 2]] + corners[[1, 2, 0]]) / 2])
    triangles = split_p2_faces(np.array([[0, 1, 2, 3, 4, 5]]))
    normals = np.cross(points[triangles[:, 1]] - points[triangles[:, 0]], points[triangles[:, 2]] - points[triangles[:, 0]])
    assert np.all(normals[:, 2] > 0)  # same orientation as the parent (+z)
    assert np.isclose(0.5 * normals[:, 2].sum(), 0.5)  # areas add up to the parent's
