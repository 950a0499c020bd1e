"""Mass properties of sphere unions (pdemfem.clumps.shape) against closed forms and independent integrations."""
from __future__ import annotations

import math

import numpy as np
import pytest

from pdemfem.clumps.shape import (exact_union_moments, lens_moments, ray_grid_moments,
                                  sphere_union_mass_properties)
from pdemfem.errors import SceneError

EPS = np.finfo(float).eps
TWO_SPHERES = (np.array([[0.0, 0.0, 0.0], [1.3, 0.4, -0.2]]), np.array([1.0, 0.7]))  # d = 1.38: lens ~ 5 % of the union


def _central_inertia(volume, first, second, density=1.0):
    center = first / volume
    central = second - volume * np.outer(center, center)
    return density * volume, center, density * (np.trace(central) * np.eye(3) - central)


def voxel_mass_properties(centers, radii, spacing):
    """Brute force, independent of the module: count voxel midpoints inside any sphere (numpy, slab by slab)."""
    low = (centers - radii[:, None]).min(axis=0)
    high = (centers + radii[:, None]).max(axis=0)
    cells = np.ceil((high - low) / spacing).astype(int)
    low = 0.5 * (low + high) - 0.5 * cells * spacing
    ys = low[1] + (np.arange(cells[1]) + 0.5) * spacing
    zs = low[2] + (np.arange(cells[2]) + 0.5) * spacing
    y_grid, z_grid = np.meshgrid(ys, zs, indexing="ij")
    count, first, second = 0, np.zeros(3), np.zeros((3, 3))
    for i in range(cells[0]):
        x = low[0] + (i + 0.5) * spacing
        inside = np.zeros(y_grid.shape, dtype=bool)
        for center, radius in zip(centers, radii):
            inside |= (x - center[0]) ** 2 + (y_grid - center[1]) ** 2 + (z_grid - center[2]) ** 2 < radius * radius
        points = np.stack([np.full(int(inside.sum()), x), y_grid[inside], z_grid[inside]])
        count += points.shape[1]
        first += points.sum(axis=1)
        second += points @ points.T
    cell_volume = spacing ** 3
    return _central_inertia(count * cell_volume, first * cell_volume, second * cell_volume)


def test_single_sphere_is_exact():
    radius, density = 0.5e-3, 2500.0
    props = sphere_union_mass_properties([[1e-3, 2e-3, -3e-3]], [radius], density)
    mass = density * 4.0 / 3.0 * math.pi * radius ** 3
    # Closed forms evaluated in a different order: a few eps apart.
    assert props.mass == pytest.approx(mass, rel=4 * EPS)
    assert np.allclose(props.inertia, 0.4 * mass * radius ** 2 * np.eye(3), rtol=0, atol=8 * EPS * 0.4 * mass * radius ** 2)
    assert np.array_equal(props.center_of_mass, [1e-3, 2e-3, -3e-3])
    assert np.array_equal(props.principal_orientation, [1.0, 0.0, 0.0, 0.0])
    assert props.method == "exact" and props.relative_error_estimate == 0.0


def test_lens_volume_matches_the_textbook_formula():
    """Cap decomposition against V = pi (r1 + r2 - d)^2 (d^2 + 2 d (r1 + r2) - 3 (r1 - r2)^2) / (12 d)."""
    for r1, r2, d in [(1.0, 0.7, 1.38), (1.0, 1.0, 0.5), (1.0, 0.4, 0.7), (0.3, 1.0, 0.9)]:
        volume, first, _ = lens_moments([0.0, 0.0, 0.0], r1, [d, 0.0, 0.0], r2)
        expected = math.pi * (r1 + r2 - d) ** 2 * (d * d + 2 * d * (r1 + r2) - 3 * (r1 - r2) ** 2) / (12 * d)
        assert volume == pytest.approx(expected, rel=1e-13)   # cancellations in the cap sums: ~100 eps
        # The lens's centroid lies on the line of centres.
        assert abs(first[1]) == 0.0 and abs(first[2]) == 0.0


def test_two_spheres_exact_against_the_ray_grid_which_converges_as_n_squared():
    centers, radii = TWO_SPHERES
    exact_mass, exact_center, exact_inertia = _central_inertia(*exact_union_moments(centers, radii))
    # The union is not the sum of the spheres: the lens is taken out once.
    assert exact_mass < 4.0 / 3.0 * math.pi * (radii ** 3).sum() * (1 - 0.02)
    ns = np.array([32, 64, 128, 256, 512])
    mass_errors, inertia_errors = [], []
    for n in ns:
        mass, center, inertia = _central_inertia(*ray_grid_moments(centers, radii, int(n)))
        mass_errors.append(abs(mass / exact_mass - 1.0))
        inertia_errors.append(np.abs(inertia - exact_inertia).max() / np.abs(exact_inertia).max())
    # Midpoint rule on a continuous integrand with square-root edges: error ~ n^-2 (module docstring).
    # Least-squares slopes measured -2.0 (mass) and -1.9 (inertia); the lattice makes single points
    # scatter by 3x, so the slope is allowed -2 +- 0.5.
    for errors in (mass_errors, inertia_errors):
        slope = np.polyfit(np.log(ns), np.log(errors), 1)[0]
        assert -2.5 <= slope <= -1.5, (slope, errors)
    # At the default n = 512: measured 2.7e-6 (mass) and 1.2e-5 (inertia); bound 16 / n^2 = 6e-5, the
    # n^-2 law with the largest constant seen over n = 16..512 (3.0 n^-2, inertia at n = 16) times about 5
    # for the lattice scatter.
    assert mass_errors[-1] <= 16 / 512 ** 2 and inertia_errors[-1] <= 16 / 512 ** 2
    # The estimate the result carries (n/2 -> n change) is not smaller than the true error.
    props = sphere_union_mass_properties(centers, radii, 1.0, method="rays")
    true_error = max(abs(props.mass / exact_mass - 1), np.abs(props.inertia - exact_inertia).max() / np.abs(exact_inertia).max())
    assert true_error <= props.relative_error_estimate


