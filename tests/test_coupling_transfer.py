"""coupling.transfer blended: the contact's gap on a surface that dimples under the contact.

A heavy sphere (R = 0.2 m, 335 kg) on a soft clamped block (E = 1e6 Pa, 16 x 16 x 8 cells): the contact is 2.5
times stiffer than the surface under it (S_n/(E l); the point-load limit is 0.5), the surface dimples into a cone
of facets under the particle.  Restitution 1, no friction: nothing dissipates, so the mechanical energy must stay
within velocity Verlet's oscillation on the resting contact, (omega_c dt)^2 / 4 of m g delta
(stability_cases.verlet_energy_bound).  The energy is taken at the particles' time level (stability_cases.
LevelEnergy, the scheme's exact invariant without FE sub-steps; sim.energies() adds the solid one step ahead,
which swings by ~dt x the exchanged power, +-0.5 J here, without any gain).

* nearest: the gap is the distance to the nearest facet; over the dimple the nearest facet changes every few
  steps and the force direction jumps (15-28 degrees): +26.6 J in 0.4 s (measured), 5e4 times the bound.
* blended: the gap is a smooth blend of the facets under the sphere, its elastic force the exact gradient of
  that potential on the particle and on every node of those facets: within the bound (measured -3.2e-4 J).
"""
import numpy as np
import pytest

from stability_cases import LevelEnergy, resting_scene, verlet_energy_bound
from pdemfem import Simulation

SOFT = 1e6


def soft_scene(cells, transfer, end, element="P1", restitution=1.0):
    scene = resting_scene(cells, restitution=restitution, end=end, element=element)
    scene["materials"]["steel"]["youngs_modulus"] = SOFT
    scene["coupling"]["transfer"] = transfer
    return scene


def energy_range(tmp_path, scene, name):
    """(lowest, highest) change of the level energy from t^1 (the invariant needs v on both sides) to the end."""
    sim = Simulation.from_dict(scene, output_dir=str(tmp_path / name))
    assert sim.coupling.fem_substeps["block"] == 1  # LevelEnergy is the scheme's exact invariant only then
    level = LevelEnergy(sim)
    sim.step()
    start = level.update()
    lowest = highest = 0.0
    for _ in range(int(round(scene["time"]["end"] / sim.dt)) - 1):
        sim.step()
        change = level.update() - start
        lowest, highest = min(lowest, change), max(highest, change)
    return lowest, highest, verlet_energy_bound(sim.dt)


def test_blended_gap_keeps_the_energy_of_a_sphere_resting_in_its_dimple(tmp_path):
    lowest, highest, bound = energy_range(tmp_path, soft_scene(16, "blended", 0.4), "blended")
    assert -bound <= lowest and highest <= bound, (lowest, highest, bound)
    # The nearest-facet gap on the same surface gains energy: what the blend removes.
    _, highest, bound = energy_range(tmp_path, soft_scene(16, "nearest", 0.4), "nearest")
    assert highest > 100 * bound, (highest, bound)


@pytest.mark.parametrize("case", ["P2 resting", "P1 sliding", "P1 rolling off the edge"])
def test_blended_gap_gains_no_energy_on_p2_faces_sliding_and_at_the_rim(tmp_path, case):
    """P2 (4 cells; the blend acts on the mirrored flat sub-triangles, whose vertices are all FE nodes): the nearest
    gap gained +14.6 J in 1 s.  A sphere sliding at 0.5 m/s across the dimpling 8-cell block (its dimple travels
    with it), and one rolling off the top's rim (the blend's facet planes are cut at the patch's boundary edges;
    uncut, it gained +37 J there): no gain beyond the Verlet bound (measured: sliding -3.2e-4 .. +5e-13 J, rim
    -3.0e-3 .. +1e-4 J, the loss where the sphere leaves the rim)."""
    if case == "P2 resting":
        scene = soft_scene(4, "blended", 0.2, element="P2")
    else:
        scene = soft_scene(8, "blended", 0.6)
        start, velocity = ((0.3, [0.5, 0.0, 0.0]) if case == "P1 sliding" else (0.8, [1.0, 0.3, 0.0]))
        scene["particles"][0]["insert"]["positions"][0][0] = start
        scene["particles"][0]["insert"]["velocities"] = [velocity]
    lowest, highest, bound = energy_range(tmp_path, scene, "run")
    assert highest <= bound, (case, lowest, highest, bound)
    if case != "P1 rolling off the edge":
        assert lowest >= -bound, (case, lowest, highest, bound)


