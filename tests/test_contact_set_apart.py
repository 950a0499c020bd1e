"""The pair loop sets contacts' first evaluations apart and computes them after the others (so the dashpot's
onset factor is not inlined for every contact); a full buffer makes it stop, compute them and go on.  The
results must be those of the loop that computes every contact in place, whatever the buffer's size."""
from __future__ import annotations

import numpy as np
import pytest

from mpi_cases.dem_scenes import dense_scene
from pdemfem import Simulation


def _pair_results(system, set_apart):
    state, neighbors, tables = system.state, system.neighbors, system.tables
    forces, torques = np.zeros_like(state.forces), np.zeros_like(state.torques)
    history = neighbors.history.copy()
    arguments = (neighbors.row_particles, neighbors.offsets[:-1], neighbors.offsets[1:], neighbors.partners, history,
                 state.ids, state.owned_count, state.positions, state.velocities, state.angular_velocities,
                 state.radii, state.mass, state.inverse_inertia, state.material_index, tables.coefficients,
                 tables.composition, system.dt, forces, torques, np.zeros(0), np.zeros((0, 2)))
    if set_apart is None:
        totals = system.contact_kernels.pair_forces(*arguments)
    else:
        totals = system.contact_kernels.pair_forces(*arguments, set_apart)
    return np.array(totals), forces, torques, history


def _first_evaluations(system):
    """The listed pairs that touch and closed by more than their overlap over the last step."""
    state, neighbors = system.state, system.neighbors
    rows = np.repeat(neighbors.row_particles, np.diff(neighbors.offsets))
    partners = neighbors.partners[:neighbors.offsets[-1]]
    separation = state.positions[rows] - state.positions[partners]
    distance = np.linalg.norm(separation, axis=1)
    overlap = state.radii[rows] + state.radii[partners] - distance
    closing = -np.einsum("ij,ij->i", state.velocities[rows] - state.velocities[partners], separation) / distance
    return int(np.count_nonzero((overlap > 0.0) & (overlap < closing * system.dt)))


@pytest.mark.parametrize("model", ["hertz_mindlin", "linear_spring_dashpot"])
def test_first_evaluations_set_apart_give_the_in_place_results(model, tmp_path):
    simulation = Simulation.from_dict(dense_scene(count=150, model=model), output_dir=str(tmp_path / "out"))
    simulation.step(6000)  # a bed on the floor: 200-230 touching pairs
    system = simulation.particle_system
    # Thrown at each other fast: many touching pairs become first evaluations, as at a pour's impacts.
    rng = np.random.default_rng(5)
    system.state.velocities[:system.state.owned_count] += rng.normal(0.0, 3.0, (system.state.owned_count, 3))
    first = _first_evaluations(system)
    capacity = 3
    assert first > 3 * capacity, f"only {first} first evaluations: the resumed loop is not exercised"

    in_place = _pair_results(system, None)
    scale = [np.abs(part).max() for part in in_place]
    for set_apart in (np.empty((3, capacity), dtype=np.int64), system.contact_kernels.set_apart_buffer()):
        results = _pair_results(system, set_apart)
        # The set-apart contacts are added to the loads after the others: round-off of the sums' order
        # (a few ulps of the largest term, with FMA contractions placed alike in both loops).
        for got, expected, largest in zip(results, in_place, scale):
            np.testing.assert_allclose(got, expected, rtol=0.0, atol=1e-12 * largest)
