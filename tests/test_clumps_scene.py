"""Clump groups in a scene: the keys, their errors, and the insertion (list, lattice, random, file)."""
from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from pdemfem.clumps.quaternion import quaternion_from_axis_angle, rotation_matrices
from pdemfem.clumps.template import clump_template
from pdemfem.errors import SceneError
from pdemfem.particles.insert import first_overlap, insert_particles
from pdemfem.scene.loader import load_scene
from test_clumps_fill import box_mesh, write_stl

RADIUS = 1e-3
SPHERES = [{"position": [0, 0, 0], "radius": RADIUS}, {"position": [1.5 * RADIUS, 0, 0], "radius": 0.7 * RADIUS},
           {"position": [0, 1.2 * RADIUS, 0.3 * RADIUS], "radius": 0.6 * RADIUS}]


def scene(group_insert, clump=None, **group):
    body = {"name": "c", "material": "glass", "insert": group_insert, **group}
    if clump is not None:
        body["clump"] = clump
    return {"time": {"end": 0.01, "dt": 1e-6}, "materials": {"glass": {"density": 2500, "youngs_modulus": 1e7,
                                                                       "poisson_ratio": 0.25}},
            "particles": [body]}


def error_of(data) -> str:
    with pytest.raises(SceneError) as caught:
        load_scene(data)
    return str(caught.value)


LIST = {"kind": "list", "positions": [[0, 0, 0]]}


@pytest.mark.parametrize("data, words", [
    (scene(LIST, {"spheres": SPHERES}, radius=RADIUS), "remove radius"),
    (scene(LIST), "clump: {spheres"),
    (scene({"kind": "stream", "region": {"box": [[0, 0, 0], [1, 1, 1]]}, "rate": 10}, {"spheres": SPHERES}),
     "cannot be inserted by a stream"),
    (scene({**LIST, "orientations": [[1, 0, 0, 0]]}, radius=RADIUS), "insert.orientations is for clump groups"),
    (scene({**LIST, "orientation": [1, 0, 0, 0]}, {"spheres": SPHERES}), "not orientation"),
    (scene({"kind": "lattice", "count": 2, "region": {"box": [[0, 0, 0], [1, 1, 1]]}, "orientations": [[1, 0, 0, 0]]},
           {"spheres": SPHERES}), "not orientations"),
    (scene({**LIST, "orientations": [[1, 0, 0, 0], [1, 0, 0, 0]]}, {"spheres": SPHERES}), "orientations has 2"),
    (scene(LIST, {"spheres": 4}), "needs file"),
    (scene(LIST, {"spheres": []}), "spheres is empty"),
    (scene({**LIST, "radii": [RADIUS]}, {"spheres": SPHERES}), "insert.radii does not apply"),
])
def test_clump_keys_are_checked(data, words):
    assert words in error_of(data)


def test_clumps_with_outlets_or_periodic_axes_are_refused():
    data = scene(LIST, {"spheres": SPHERES})
    data["outlets"] = [{"name": "hole", "kind": "box", "box": [[0, 0, -1], [1, 1, 0]]}]
    assert "outlets cannot take clumps" in error_of(data)
    data = scene(LIST, {"spheres": SPHERES})
    data["domain"] = {"box": [[-1, -1, -1], [1, 1, 1]], "periodic": ["x"]}
    assert "periodic domain" in error_of(data)


def test_a_quaternion_that_is_not_a_rotation_is_refused():
    data = scene({**LIST, "orientations": [[1, 0, 0.5, 0]]}, {"spheres": SPHERES})
    with pytest.raises(SceneError) as caught:
        insert_particles(load_scene(data)[0])
    assert "particles[0].insert.orientations[0]" in str(caught.value) and "unit quaternion" in str(caught.value)


def test_overlapping_clumps_in_a_list_are_refused():
    data = scene({"kind": "list", "positions": [[0, 0, 0], [2.5 * RADIUS, 0, 0]]}, {"spheres": SPHERES})
    with pytest.raises(SceneError) as caught:
        insert_particles(load_scene(data)[0])
    assert "overlap" in str(caught.value) and "orientations" in str(caught.value)


def test_list_places_the_members_turned_about_the_centre_of_mass():
    turn = quaternion_from_axis_angle([0.3, -0.4, 1.0], 1.1)
    data = scene({"kind": "list", "positions": [[0.01, 0.02, 0.03]], "orientations": [turn.tolist()],
                  "angular_velocities": [[0, 0, 5.0]]}, {"spheres": SPHERES})
    loaded = load_scene(data)[0]
    inserted = insert_particles(loaded)
    template = clump_template(loaded.particles[0].clump, 2500.0)
    centres = np.array([sphere["position"] for sphere in SPHERES])
    expected = np.array([0.01, 0.02, 0.03]) + (centres - template.center_of_mass) @ rotation_matrices(turn)[0].T
    np.testing.assert_allclose(inserted.positions, expected, rtol=0, atol=1e-17)
    # A member moves with the body: v = omega x r.  The levers taken back from positions near 0.03 m
    # carry their round-off, a few eps x 0.03 m, times omega = 5 rad/s: 1e-16 m/s bounds it.
    levers = inserted.positions - inserted.clumps.positions[0]
    np.testing.assert_allclose(inserted.velocities, np.cross([0, 0, 5.0], levers), rtol=0, atol=1e-16)