def test_blended_gap_restarts_bit_identically(tmp_path):
    """A sphere sliding with friction and damping across the soft block's triangles: a restart from the
    checkpoint at step 150 continues exactly (the blend keeps no state of its own)."""
    from mpi_cases import restart_scenes

    def run(restart=None):
        scene = soft_scene(8, "blended", 300 * 2e-4, restitution=0.5)
        scene["interactions"]["default"]["friction"] = 0.3
        scene["particles"][0]["insert"]["velocities"] = [[3.0, 0.8, 0.0]]
        scene["checkpoint"] = {"every": 150 * 2e-4, "keep": 5}
        scene["output"] = {"every": 150 * 2e-4}
        sim = Simulation.from_dict(scene, base_dir=tmp_path, output_dir=str(tmp_path), restart=restart)
        sim.run(progress=False)
        return restart_scenes.gather_state(sim)

    uninterrupted = run()
    restarted = run(restart=tmp_path / "checkpoints" / f"checkpoint_{150:012d}.h5")
    for key in uninterrupted:
        assert np.array_equal(uninterrupted[key], restarted[key]), key


def test_check_names_the_blended_gap_and_drops_the_energy_warning_with_it(tmp_path):
    """Past the point-load limit check warns with either transfer; with nearest it names the energy growth and
    the blended gap as a fix, with blended only the accuracy (the surface's indentation under the contact)."""
    import yaml

    from pdemfem.cli import check_report

    for transfer in ("nearest", "blended", "auto"):
        path = tmp_path / f"{transfer}.yaml"
        path.write_text(yaml.safe_dump(soft_scene(32, transfer, 1.0)))
        _, warnings = check_report(str(path))
        point_load = [w for w in warnings if "stiffer than the surface under it" in w]
        assert len(point_load) == 1, (transfer, warnings)
        assert ("energy then grows" in point_load[0]) == (transfer == "nearest")
        assert ("Set coupling.transfer: auto or blended" in point_load[0]) == (transfer == "nearest")
        assert ("auto chose it" in point_load[0]) == (transfer == "auto")


def test_auto_transfer_blends_only_the_solids_a_point_load_dimples(tmp_path):
    """coupling.transfer auto (the default): the soft block past the point-load limit gets the blended gap,
    a steel block of the same mesh keeps the nearest-point gap."""
    for modulus, blended in ((1.0e6, True), (2.0e10, False)):
        scene = soft_scene(16, "auto", 1e-3)
        scene["materials"]["steel"]["youngs_modulus"] = modulus
        sim = Simulation.from_dict(scene, output_dir=tmp_path / f"{modulus:g}")
        assert sim.coupled_surfaces[0].triangle_surface.blended is blended


def test_blended_contact_spring_balance_reaches_its_own_particle(tmp_path):
    """The blended contact's normal spring over the FE sub-steps (share rows, coupling/dampers.py) is balanced on the
    particle that touches: a bead touching a P2 plate (2 sub-steps per DEM step) next to a bead still in the air,
    the airborne bead moves bit-identically to the same bead alone.  (The share rows carried the id of the particle
    at the contact's *record* index: the touching bead's spring impulse went to the airborne one, and on 2 ranks to
    another particle than on 1: the solid's contact forces depended on the rank count by ~4e-7.)"""
    def airborne(positions, name):
        scene = {
            "time": {"end": 0.01, "dt": 8.9e-6},
            "gravity": [0.0, 0.0, -9.81],
            "materials": {"glass": {"density": 2500, "youngs_modulus": 1.0e7, "poisson_ratio": 0.3},
                          "alu": {"density": 2700, "youngs_modulus": 7.0e8, "poisson_ratio": 0.33}},
            "interactions": {"default": {"model": "hertz_mindlin", "restitution": 0.3, "friction": 0.5}},
            "particles": [{"name": "beads", "material": "glass", "radius": 0.005,
                           "insert": {"kind": "list", "positions": positions,
                                      "velocities": [[0.0, 0.0, -0.5]] * len(positions)}}],
            "solids": [{"name": "plate", "mesh": {"box": [[0, 0, 0], [0.2, 0.2, 0.02]], "cells": [6, 6, 1]},
                        "material": "alu", "element": "P2", "mass": "lumped", "damping": {"alpha": 500.0, "beta": 0.0},
                        "fixed": ["xmin", "xmax"], "contact": ["zmax"]}],
            "coupling": {"fem_every": 1, "transfer": "blended"},
        }
        sim = Simulation.from_dict(scene, output_dir=str(tmp_path / name))
        sim.step(250)
        assert sim.coupling.fem_substeps["plate"] > 1  # the springs act only over several sub-steps
        particles = sim.particles
        return sim.contact_count(), particles.velocities[particles.ids == 0][0]

    contacts, together = airborne([[0.07, 0.1, 0.035], [0.13, 0.1, 0.0258]], "both")
    assert contacts == 1  # bead 1 rests on the plate, bead 0 (id 0) falls
    _, alone = airborne([[0.07, 0.1, 0.035]], "alone")
    assert np.array_equal(together, alone), together - alone
