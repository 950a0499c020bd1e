"""The contact kernels compiled for a scene's composition (pdemfem/contact/specialized.py) give the generic
kernels' results: folding the composition tests removes code that is never taken and changes no arithmetic
of the code that is.  Both fuse multiplies and adds (FMA) where the compiler finds them, and the folded
code gives it other places to do so: the results agree to round-off, not bit for bit."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from mpi_cases.dem_scenes import dense_scene
from pdemfem import Simulation
from pdemfem.contact import forces, specialized


def _hertz_mindlin():
    return dense_scene(count=120)


def _linear_with_rolling_spring():
    scene = dense_scene(count=120, model="linear_spring_dashpot", rolling_friction=0.1)
    scene["interactions"]["default"]["rolling_model"] = "elastic_plastic"
    return scene


def _adhesive_and_conducting():
    scene = dense_scene(count=120, model="jkr")
    scene["interactions"]["default"]["work_of_adhesion"] = 0.05
    scene["materials"]["glass"].update(conductivity=1.0, heat_capacity=800.0)
    scene["particles"][0]["initial_temperature"] = 300.0
    scene["walls"][0]["temperature"] = 400.0
    return scene


def _kernel_results(kernels, system):
    """pair_forces and plane_wall_forces on a copy of the system's state: returned totals, loads, histories,
    heat flows and the walls' forces and heat."""
    state, neighbors, walls, tables = system.state, system.neighbors, system.walls, system.tables
    loads = np.zeros_like(state.forces), np.zeros_like(state.torques)
    heat_flows = np.zeros_like(state.heat_flows) if system.heat else np.zeros((0, 2))
    temperatures = state.temperatures if system.heat else np.zeros(0)
    pair_history, wall_history = neighbors.history.copy(), walls.candidate_history.copy()
    wall_forces, wall_heat = np.zeros_like(walls.forces), np.zeros(walls.count)
    pair_totals = kernels.pair_forces(
        neighbors.row_particles, neighbors.offsets[:-1], neighbors.offsets[1:], neighbors.partners, pair_history,
        state.ids, state.owned_count, state.positions, state.velocities, state.angular_velocities, state.radii,
        state.mass, state.inverse_inertia, state.material_index, tables.coefficients, tables.composition, system.dt,
        *loads, temperatures, heat_flows)
    wall_totals = kernels.plane_wall_forces(
        walls.candidate_particles, walls.candidate_walls, walls.points, walls.normals, walls.velocities,
        walls.material_index, wall_history, state.positions, state.velocities, state.angular_velocities,
        state.radii, state.mass, state.inverse_inertia, state.material_index, tables.coefficients,
        tables.composition, system.dt, *loads, wall_forces, temperatures, heat_flows, walls.temperatures, wall_heat)
    return pair_totals, wall_totals, loads, pair_history, wall_history, heat_flows, wall_forces, wall_heat


@pytest.mark.parametrize("build", [_hertz_mindlin, _linear_with_rolling_spring, _adhesive_and_conducting])
def test_the_specialized_kernels_give_the_generic_results(build, tmp_path):
    sim = Simulation.from_dict(build(), output_dir=tmp_path)
    system = sim.particle_system
    kernels = system.contact_kernels
    assert kernels is not forces and kernels.COMPILED_COMPOSITION == system.tables.composition
    sim.step(5000)  # the pile has formed contacts with both kernels' branches in use (~130-200 contacts)
    pair_totals, wall_totals = _kernel_results(kernels, system)[:2]
    assert pair_totals[2] > 20 and wall_totals[2] > 5, "the state must hold pair and wall contacts"
    specialized_results = _kernel_results(kernels, system)
    generic_results = _kernel_results(forces, system)
    for specialized_value, generic_value in zip(specialized_results, generic_results):
        for a, b in zip(np.atleast_1d(np.asarray(specialized_value, dtype=object)),
                        np.atleast_1d(np.asarray(generic_value, dtype=object))):
            a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
            # A contact's force is a chain of some 50 operations, each rounded once or (fused) not: a few
            # ulp apart, summed over a particle's dozen contacts; 1e-12 of the array's scale bounds that,
            # and any sub-model run or skipped by mistake moves the results by far more.
            assert np.allclose(a, b, rtol=0.0, atol=1e-12 * max(np.abs(b).max(initial=0.0), 1e-300)), (a, b)
    # Counts (pair and wall contacts) are decisions, not sums: equal.
    assert specialized_results[0][2] == generic_results[0][2] and specialized_results[1][2] == generic_results[1][2]


def test_a_composition_module_is_written_once_and_without_a_cache_folder_the_generic_kernels_run(
        tmp_path, monkeypatch):
    path = tmp_path / "kernels.py"
    specialized._write_once(path, "first = 1\n")
    stamp = os.stat(path).st_mtime_ns
    specialized._write_once(path, "second = 2\n")  # another rank, later: the file (and its time stamp) stay
    assert path.read_text() == "first = 1\n" and os.stat(path).st_mtime_ns == stamp
    assert not list(tmp_path.glob("*.tmp"))
    monkeypatch.setattr(specialized, "module_folder", lambda: None)
    assert specialized.contact_kernels.__wrapped__(257) is forces


def test_the_modules_go_beside_a_numba_cache_a_job_points_elsewhere(tmp_path, monkeypatch):
    from pdemfem.runtime import kernel_cache_directory, source_digest

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert specialized.module_folder() == tmp_path / f"pdemfem-specialized-{source_digest()}"
    monkeypatch.setenv("NUMBA_CACHE_DIR", kernel_cache_directory())  # pdemfem's own default (pdemfem.launch)
    assert specialized.module_folder() == Path(kernel_cache_directory()) / "specialized"
