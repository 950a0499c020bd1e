"""A heavy sphere resting on a clamped elastic block: the coupled scheme's long-rest stability case.

Sphere R = 0.2 m (density 1e4, E = 1e7, nu = 0.2) placed at rest at its Hertz rest overlap on the top of a
1 x 1 x 0.5 m steel block (E = 2e10, nu = 0.29, density 7850) clamped at its base, meshed n x n x n/2.
The contact is much stiffer in damping than the surface nodes are heavy (c dt / m_node >> 1 at fine
meshes), the case where a dashpot held over the FE sub-steps pumped energy into the block.

Used by tests/test_coupling_stability.py (a sampled map) and benchmarks/coupled_stability.py (the full map).
"""
from __future__ import annotations

import math
import time

import numpy as np

from mpi_cases.coupling_scenes import BALL, BALL_RADIUS, BLOCK_STEEL, ball_on_block, effective_modulus, sphere_mass

GRAVITY = 9.81
TOP = 0.5


def rest_overlap() -> float:
    """Hertz overlap of the sphere resting under its weight: m g = 4/3 E* sqrt(R) delta^(3/2)."""
    mass = sphere_mass(BALL_RADIUS, BALL["density"])
    return (mass * GRAVITY / (4.0 / 3.0 * effective_modulus(BALL, BLOCK_STEEL) * math.sqrt(BALL_RADIUS))) ** (2.0 / 3.0)


def contact_period() -> float:
    """Period 2 pi / omega of the resting contact, omega^2 = S_n / m, S_n = 2 E* sqrt(R delta)."""
    mass = sphere_mass(BALL_RADIUS, BALL["density"])
    stiffness = 2.0 * effective_modulus(BALL, BLOCK_STEEL) * math.sqrt(BALL_RADIUS * rest_overlap())
    return 2.0 * math.pi * math.sqrt(mass / stiffness)


def energy_scale() -> float:
    """m g delta: the resting contact's energy scale [J]."""
    return sphere_mass(BALL_RADIUS, BALL["density"]) * GRAVITY * rest_overlap()


def verlet_energy_bound(dt: float) -> float:
    """Velocity Verlet's energy error on the resting contact's oscillation, (omega_c dt)^2 / 4 of m g delta."""
    return (2.0 * math.pi / contact_period() * dt) ** 2 / 4.0 * energy_scale()


def resting_scene(cells: int, element="P1", mass="lumped", restitution=0.2, friction=0.0, dt=2e-4, fem_every=1,
                  end=1.0, offset=(0.013, 0.007)) -> dict:
    """The sphere at rest at its Hertz overlap, centre `offset` from the top's centre (off the mesh nodes)."""
    delta = rest_overlap()
    scene = ball_on_block(element=element, dt=dt, fem_every=fem_every, restitution=restitution,
                          cells=(cells, cells, max(1, cells // 2)), end=end, mass=mass, height=TOP + BALL_RADIUS - delta)
    scene["interactions"]["default"]["friction"] = friction
    scene["particles"][0]["insert"]["positions"] = [[0.5 + offset[0], 0.5 + offset[1], TOP + BALL_RADIUS - delta]]
    return scene


def run_resting(scene: dict, output_dir: str, samples: int = 10) -> dict:
    """Run the scene to time.end, sampling `samples` times: total energy (particles + solid + dissipated),
    largest nodal speed, the sphere's overlap / Hertz rest overlap.  Returns the series and figures."""
    from pdemfem import Simulation

    sim = Simulation.from_dict(scene, output_dir=output_dir)
    block = sim.solids["block"]
    top = TOP + float(block.displacements[block.group_node_numbers("zmax")][:, 2].max())
    delta = rest_overlap()
    total_steps = int(round(scene["time"]["end"] / sim.dt))
    energy0 = sim.total_energy()
    energies, speeds, overlaps, times = [], [], [], []
    started = time.perf_counter()
    done = 0
    for sample in range(1, samples + 1):
        target = total_steps * sample // samples
        sim.step(target - done)
        done = target
        energies.append(sim.total_energy() - energy0)
        speeds.append(float(np.abs(block.velocities).max()))
        overlaps.append((BALL_RADIUS - (float(sim.particles.positions[0, 2]) - top)) / delta)
        times.append(sim.time)
    return {"times": times, "energy_change": energies, "largest_nodal_speed": speeds, "overlap_ratio": overlaps,
            "energy_scale": energy_scale(),
            "substeps": int(sim.coupling.fem_substeps["block"]), "dt": sim.dt,
            "wall_seconds": time.perf_counter() - started}


class LevelEnergy:
    """Mechanical energy of a coupled run (lumped-mass solids) at the particles' time level.

    The solid runs one step ahead (coupling/driver.py): after the step to t^{n+1} it holds u^{n+2}, v^{n+3/2},
    so sim.energies() adds its energies a step late or early and, while the sphere and the block exchange
    energy, swings by ~dt x the exchanged power.  Here the solid's part is the central-difference invariant at
    t^{n+1}: 1/2 v^{n+1/2} M v^{n+3/2} + 1/2 u^{n+1} K u^{n+1} - b . u^{n+1} (u^{n+1}, v^{n+1/2} kept from the
    previous call, so call `update` after every step, and take the reference after the first step: at t^0 the
    velocity before the prime is gone), the particles' part is sim.energies()' own.  Exact only
    when the solid takes one FE step per DEM step (with sub-steps the invariant pairs the velocities of adjacent
    sub-steps, which this does not see)."""

    def __init__(self, sim):
        self.sim = sim
        self.previous = {name: self._state(solid) for name, solid in sim.solids.items()}

    @staticmethod
    def _state(solid):
        return (solid.displacement_vec.getArray(readonly=True).copy(), solid.velocity_vec.getArray(readonly=True).copy())

    def update(self) -> float:
        energies = self.sim.energies()
        total = sum(energies[k] for k in ("kinetic_energy", "rotational_energy", "potential_energy", "elastic_energy"))
        for name, solid in self.sim.solids.items():
            u_previous, v_previous = self.previous[name]
            u, v = self._state(solid)
            mass = solid.lumped_mass.getArray(readonly=True)
            x = solid.displacement_vec.duplicate()
            x.setArray(u_previous)
            y = x.duplicate()
            solid.stiffness.mult(x, y)
            total += (0.5 * float(np.dot(v_previous * mass, v)) + 0.5 * y.dot(x) - solid.constant_load_vec.dot(x))
            self.previous[name] = (u, v)
        return total
