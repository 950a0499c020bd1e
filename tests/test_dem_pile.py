"""Verification: a settled pile carries its weight on the floor; energy bookkeeping.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from mpi_cases.dem_scenes import GLASS, STEEL, box_walls, dense_scene
from pdemfem import Simulation
from pdemfem.scene import derived
from pdemfem.scene.loader import load_scene

G = 9.81


def _pile_scene(model):
    """200 glass spheres settling from a jittered lattice (4 layers) in a 16 x 16 mm box.

    The side walls are frictionless (interaction glass-side, friction 0), so they push
    only horizontally and cannot carry weight (no Janssen effect): in equilibrium the
    floor's vertical force is exactly the weight.  The floor has friction (without it
    the bottom layer never stops sliding).  e = 0.1 settles in a few bounces; rolling
    friction 0.1 stops the slow rolling rearrangements that otherwise go on for long.
    """
    lx = ly = 16.0e-3
    walls = box_walls((lx, ly), 40e-3, material="floor", side_material="side")
    # dt = 0.2 Rayleigh times (~14 steps per contact): the floor force does not need the restitution
    # to 1 %, which dt auto would buy at e = 0.1 with ~300 steps per contact (20 x the cost).
    rayleigh = math.pi * 1.0e-3 * math.sqrt(GLASS["density"] * 2.0 * (1.0 + GLASS["poisson_ratio"])
                                             / GLASS["youngs_modulus"]) / (0.1631 * GLASS["poisson_ratio"] + 0.8766)
    return {
        "time": {"end": 1.0, "dt": 0.2 * rayleigh},
        "gravity": [0.0, 0.0, -G],
        "materials": {"glass": dict(GLASS), "floor": dict(STEEL), "side": dict(STEEL)},
        "interactions": {"default": {"model": model, "restitution": 0.1, "friction": 0.5, "rolling_friction": 0.1},
                         "glass-side": {"model": model, "restitution": 0.1, "friction": 0.0}},
        "particles": [{"name": "grains", "material": "glass", "radius": 1.0e-3,
                       "insert": {"kind": "lattice", "region": {"box": [[0, 0, 0], [lx, ly, 40e-3]]},
                                  "count": 200, "seed": 1, "jitter": 0.5, "spacing": 2.3e-3}}],
        "walls": walls,
    }


@pytest.mark.parametrize("model", ["hertz_mindlin", "linear_spring_dashpot"])
def test_settled_pile_floor_force(model):
    """Time-averaged floor force = weight within 0.1 %, with a rigorous bound on the residual.

    Momentum balance of all particles (side walls frictionless and vertical): velocity Verlet
    advances the momentum by the trapezoidal rule, P_z(n+1) = P_z(n) + dt ((R_n + R_n+1) / 2 - W)
    with R_n the floor's vertical force after step n, so over a window of N steps (T = N dt) the
    mean of R_1..R_N is exactly W + (P_z(N) - P_z(0)) / T + (R_N - R_0) / (2 N).  By Cauchy-Schwarz
    |P_z| = |sum m v_z| <= sqrt(2 M E_kin) at any instant, hence
    |<R> - W| <= (sqrt(2 M E_kin(0)) + sqrt(2 M E_kin(T))) / T + |R_N - R_0| / (2 N).  A settled
    pack still rings at its contact frequencies (E_kin ~ 1e-10 J here, accelerations comparable
    to g), so the instantaneous force is noisy; the average over T = 0.3 s is not.
    """
    sim = Simulation.from_dict(_pile_scene(model))
    state = sim.particle_system.state
    total_mass = float(state.mass.sum())
    weight = total_mass * G
    # Free fall over <= 10 mm (0.045 s), the bounces, and the slow rearrangements: by 0.35 s the
    # pack only rings (E_kin ~ 1e-10 J; measured at 0.15 s it is still ~1e-7 J and settling).
    sim.step(int(round(0.35 / sim.dt)))
    window = int(round(0.3 / sim.dt))

    def momentum_and_kinetic():
        state = sim.particle_system.state
        return float(np.sum(state.mass * state.velocities[:, 2])), sim.energies()["kinetic_energy"]

    momentum_before, kinetic_before = momentum_and_kinetic()
    floor_before = -sim.wall_force("floor")[2]  # the force ON the floor points down
    floor_sum = 0.0
    for _ in range(window):
        sim.step(1)
        floor_sum += -sim.wall_force("floor")[2]
    floor_after = -sim.wall_force("floor")[2]
    momentum_after, kinetic_after = momentum_and_kinetic()
    floor = floor_sum / window
    span = window * sim.dt
    end_terms = (floor_after - floor_before) / (2 * window)
    bound = (np.sqrt(2.0 * total_mass * kinetic_before) + np.sqrt(2.0 * total_mass * kinetic_after)) / span
    bound += abs(end_terms)
    identity = floor - weight - (momentum_after - momentum_before) / span - end_terms
    print(f"{model}: floor / weight - 1 = {floor / weight - 1:.3g}, bound {bound / weight:.3g}, "
          f"identity residual {identity / weight:.3g} of the weight")
    # The identity holds to the round-off of summing the N floor forces (each ~W): <= N eps W
    # (4e-12 for N = 17333; measured 5e-15, rounding errors of random sign grow only as sqrt(N)).
    assert abs(identity) <= window * np.finfo(float).eps * weight
    # The bound is rigorous (measured |<R> - W| 1.2e-5 and 4.1e-5 of W against 3.4e-4 and 8.5e-4: the
    # particles' momenta have random signs, so |P_z| is far below sqrt(2 M E_kin)) ...
    assert abs(floor - weight) <= bound + window * np.finfo(float).eps * weight
    # ... and the requirement is 0.1 % of the weight.
    assert abs(floor / weight - 1.0) < 1e-3
    # Side walls carry no weight: their normals are exactly horizontal and they are frictionless, so the
    # z component of every contact force on them is exactly zero.
    for name in ("x0", "x1", "y0", "y1"):
        assert sim.wall_force(name)[2] == 0.0, (name, sim.wall_force(name))


def _total(energies):
    return (energies["kinetic_energy"] + energies["rotational_energy"] + energies["potential_energy"]
            + energies["elastic_energy"] + energies["dissipated_energy"] - energies["wall_work"])


def _bookkeeping_error(scene, duration):
    """(worst |total - start|, dissipated energy at the end, sim, largest elastic energy) over 10 samples."""
    sim = Simulation.from_dict(scene)
    start = _total(sim.energies())
    worst, elastic = 0.0, 0.0
    steps = int(round(duration / sim.dt))
    for _ in range(10):
        sim.step(steps // 10)
        energies = sim.energies()
        worst = max(worst, abs(_total(energies) - start))
        elastic = max(elastic, energies["elastic_energy"])
    return worst, sim.energies()["dissipated_energy"], sim, elastic


@pytest.mark.parametrize("model", ["hertz_mindlin", "linear_spring_dashpot"])
def test_energy_bookkeeping(model):
    """kinetic + rotational + potential + elastic + dissipated - wall work is conserved.

    The booked dissipation is a one-sided quadrature of the damping/friction power
    (force at step n+1 times the half-step velocity), while the kinetic energy of
    velocity Verlet changes by the trapezoidal work; the two differ by O(dt / t_c) of
    the dissipated energy D (measured ~ 0.75 dt/t_c for one damped impact).  So:
      (a) |error| <= pi (dt / t_c) D at the scene's dt, t_c the shortest contact
          duration the scene expects (pdemfem.scene.derived at its impact speed);
      (b) the error converges: halving dt divides it by 2 (the dashpots' one-sided quadrature,
          first order) to 4 (the tangential spring's work, booked by the trapezoid of its
          forces at the step's two ends, is second order while it sticks; the linear law's
          pile measured 3.7 since, Hertz ~2).  A term missing from the bookkeeping would not
          vanish with dt (ratio ~ 1): before the fix of the spring energy it stayed at ~13 % of D.
    """
    duration = 0.06  # the fall and the first ~10 collisions of every particle
    scene = dense_scene(model=model)
    scene_model, _ = load_scene(scene)
    dt = derived.time_step(scene_model)
    contact_time = derived.contact_duration(scene_model, derived.expected_impact_speed(scene_model)).shortest
    error, dissipated, sim, _ = _bookkeeping_error(scene, duration)
    assert dissipated > 0.3 * _total(sim.energies()) * 0.5  # a scene that really dissipates
    assert error < np.pi * dt / contact_time * dissipated, (error, dissipated, dt / contact_time)
    half_error, half_dissipated, _, _ = _bookkeeping_error(dense_scene(model=model, dt=dt / 2), duration)
    ratio = (error / dissipated) / (half_error / half_dissipated)
    assert 1.5 < ratio < 4.5, ratio  # 2 (first order) to 4 (second order), +- 0.5


def test_energy_conserved_without_dissipation():
    """e = 1, mu = 0: nothing dissipates; velocity Verlet conserves a shadow energy, so the total
    oscillates by O((dt/t_c)^2) of the energy held in the contacts and does not drift.

    For a contact of frequency omega the total differs from the conserved shadow energy by
    (omega dt)^2 / 4 times the contact's elastic energy; a Hertz contact is stiffest at its peak
    overlap, omega_max = 1.369 v0 / delta_max = 4.03 / t_c (t_c = 2.94 delta_max / v0).  Contacts
    that have ended leave a residual of the same order (the Hertz force's x^1.5 onset is not
    smooth), so the bound is (omega_max dt)^2 / 4 of the largest elastic energy of the run, not of
    the total: most of the energy is the fall's, never held in a contact at once (the former bound,
    (pi dt / t_c)^2 of the total, was 300x the error).  Measured 0.28 of the bound (error 1.2e-7 J,
    elastic energy up to 1.3e-5 J at the samples, (omega_max dt)^2 / 4 = 0.033).
    """
    scene = dense_scene(restitution=1.0, friction=0.0)
    scene_model, _ = load_scene(scene)
    dt = derived.time_step(scene_model)
    contact_time = derived.contact_duration(scene_model, derived.expected_impact_speed(scene_model)).shortest
    error, dissipated, _, elastic = _bookkeeping_error(scene, 0.06)
    assert dissipated == 0.0
    assert elastic > 0.0  # the grains collided
    bound = (4.03 * dt / contact_time) ** 2 / 4 * elastic
    print(f"energy error {error:.3g} J, largest elastic energy {elastic:.3g} J, bound {bound:.3g} J "
          f"({error / bound:.2f} of it)")
    assert error < bound
