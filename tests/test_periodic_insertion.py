"""Insertion in a periodic domain tests its pairs through the periodic faces: a listed particle overlapping
another through a face is refused like one overlapping it inside, and a stream keeps clear of the particles
that stand beyond the opposite face (a chute's inlet across its periodic width)."""
from __future__ import annotations

import numpy as np
import pytest

from pdemfem import Simulation
from pdemfem.errors import SceneError
from pdemfem.particles.periodic_images import PeriodicBox
from pdemfem.scene.loader import load_scene

PERIOD = 0.03
RADIUS = 0.002


def _scene(groups, periodic=("x", "y", "z")):
    return {
        "time": {"end": 0.003, "dt": "auto"},
        "gravity": [0, 0, 0],
        "materials": {"grain": {"density": 2500, "youngs_modulus": 5e6, "poisson_ratio": 0.25}},
        "interactions": {"default": {"restitution": 0.5, "friction": 0.5}},
        "particles": groups,
        "domain": {"box": [[0, 0, 0], [PERIOD, PERIOD, PERIOD]], "periodic": list(periodic)},
        "output": {"every": 1e-3},
    }


def _listed(positions, name="bed"):
    return {"name": name, "material": "grain", "radius": RADIUS, "insert": {"kind": "list", "positions": positions}}


def _minimum_image_overlap(positions, radii) -> float:
    """The deepest overlap over the smaller radius, distances taken to the nearest periodic image."""
    worst = 0.0
    for i in range(len(radii)):
        separation = positions - positions[i]
        separation -= PERIOD * np.round(separation / PERIOD)
        overlap = (radii + radii[i] - np.linalg.norm(separation, axis=1)) / np.minimum(radii, radii[i])
        overlap[i] = -np.inf
        worst = max(worst, float(overlap.max()))
    return worst


def test_images_cover_faces_edges_and_corners():
    box = PeriodicBox(np.zeros(3), np.full(3, 1.0), np.array([True, True, False]))
    positions, radii, rows = box.with_images(np.array([[0.05, 0.95, 0.5], [0.5, 0.5, 0.01]]), np.array([1.0, 2.0]),
                                             0.1)
    images, sources = positions[2:], rows[2:]
    assert list(rows[:2]) == [0, 1] and list(radii) == [1.0, 2.0] + [1.0] * len(images)
    # The first is near x = 0 and y = 1: images across x, across y and across the (x, y) edge; the second is
    # near z = 0 only, which is not periodic.
    expected = {(1.05, 0.95, 0.5), (0.05, -0.05, 0.5), (1.05, -0.05, 0.5)}
    assert {tuple(np.round(image, 12)) for image in images} == expected
    assert np.all(sources == 0)
    assert np.allclose(box.wrapped([[1.25, -0.25, 3.0]]), [[0.25, 0.75, 3.0]])


@pytest.mark.parametrize("second", [[PERIOD, 0.01, 0.005], [PERIOD - 0.0015, 0.01, 0.005]])
def test_listed_particles_overlapping_through_a_periodic_face_are_refused(second):
    """The same point through the x period (a run divided by its zero distance) and 1.5 mm apart through it
    (a radius sum of 4 mm: the pair shot apart at step 0 and the monitor blamed the step)."""
    with pytest.raises(SceneError) as caught:
        Simulation.from_dict(_scene([_listed([[0.0, 0.01, 0.005], second])]))
    message = str(caught.value)
    assert "particles 0 and 1 overlap at insertion through a periodic face" in message, message
    distance = PERIOD - second[0]
    assert f"centre distance {distance:g} m" in message, message


def test_listed_particles_apart_through_the_face_are_accepted():
    load_scene(_scene([_listed([[0.0025, 0.01, 0.005], [PERIOD - 0.0025, 0.01, 0.005]])]))  # 5 mm apart
    simulation = Simulation.from_dict(_scene([_listed([[0.0025, 0.01, 0.005], [PERIOD - 0.0025, 0.01, 0.005]])]))
    assert simulation.particle_count() == 2


def test_a_stream_keeps_clear_of_particles_beyond_the_opposite_face(tmp_path):
    """A wall of resting spheres 1.5 mm inside the x = L face and a stream region along the x = 0 face: through
    the period the two are 1.5 mm apart, less than a radius.  The stream's candidates were drawn clear of the
    particles near its region only, and the second event put one 0.125 r into a resting sphere (without
    gravity the monitor then stopped the run; with it, the pair would have been kicked apart silently).  Now
    no candidate overlaps any particle or its image, and with nothing moving the books hold no elastic energy."""
    layers = np.arange(0.003, 0.029, 0.0042)
    bed = [[PERIOD - 0.0015, y, z] for y in layers for z in layers]
    feed = {"name": "feed", "material": "grain", "radius": RADIUS,
            "insert": {"kind": "stream", "region": {"box": [[0, 0, 0], [0.007, PERIOD, PERIOD]]}, "rate": 20000,
                       "interval": 0.001, "seed": 1}}
    simulation = Simulation.from_dict(_scene([_listed(bed), feed]), output_dir=str(tmp_path / "out"))
    steps = int(np.ceil(0.0025 / simulation.dt))  # three insertion events
    worst = 0.0
    for _ in range(steps):
        simulation.step(1)
        particles = simulation.particles
        worst = max(worst, _minimum_image_overlap(particles.positions, particles.radii))
    assert simulation.particle_count() >= len(bed) + 30, simulation.particle_count()  # two events placed (20 each)
    assert worst <= 0.0, worst
    assert simulation.energies()["elastic_energy"] == 0.0