@pytest.mark.parametrize("kind", ["lattice", "random"])
def test_lattice_and_random_clumps_do_not_overlap_and_follow_the_seed(kind):
    region = {"box": [[0, 0, 0], [0.012, 0.012, 0.012]]}
    insert = {"kind": kind, "count": 20, "region": region, "seed": 7}
    inserted = insert_particles(load_scene(scene(insert, {"spheres": SPHERES}))[0])
    assert len(inserted.clumps.positions) == 20 and len(inserted.radii) == 60
    assert first_overlap(inserted.positions, inserted.radii, inserted.member_body) is None
    # Members of one clump overlap (that is the shape): without the labels the check finds them.
    assert first_overlap(inserted.positions, inserted.radii) is not None
    low, high = np.array(region["box"])
    assert np.all(inserted.positions - inserted.radii[:, None] >= low - 1e-15)
    assert np.all(inserted.positions + inserted.radii[:, None] <= high + 1e-15)
    again = insert_particles(load_scene(scene(insert, {"spheres": SPHERES}))[0])
    assert np.array_equal(again.positions, inserted.positions)
    other = insert_particles(load_scene(scene({**insert, "seed": 8}, {"spheres": SPHERES}))[0])
    assert not np.array_equal(other.clumps.orientations, inserted.clumps.orientations)
    # Random orientations: the body axes point every way (a fixed orientation would repeat one).
    assert np.unique(np.round(inserted.clumps.orientations, 6), axis=0).shape[0] == 20


def test_a_given_orientation_turns_every_clump():
    turn = quaternion_from_axis_angle([0, 0, 1], 0.5 * math.pi)
    insert = {"kind": "lattice", "count": 3, "region": {"box": [[0, 0, 0], [0.02, 0.02, 0.02]]},
              "orientation": turn.tolist()}
    loaded = load_scene(scene(insert, {"spheres": SPHERES}))[0]
    inserted = insert_particles(loaded)
    from pdemfem.clumps.quaternion import quaternion_conjugates, quaternion_products

    clump_frame = quaternion_products(inserted.clumps.orientations,
                                      quaternion_conjugates(clump_template(loaded.particles[0].clump,
                                                                           2500.0).principal_orientation))
    np.testing.assert_allclose(np.abs(clump_frame), np.tile(np.abs(turn), (3, 1)), atol=1e-14)


def test_a_clump_filled_from_a_surface_file(tmp_path):
    """clump: {file, spheres: N} fills the surface (relative to the scene file) with N spheres."""
    vertices, triangles = box_mesh([0, 0, 0], [4.0, 2.0, 2.0])
    write_stl(tmp_path / "grain.stl", vertices, triangles)
    data = scene({"kind": "list", "positions": [[0, 0, 0], [0.01, 0, 0]]},
                 {"file": "grain.stl", "spheres": 3, "scale": 1e-3})
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump(data))
    loaded = load_scene(path)[0]
    inserted = insert_particles(loaded)
    assert len(inserted.radii) == 6
    # Inscribed spheres of a 4 x 2 x 2 mm box: radius at most 1 mm.
    assert inserted.radii.max() <= 1e-3 + 1e-12
    data["particles"][0]["clump"]["file"] = "missing.stl"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(SceneError) as caught:
        load_scene(path)
    assert "missing.stl" in str(caught.value)


def test_a_region_thinner_than_a_clump_or_too_full_is_refused():
    thin = {"kind": "random", "count": 2, "region": {"box": [[0, 0, 0], [0.02, 0.02, 0.003]]}}
    with pytest.raises(SceneError) as caught:
        insert_particles(load_scene(scene(thin, {"spheres": SPHERES}))[0])
    assert "particles[0].insert.region.box" in str(caught.value) and "thinner than one clump" in str(caught.value)
    full = {"kind": "random", "count": 200, "max_attempts": 50, "region": {"box": [[0, 0, 0], [0.01, 0.01, 0.01]]}}
    with pytest.raises(SceneError) as caught:
        insert_particles(load_scene(scene(full, {"spheres": SPHERES}))[0])
    assert "particles[0].insert.count" in str(caught.value) and "of 200 clumps" in str(caught.value)
