"""Balance of a settled pile on a clamped elastic plate, and exact force/moment transfer to the FE nodes.

* Every step (P1 and P2): the force the particles exert on the mirrored surface (the contact kernel's
  totals, which are minus the particle-side force) equals the sum of the nodal counter-forces the
  coupling spreads onto the FE nodes, and so does the moment about a point, to round-off.
* Settled pile (P1): the plate's support reaction minus its own weight (from the static start), averaged
  over the last 500 steps, equals the particles' weight within 0.5 %.
"""
import numpy as np
import pytest

from mpi_cases.coupling_scenes import pile_on_plate
from pdemfem import Simulation
from pdemfem.coupling.surface import CoupledSurface

EPS = np.finfo(float).eps
SUPPORTS = ("xmin", "xmax")
ABOUT = np.array([0.03, -0.05, 0.2])  # any point: the moment check must not depend on the origin


class TransferRecorder:
    """Wraps CoupledSurface.collect_contact_forces: after each call compares the nodal counter-forces
    with the contact kernel's totals (force on the surface and its moment about ABOUT)."""

    def __init__(self, monkeypatch):
        self.worst_force = 0.0
        self.worst_moment = 0.0
        self.steps_with_contacts = 0
        original = CoupledSurface.collect_contact_forces
        recorder = self

        def wrapped(surface, *args, **kwargs):
            original(surface, *args, **kwargs)
            recorder.check(surface)

        monkeypatch.setattr(CoupledSurface, "collect_contact_forces", wrapped)

    def check(self, surface):
        contacts = surface.triangle_surface.contacts
        if len(contacts.triangle) == 0:
            return
        self.steps_with_contacts += 1
        vertices = surface.triangle_surface.vertices  # the positions the contacts were computed with
        nodal_force = surface.node_forces.sum(axis=0)
        nodal_moment = np.cross(vertices - ABOUT, surface.node_forces).sum(axis=0)
        wall = surface.triangle_surface
        force, moment = wall.force, wall.torque(ABOUT)
        magnitudes = np.linalg.norm(contacts.force, axis=1)
        # Round-off: each nodal term is a product of a weight (<= 1) and a force; summing n terms in
        # either order errs by <= n eps sum|F| (force), and n eps sum |F| |x - ABOUT| (moment).
        terms = 6 * len(magnitudes) + len(surface.node_forces)
        lever = np.max(np.linalg.norm(vertices - ABOUT, axis=1))
        force_tolerance = terms * EPS * magnitudes.sum() + np.finfo(float).tiny
        moment_tolerance = terms * EPS * magnitudes.sum() * lever + np.finfo(float).tiny
        self.worst_force = max(self.worst_force, np.max(np.abs(nodal_force - force)) / force_tolerance)
        self.worst_moment = max(self.worst_moment, np.max(np.abs(nodal_moment - moment)) / moment_tolerance)


def particle_weight(sim) -> float:
    state = sim.particle_system.state
    return float(np.sum(state.mass[:state.owned_count])) * 9.81


def support_reaction(sim) -> np.ndarray:
    return sum(sim.solid_reaction("plate", group) for group in SUPPORTS)


@pytest.mark.parametrize("element, steps", [("P1", 2500), ("P2", 1500)])
def test_counter_forces_preserve_force_and_moment_every_step(monkeypatch, tmp_path, element, steps):
    recorder = TransferRecorder(monkeypatch)
    scene = pile_on_plate(element=element, count=120)
    # The nearest point's barycentric spreading (on P2 faces over the flat sub-triangle), not the blended gap.
    scene.setdefault("coupling", {})["transfer"] = "nearest"
    sim = Simulation.from_dict(scene, output_dir=str(tmp_path))
    sim.step(steps)  # the grains land (first contacts after ~1000 steps) and pile up
    assert recorder.steps_with_contacts > steps // 3
    print(f"{element}: worst |nodal - kernel| / tolerance: force {recorder.worst_force:.3g}, "
          f"moment {recorder.worst_moment:.3g}")
    assert recorder.worst_force <= 1.0, recorder.worst_force
    assert recorder.worst_moment <= 1.0, recorder.worst_moment


def test_settled_pile_reaction_equals_particle_weight(monkeypatch, tmp_path):
    recorder = TransferRecorder(monkeypatch)
    sim = Simulation.from_dict(pile_on_plate(element="P1", count=200), output_dir=str(tmp_path))
    # The static start carries the plate's own weight: subtract it (the supports see weight + grains).
    own = support_reaction(sim)
    weight = particle_weight(sim)
    # Static solve to rtol 1e-10: K sums to zero over a translation, so reaction - plate weight = -sum of the
    # residual's free z rows, |.| <= sqrt(n) |r| <= 1e-10 sqrt(n) |b| ~ 1e-10 W for near-uniform nodal loads
    # (|b| ~ W / sqrt(n)); 1e-9 leaves a factor 10 for the nodal weights' spread.  Measured 1.0e-13.
    assert abs(abs(own[2]) - 2700 * 0.2 * 0.2 * 0.02 * 9.81) <= 1e-9 * abs(own[2])
    # 0.52 s: the grains fall ~4 cm, pile up and settle (kinetic energy < 1e-6 J; the last grain to arrive may
    # still tumble on top at 0.42 s: 1.2e-5 J, 0.08 m/s, and 1.1e-6 J at 0.5 s; 4.6e-8 J at 0.54 s)
    sim.step(13000)
    # Settled, the pile still rings on its contacts (period ~2 ms): the instantaneous reaction swings by
    # -0.4 % .. +0.3 % of the weight over the last 500 steps (measured; up to 2.5 % 1500 steps earlier), its
    # deviation being the grains' sum m a_z.  Averaged over those 500 steps (0.02 s, ~10 periods) the swings
    # cancel: window means within 1.2e-3 of the weight over the last 2000 steps (measured).  0.5 % allowed.
    window, reaction, surface = 500, np.zeros(3), 0.0
    for _ in range(window):
        sim.step()
        reaction += (support_reaction(sim) - own) / window
        surface += -sim.wall_force("plate")[2] / window
    kinetic = sim.energies()["kinetic_energy"]
    print(f"settled pile: kinetic {kinetic:.3g} J, mean reaction {reaction[2]:.6g} N, weight {weight:.6g} N, "
          f"relative {(reaction[2] - weight) / weight:+.3g}")
    assert kinetic < 1e-6
    assert abs(reaction[2] - weight) <= 5e-3 * weight, (reaction, weight)   # sign: supports push up
    # The frictionless side walls carry no vertical force, so the plate's surface force is the weight too.
    assert abs(surface - weight) <= 5e-3 * weight
    assert recorder.worst_force <= 1.0 and recorder.worst_moment <= 1.0
