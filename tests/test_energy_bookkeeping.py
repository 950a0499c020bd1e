"""The dissipated energy the contact kernels book equals the energy the contacts take out of the particles.

Two spheres (r = 1 mm, soft glass) collide head on at 5 m/s with dt auto; after they separate the booked
`dissipated_energy` must equal the kinetic energy lost.  Velocity Verlet gives a contact force the mean of
the half-step velocities around it, so the dashpot work is booked at that mean (the half-step rate alone
over-booked by 5 % (Hertz) and 36 % (linear) at e = 1e-4).  What remains is the integration error of the
elastic energy over the contact, (omega dt)^2 ~ (pi dt / t_c)^2 of the impact energy (measured: 1.7e-7 to
1.8e-3 here).
"""
import math

import pytest

from pdemfem import Simulation
from pdemfem.scene import derived


@pytest.mark.parametrize("model", ["hertz_mindlin", "linear_spring_dashpot"])
@pytest.mark.parametrize("restitution", [1e-4, 0.2, 0.5])
def test_booked_dissipation_equals_the_energy_lost(tmp_path, model, restitution):
    scene = {"time": {"end": 0.0005, "dt": "auto"}, "gravity": [0, 0, 0],
             "materials": {"glass": {"density": 2500, "youngs_modulus": 5e6, "poisson_ratio": 0.3}},
             "interactions": {"default": {"model": model, "restitution": restitution, "friction": 0.5}},
             "particles": [{"name": "pair", "material": "glass", "radius": 0.001,
                            "insert": {"kind": "list", "positions": [[0, 0, 0], [0.0021, 0, 0]],
                                       "velocities": [[2.5, 0, 0], [-2.5, 0, 0]]}}]}
    sim = Simulation.from_dict(scene, output_dir=str(tmp_path))
    start = sim.energies()
    kinetic = start["kinetic_energy"] + start["rotational_energy"]
    sim.step(int(round(scene["time"]["end"] / sim.dt)))
    end = sim.energies()
    # Apart again, or (e = 1e-4) still touching nearly at rest: the contact's elastic energy is not lost.
    lost = kinetic - end["kinetic_energy"] - end["rotational_energy"] - end["elastic_energy"]
    duration = derived.contact_duration(sim.scene, 5.0).particle_particle
    bound = (math.pi * sim.dt / duration) ** 2 * kinetic
    assert abs(end["dissipated_energy"] - lost) <= bound, (end["dissipated_energy"], lost, bound)


@pytest.mark.parametrize("partner", ["wall", "sphere"])
def test_an_oblique_frictional_impact_books_the_tangential_work_velocity_verlet_does(tmp_path, partner):
    """A sphere (R = 2 mm, soft glass) hits a plane or a resting sphere at 1 m/s, 45 degrees, e = 0.99,
    friction 1: it slides, sticks and rolls off.  The tangential work was booked from the new spring force at
    the new stiffness and with the new levers: the books' total rose by 0.64 % (wall) and 0.34 % (sphere) of
    the impact energy at dt auto, halving with dt.  Booked as the trapezoid of the two applied forces, each on
    the contact velocity of its own geometry, the total keeps the impact energy to velocity Verlet's own error
    over a contact resolved in >= 30 steps, (pi / 30)^2 / 8 = 1.4e-3 (measured 1.2e-4 and 1.4e-5)."""
    radius, speed = 0.002, 1.0
    velocity = [speed * math.sin(math.pi / 4), 0.0, -speed * math.cos(math.pi / 4)]
    if partner == "wall":
        insert = {"kind": "list", "positions": [[0, 0, 1.01 * radius]], "velocities": [velocity]}
        walls = [{"name": "floor", "kind": "plane", "point": [0, 0, 0], "normal": [0, 0, 1], "material": "glass"}]
    else:
        insert = {"kind": "list", "positions": [[0, 0, 0], [0, 0, 2.02 * radius]], "velocities": [[0, 0, 0], velocity]}
        walls = []
    scene = {"time": {"end": 1.0, "dt": "auto"}, "gravity": [0, 0, 0],
             "materials": {"glass": {"density": 2500, "youngs_modulus": 5e6, "poisson_ratio": 0.3}},
             "interactions": {"default": {"model": "hertz_mindlin", "restitution": 0.99, "friction": 1.0}},
             "particles": [{"name": "ball", "material": "glass", "radius": radius, "insert": insert}],
             "walls": walls, "output": {"every": 1.0, "particles": []}}
    sim = Simulation.from_dict(scene, output_dir=str(tmp_path))
    start = sim.total_energy()
    sim.step(int(4e-3 / sim.dt))  # the ~1 ms contact and well apart again
    assert sim.contact_count() == 0
    assert abs(sim.total_energy() - start) <= (math.pi / 30) ** 2 / 8 * start, (sim.total_energy() - start) / start


@pytest.mark.parametrize("rolling_model", ["elastic_plastic", "constant_torque"])
def test_an_oblique_impact_with_rolling_resistance_books_the_rolling_work_velocity_verlet_does(tmp_path,
                                                                                               rolling_model):
    """The impact above on the plane, with rolling resistance mu_r = 0.5.  The rolling moment's work was booked
    from the new moment alone: the books' total rose by 0.55 % (elastic_plastic) and fell by 0.38 %
    (constant_torque) of the impact energy at dt auto, halving with dt.  Booked as the trapezoid of the moment
    applied at the previous evaluation and the new one (a moment's power M . w needs no older geometry), the
    total keeps the impact energy to velocity Verlet's own error, (pi / 30)^2 / 8 = 1.4e-3 as above (measured
    -9.4e-5 and -6.8e-5)."""
    radius, speed = 0.002, 1.0
    velocity = [speed * math.sin(math.pi / 4), 0.0, -speed * math.cos(math.pi / 4)]
    scene = {"time": {"end": 1.0, "dt": "auto"}, "gravity": [0, 0, 0],
             "materials": {"glass": {"density": 2500, "youngs_modulus": 5e6, "poisson_ratio": 0.3}},
             "interactions": {"default": {"model": "hertz_mindlin", "restitution": 0.99, "friction": 1.0,
                                          "rolling_friction": 0.5, "rolling_model": rolling_model}},
             "particles": [{"name": "ball", "material": "glass", "radius": radius,
                            "insert": {"kind": "list", "positions": [[0, 0, 1.01 * radius]],
                                       "velocities": [velocity]}}],
             "walls": [{"name": "floor", "kind": "plane", "point": [0, 0, 0], "normal": [0, 0, 1],
                        "material": "glass"}],
             "output": {"every": 1.0, "particles": []}}
    sim = Simulation.from_dict(scene, output_dir=str(tmp_path))
    start = sim.total_energy()
    sim.step(int(4e-3 / sim.dt))
    assert sim.contact_count() == 0
    # The rolling moment took a large share of the energy, so the books have something to get wrong: 0.51 of
    # the impact energy is dissipated, against 0.15 without rolling resistance.
    assert sim.energies()["dissipated_energy"] > 0.3 * start
    assert abs(sim.total_energy() - start) <= (math.pi / 30) ** 2 / 8 * start, (sim.total_energy() - start) / start
