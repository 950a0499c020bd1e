"""coupling.transfer: where a particle-solid contact acts on a surface that dimples under it.

A heavy sphere (R = 0.2 m, 335 kg) rests on a soft clamped block (E = 1e6 Pa, 16 x 16 x 8 cells): the contact
is 2.5 times stiffer than the surface under it (S_n/(E l), the point-load limit is 0.5), the point load dents
the surface and the sphere sits in a dimple of the mesh's faces.  Restitution 1, no friction: nothing
dissipates, so the mechanical energy must stay within velocity Verlet's oscillation on the resting contact,
(omega_c dt)^2 / 4 of m g delta (stability_cases.verlet_energy_bound).  The energy is taken at the particles'
time level (stability_cases.LevelEnergy): sim.energies() adds the solid's energies one step ahead, which
swings by ~dt x the exchanged power (+-0.5 J here) without any gain.

* nearest: the nearest triangle switches between the dimple's faces and its normal jumps by 15-28 degrees;
  the energy grew by +26.6 J in 0.4 s (measured), 5e4 times the bound.
* anchored: the contact keeps the triangle, barycentric weights and normal of its first touch; its gap
  n0 . (p - sum w0_k x_k) is linear in the particle and node positions, so the force field is the gradient of
  the contact's potential and the coupled scheme is a symplectic one on a smooth potential.  Measured:
  -2.1e-4 .. +2.2e-5 J over 1 s (bound 4.8e-4 J), and the same on 4, 8 and 32 cells.
"""
import numpy as np
import pytest

from stability_cases import LevelEnergy, resting_scene, verlet_energy_bound
from pdemfem import Simulation


def energy_excursion(tmp_path, transfer, cells=16, end=0.4, element="P1"):
    scene = resting_scene(cells, restitution=1.0, end=end, element=element)
    scene["materials"]["steel"]["youngs_modulus"] = 1e6
    scene["coupling"]["transfer"] = transfer
    sim = Simulation.from_dict(scene, output_dir=str(tmp_path / transfer))
    assert sim.coupling.fem_substeps["block"] == 1  # LevelEnergy is the scheme's exact invariant only then
    level = LevelEnergy(sim)
    start = level.update()
    excursion = 0.0
    for _ in range(int(round(end / sim.dt))):
        sim.step()
        excursion = max(excursion, abs(level.update() - start))
    return excursion, verlet_energy_bound(sim.dt)


def test_anchored_contact_keeps_the_energy_of_a_sphere_resting_in_its_dimple(tmp_path):
    excursion, bound = energy_excursion(tmp_path, "anchored")
    assert excursion <= bound, (excursion, bound)
    # The nearest-point contact on the same surface gains energy: what the anchor removes.
    excursion, bound = energy_excursion(tmp_path, "nearest")
    assert excursion > 100 * bound, (excursion, bound)


def test_anchored_contact_on_p2_faces_spreads_by_the_flat_triangles_weights(tmp_path):
    """P2 faces are mirrored as four flat triangles and the anchored gap is measured on them; its force goes to
    their three nodes by the same weights (the gap's exact derivative).  Spread by the parent face's quadratic
    shape functions instead, the same run swung by -3.4 J within 0.2 s (measured, 4 cells: S_n/(E l) = 0.63,
    no FE sub-steps, so the level energy is the scheme's exact invariant)."""
    excursion, bound = energy_excursion(tmp_path, "anchored", cells=4, end=0.2, element="P2")
    assert excursion <= bound, (excursion, bound)


def test_anchored_contact_restarts_bit_identically(tmp_path):
    """A sphere sliding with friction across the soft block's triangles: anchors are set, carried and
    refreshed (the foot leaves its triangle); a restart from the checkpoint at step 150 continues exactly."""
    from mpi_cases import restart_scenes

    def run(restart=None):
        scene = resting_scene(8, restitution=0.5, friction=0.3, end=300 * 2e-4)
        scene["materials"]["steel"]["youngs_modulus"] = 1e6
        scene["coupling"]["transfer"] = "anchored"
        scene["particles"][0]["insert"]["velocities"] = [[3.0, 0.8, 0.0]]
        scene["checkpoint"] = {"every": 150 * 2e-4, "keep": 5}
        scene["output"] = {"every": 150 * 2e-4}
        sim = Simulation.from_dict(scene, base_dir=tmp_path, output_dir=str(tmp_path), restart=restart)
        sim.run(progress=False)
        return sim, restart_scenes.gather_state(sim)

    sim, uninterrupted = run()
    # Anchored at the end, on a triangle under the sphere's final position, not the one it started on (the
    # sphere slid ~0.19 m, 1.5 cells): the anchor was refreshed on the way.
    anchor = sim.particle_system.state.fields["wall:block:anchor"][0, 0]
    surface = next(wall for wall in sim.contributor_walls if wall.name == "block")
    centroid = surface.vertices[surface.triangles[int(anchor[0])]].mean(axis=0)
    position = sim.particle_system.state.positions[0]
    cell = 1.0 / 8
    assert anchor[0] >= 0.0 and np.hypot(*(centroid - position)[:2]) < cell
    assert np.hypot(position[0] - 0.513, position[1] - 0.507) > cell
    checkpoint = tmp_path / "checkpoints" / f"checkpoint_{150:012d}.h5"
    _, restarted = run(restart=checkpoint)
    for key in uninterrupted:
        assert np.array_equal(uninterrupted[key], restarted[key]), key


def test_check_names_the_anchored_transfer_and_drops_the_energy_warning_with_it(tmp_path):
    """Past the point-load limit check warns with either transfer; with nearest it names the energy growth and
    the anchored transfer as a fix, with anchored only the accuracy (the point load's indentation)."""
    import yaml

    from pdemfem.cli import check_report

    for transfer in ("nearest", "anchored"):
        scene = resting_scene(32, restitution=1.0)
        scene["materials"]["steel"]["youngs_modulus"] = 1e6
        scene["coupling"]["transfer"] = transfer
        path = tmp_path / f"{transfer}.yaml"
        path.write_text(yaml.safe_dump(scene))
        _, warnings = check_report(str(path))
        point_load = [w for w in warnings if "stiffer than the surface under it" in w]
        assert len(point_load) == 1, (transfer, warnings)
        assert ("energy then grows" in point_load[0]) == (transfer == "nearest")
        assert ("Set coupling.transfer: anchored" in point_load[0]) == (transfer == "nearest")
