"""The coupled step: DEM step, counter-forces to the FE nodes, FE advance, surface update.

Order per DEM step (DESIGN 1.3): the particle system integrates the particles
and computes every contact, including those with the mirrored FE surfaces at
their current positions; the counter-forces are spread onto FE nodes; the solid
advances; the mirrored vertices move to the new nodal positions.

Time levels: the DEM force F^{n+1} acts on the particles through the two half
kicks around t^{n+1} (impulse F dt), and on the solid through the central
difference step t^{n+1} -> t^{n+2} (impulse F dt): the impulses match, so the
total momentum of particles plus solid is conserved to round-off.

Sub-cycling knobs:
- fem_every = k: the solid advances every k DEM steps over k dt with the mean
  (impulse-preserving) load of those steps; cheaper FE, surface k steps stale.
- when the FE critical step is below the DEM step, Solid.advance covers each
  interval with the fewest equal stable sub-steps.
"""
from __future__ import annotations


class CouplingDriver:
    def __init__(self, solids: dict, surfaces: list, dt: float, fem_every: int = 1):
        self.solids = solids
        self.surfaces = surfaces
        self.dt = float(dt)
        self.fem_every = int(fem_every)
        self.steps_since_advance = 0
        self.fem_substeps = {name: 1 for name in solids}

    def after_particle_step(self) -> None:
        """Collective: collect counter-forces, and every fem_every steps advance the solids."""
        for surface in self.surfaces:
            surface.collect_contact_forces()
        self.steps_since_advance += 1
        if self.steps_since_advance < self.fem_every:
            return
        interval = self.steps_since_advance * self.dt
        for surface in self.surfaces:
            # Mean load over the interval: the same impulse as the per-step loads.
            surface.send_forces_to_solid(1.0 / self.steps_since_advance)
        for name, solid in self.solids.items():
            self.fem_substeps[name] = solid.advance(interval)
        for surface in self.surfaces:
            surface.refresh_vertices()
        self.steps_since_advance = 0