def test_symmetric_dumbbell_principal_axes_follow_its_axis():
    axis = np.array([1.0, 1.0, 1.0]) / math.sqrt(3.0)
    centers = np.array([-0.6 * axis, 0.6 * axis]) + [0.2, -0.1, 0.3]
    props = sphere_union_mass_properties(centers, [0.8, 0.8], 1000.0)
    principal = props.principal_axes()
    # Smallest moment about the rod axis; the two transverse moments equal.  Eigenvector round-off:
    # eps / (relative gap of the moments ~ 0.5) -> 1e-14.
    assert abs(abs(principal[:, 0] @ axis) - 1.0) <= 1e-14
    assert props.principal_moments[1] == pytest.approx(props.principal_moments[2], rel=1e-14)
    assert props.principal_moments[0] < 0.9 * props.principal_moments[1]
    assert np.allclose(props.center_of_mass, [0.2, -0.1, 0.3], atol=1e-15)
    assert np.linalg.det(principal) == pytest.approx(1.0, abs=1e-14)   # right-handed
    # Member offsets in the body frame lie on body axis 1, at +-0.6.
    offsets = props.member_offsets(centers)
    assert np.allclose(np.abs(offsets), [[0.6, 0, 0], [0.6, 0, 0]], atol=1e-14)


def test_chain_without_triple_overlap_is_exact():
    """Three spheres in a row, only neighbours overlap: inclusion-exclusion to pairs is exact."""
    centers = np.array([[0.0, 0.0, 0.0], [0.9, 0.1, 0.0], [1.8, 0.0, 0.2]])
    radii = np.array([0.5, 0.6, 0.5])
    exact = sphere_union_mass_properties(centers, radii, 1.0)
    rays = sphere_union_mass_properties(centers, radii, 1.0, method="rays")
    assert exact.method == "exact"
    # Ray grid error at n = 512 (previous test): its own n/2 -> n estimate bounds the difference.
    assert abs(rays.mass / exact.mass - 1) <= rays.relative_error_estimate
    assert np.abs(rays.inertia - exact.inertia).max() <= rays.relative_error_estimate * np.abs(exact.inertia).max()


def test_three_mutually_overlapping_spheres_against_brute_force_voxels():
    centers = np.array([[0.0, 0.0, 0.0], [0.75, 0.25, 0.1], [0.3, 0.6, -0.25]])
    radii = np.array([0.7, 0.5, 0.4])            # overlaps: 12 % of the union; moments 0.40, 0.59, 0.64
    props = sphere_union_mass_properties(centers, radii, 1.0)
    assert props.method.startswith("ray grid")
    spacing = radii.min() / 48
    mass, center, inertia = voxel_mass_properties(centers, radii, spacing)
    # Voxel counting of a ball of R = r/h voxels errs by O(R^2) voxels: relative 4 (h/r)^2 at most on the
    # exact one- and two-sphere clumps (measured, r/h = 35..80); bound 10 (h / r_min)^2 = 4.3e-3.  Measured
    # here: mass 1.3e-4, inertia 1.9e-4.  Counting the overlaps twice would be off by 12 % (> 25 bounds).
    bound = 10 * (spacing / radii.min()) ** 2
    assert abs(props.mass / mass - 1) <= bound
    assert np.abs(props.inertia - inertia).max() <= bound * np.abs(inertia).max()
    assert np.abs(props.center_of_mass - center).max() <= bound * radii.min()
    summed_volume = 4.0 / 3.0 * math.pi * (radii ** 3).sum()
    assert summed_volume > (1 + 25 * bound) * props.mass


def test_given_mass_and_inertia_override():
    centers, radii = TWO_SPHERES
    computed = sphere_union_mass_properties(centers, radii, 1000.0)
    heavier = sphere_union_mass_properties(centers, radii, 1000.0, mass=2 * computed.mass)
    assert heavier.mass == 2 * computed.mass
    assert np.allclose(heavier.inertia, 2 * computed.inertia, rtol=4 * EPS, atol=0)
    given = sphere_union_mass_properties(centers, radii, 1000.0, inertia=[1.0, 2.0, 2.5])
    assert np.array_equal(given.principal_moments, [1.0, 2.0, 2.5])
    assert np.array_equal(given.center_of_mass, computed.center_of_mass)
    with pytest.raises(SceneError, match="triangle|I1 \\+ I2"):
        sphere_union_mass_properties(centers, radii, 1000.0, inertia=[1.0, 1.0, 3.0])
    with pytest.raises(SceneError, match="positive"):
        sphere_union_mass_properties(centers, radii, 1000.0, mass=-1.0)
    with pytest.raises(SceneError, match="radii"):
        sphere_union_mass_properties(centers, [1.0, -0.1], 1000.0)
