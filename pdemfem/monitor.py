"""Run-time guard: stop a diverging run, with a diagnosis, before it writes garbage to the end.

`pdemfem run` calls `DivergenceMonitor.check()` before the first step, at every output step
and at every stop check (at most every STOP_CHECK_EVERY steps), on all ranks together.  It
reads quantities reduced over the ranks (the energies of a history row and the largest speed,
from one pass; the lost-particle counts), so every rank takes the same decision.  Each test is a
statement of physics (docs/stability.md lists them):

1. Non-finite: an energy that is inf/NaN, or a particle removed because its position
   became inf/NaN.
2. Tunnelling: mesh walls and the solids' contact surfaces have no thickness; a particle
   moving more than TUNNEL_TRAVEL of the smallest radius per step relative to them can
   cross one before a contact force builds up, and one whose impact would overlap more than
   its radius passes whatever the step.
3. Runaway: a particle moving more than the smallest radius in one step misses its contacts
   (`Simulation.step` stops at once on the displacement the step computes anyway).
4. Energy created: the bookkeeping total (kinetic + rotational + potential + elastic +
   dissipated - wall work + the solids' kinetic, strain and load potential - the stream energy
   of inserted minus removed particles - the work of solids' prescribed rigid motions) is conserved
   by the equations; a stable explicit step errs by a fraction of the energy that moves.
   The run stops when the total has grown by more than all the energy the scene has had
   available since the baseline: its kinetic, rotational, elastic and solid energies at
   the baseline, the largest drop of its potentials seen since, and the work moving walls
   did.  An integration that creates more energy than the scene ever had is diverging.
5. Overlap: the contact laws are small-overlap laws.  The pair, plane-wall and triangle-surface kernels
   keep the deepest overlap they met (as a fraction of the smaller radius) since the last check; past 1
   for two spheres their centres can cross and they pass through each other: the run stops.  Past
   derived.PEAK_OVERLAP_WARNING (any of the three) the run warns once.  A solid whose cell turned
   inside out (deformed volume <= 0, Solid.smallest_volume_ratio) stops the run: the small-strain
   model is past its validity there, and its surface no longer bounds it.
6. Thermal step (heat on): the explicit temperature update is stable and overshoot-free while
   dt sum(H) / (m c) <= 1 for every particle (pdemfem.particles.heat); past that the run stops.
   Heat content is not part of the energy test (it is conserved on its own, see docs/heat.md).
7. Energy given back by the dashpots: dashpots and friction only dissipate, so the mechanical
   energy (the total without dissipated_energy) can only grow by what the scene had available
   (test 4's figure).  An explicit dashpot with c dt / m* past its limit overshoots: the motion
   gains energy and the contact books the same amount as negative dissipation, which cancels it
   in the total, so test 4 cannot see it.  The run stops when the mechanical energy has grown by
   more than all the energy available while dissipated_energy fell (below its highest value since
   the baseline, beyond round-off).  The fall alone is no evidence: the dashpot's work is booked at
   the half-step velocities of an isolated contact, and where other forces set the velocity change
   (a contact held by a weight, creeping in) the booked dissipation falls, even below zero, by up to
   ~c dt / (2 m*) of the energy released, i.e. up to about all of it at the dashpot limit (measured:
   a sphere settling on a floor, docs/stability.md), while the motion gains nothing.  Sticking springs
   and the FE surface dashpots' correction of the booked dissipation lower it a little too.

Scenes whose bookkeeping cannot be closed skip tests 4 and 7 (logged once): gravity along a
periodic axis (a wrapped particle's potential jumps by m g L).  The work of a solid's prescribed
groups is booked (support_work) and subtracted like a moving wall's.
"""
from __future__ import annotations

import logging
import math

from pdemfem.errors import SolverError
from pdemfem.scene import derived

log = logging.getLogger("pdemfem")

# The bookkeeping total is a sum of O(particles) terms accumulated over up to ~1e7 steps: its
# round-off is below ~1e7 * 2.2e-16 = 2e-9 of the magnitudes summed; 1e-8 is above that.
ROUND_OFF = 1e-8

_POTENTIALS = ("potential_energy", "solid_load_potential")


def _potential(energies: dict) -> float:
    """Energy that can turn into motion when it falls: gravity's and the loads' potentials, and the
    negative part of the contacts' elastic energy (adhesive contacts pull the bodies together)."""
    return sum(energies.get(name, 0.0) for name in _POTENTIALS) + min(energies.get("elastic_energy", 0.0), 0.0)
_STORED = ("kinetic_energy", "rotational_energy", "elastic_energy", "solid_kinetic_energy", "solid_strain_energy")


def total_energy(energies: dict) -> float:
    """The bookkeeping total of Simulation.total_energy, from an energies() dict."""
    return (energies["kinetic_energy"] + energies["rotational_energy"] + energies["potential_energy"]
            + energies["elastic_energy"] + energies["dissipated_energy"] - energies["wall_work"]
            + energies.get("solid_kinetic_energy", 0.0) + energies.get("solid_strain_energy", 0.0)
            + energies.get("solid_load_potential", 0.0) - energies.get("thermoelastic_work", 0.0)
            - energies.get("stream_energy", 0.0) - energies.get("frame_work", 0.0)
            - energies.get("support_work", 0.0) + energies.get("lost_energy", 0.0))


# Heat content (m c T, relative to 0 K) is orders of magnitude above the mechanical energies and
# conserved on its own: it neither enters the bookkeeping total nor its round-off floor.
THERMAL_ENERGIES = ("thermal_energy", "particle_thermal_energy")


def _mechanical_magnitude(energies: dict) -> float:
    return sum(abs(value) for name, value in energies.items() if name not in THERMAL_ENERGIES)


class DivergenceMonitor:
    """Collective checks of a running Simulation; `check()` raises SolverError (exit 3) on divergence."""

    def __init__(self, simulation):
        self.sim = simulation
        scene = simulation.scene
        self.thin_surfaces = ([wall.name for wall in scene.walls if wall.kind == "mesh"]
                              + [solid.name for solid in scene.solids if solid.contact])
        radii = simulation.particle_system.state.radii[:simulation.particle_system.state.owned_count]
        local = float(radii.min()) if len(radii) else math.inf
        self.smallest_radius = simulation.comm.allreduce(local, op=_min_op())
        from pdemfem.particles.stream import stream_radius_range

        streamed = stream_radius_range(scene)  # the particles streams insert later
        if streamed is not None:
            self.smallest_radius = min(self.smallest_radius, streamed[0])
        self.wall_speed = max((derived._wall_speed(wall) for wall in scene.walls), default=0.0)
        self.energy_check_skipped = self._energy_check_skipped()
        # A particle that moves more than the smallest radius in one step passes through others
        # unseen.  `Simulation.step` stops at once when one has moved more than r_min + skin/2 since
        # the list build: the list is rebuilt whenever a particle passes skin/2, so that much means
        # more than r_min in the last step alone.  It reads the displacement the step computes anyway
        # (no cost), and stops a runaway before its coordinates overflow the neighbour search.
        if math.isfinite(self.smallest_radius):
            simulation.runaway_displacement = self.smallest_radius + 0.5 * simulation.particle_system.skin
        self.baseline = None
        self.checks = 0
        self.overlap_warned = False
        self.dissipation_fell = False  # set by test 7: the diagnosis then names the dashpot

    # ------------------------------------------------------------------ setup
    def _energy_check_skipped(self):
        """Why the energy test cannot apply to this scene, or None."""
        scene = self.sim.scene
        for axis in scene.domain.periodic:
            if scene.gravity["xyz".index(axis)] != 0.0:
                return f"gravity has a component along the periodic axis {axis}"
        return None

    def start(self) -> None:
        """Collective: take the baseline (the state `run` starts from, fresh or restarted) and check it.

        The elastic energy of the starting overlaps is available energy like any other: the scene's
        validation refuses a particle deeper than START_OVERLAP_TOLERANCE (0.05) of its radius in a wall, a solid or
        another particle (pdemfem.scene.inputs), so what is left is a state the user meant, e.g. a packing
        resting at its static overlaps, which then stays at rest."""
        self._take_baseline(self.sim.energies())
        if self.energy_check_skipped is not None and self.sim.comm.rank == 0:
            log.info("run monitor: no energy test (%s); the other tests apply", self.energy_check_skipped)
        self.check()

    def _take_baseline(self, energies: dict) -> None:
        system = self.sim.particle_system
        self.baseline = {
            "total": total_energy(energies),
            "stored": sum(max(energies.get(name, 0.0), 0.0) for name in _STORED),
            "potential": _potential(energies),
            "wall_work": energies["wall_work"],
            "thermoelastic_work": energies.get("thermoelastic_work", 0.0),
            "frame_work": energies.get("frame_work", 0.0),
            "support_work": energies.get("support_work", 0.0),
            "stream_energy": energies.get("stream_energy", 0.0),
            "lost": system.lost_particles,
            "step": self.sim.step_count,
            "magnitude": _mechanical_magnitude(energies),
            "dissipated": energies["dissipated_energy"],
        }
        self.baseline["mechanical"] = self.baseline["total"] - self.baseline["dissipated"]
        self.lowest_potential = self.baseline["potential"]
        self.highest_dissipated = self.baseline["dissipated"]

    # ------------------------------------------------------------------ the check
    def check(self) -> None:
        """Collective: raise SolverError naming what diverged and the likely causes."""
        self.checks += 1
        sim, system = self.sim, self.sim.particle_system
        energies = sim.energies()
        problem = None
        if not all(math.isfinite(value) for value in energies.values()):
            bad = [name for name, value in energies.items() if not math.isfinite(value)]
            problem = f"the simulation diverged: non-finite energies ({', '.join(bad)})"
        elif system.nonfinite_particles:
            problem = (f"the simulation diverged: {system.nonfinite_particles} particle(s) reached an infinite or NaN "
                       f"position and were removed")
        fastest = system.fastest_speed  # from the energies() pass above
        travel = (fastest + self.wall_speed) * sim.dt
        if problem is None and self.thin_surfaces and travel > derived.TUNNEL_TRAVEL * self.smallest_radius:
            problem = (f"tunnelling: a particle moved at {fastest:.3g} m/s, {travel / self.smallest_radius:.2f} "
                       f"radii per step relative to the thin surfaces {', '.join(self.thin_surfaces)} (want <= "
                       f"{derived.TUNNEL_TRAVEL}): it can pass through them (tunnelling)")
        if problem is None and self.thin_surfaces and math.isfinite(fastest):
            deepest = max(derived.thin_surface_overlaps(sim.scene, fastest + self.wall_speed), default=None)
            if deepest is not None and deepest[0] > 1.0:
                problem = (f"tunnelling: a particle moved at {fastest:.3g} m/s: an impact of {deepest[1]} at that "
                           f"speed overlaps {deepest[0]:.2g} radii, so it passes through the thin surfaces "
                           f"{', '.join(self.thin_surfaces)} (tunnelling)")
        if problem is None and (fastest * sim.dt > self.smallest_radius
                                or system.largest_displacement > sim.runaway_displacement):
            problem = (f"{'the simulation diverged: ' if sim.step_count > self.baseline['step'] else ''}"
                       f"a particle moved at {fastest:.3g} m/s, "
                       f"{fastest * sim.dt / self.smallest_radius:.3g} radii in one step (more than the smallest "
                       f"radius: contacts are missed)")
        # Collective on every rank at every check (it resets the kernels' records).
        overlap_problem = self._overlap_problem()
        # Before any other finding: an unstable temperature update is what turns the temperatures (and then the
        # energies) non-finite.
        if system.heat and system.largest_heat_step_ratio > 1.0:
            raise SolverError(
                f"run stopped at step {sim.step_count} (t = {sim.time:.6g} s)",
                f"the temperature update is unstable: dt sum(H) / (m c) reached {system.largest_heat_step_ratio:.3g} "
                f"on a particle (it must stay <= 1: its contacts' conductance H moves more heat per step than it "
                f"holds)",
                "lower time.dt, or raise the particles' heat_capacity (or lower their conductivity); "
                "`pdemfem check` estimates the thermal step limit (docs/heat.md)")
        # Collective on every rank, the solids in the scene's order.
        for index, (name, solid) in enumerate(sim.solids.items()):
            smallest, inverted = solid.smallest_volume_ratio()
            if problem is None and inverted:
                raise SolverError(
                    f"run stopped at step {sim.step_count} (t = {sim.time:.6g} s)",
                    f"solid '{name}': {inverted} cell(s) turned inside out (the smallest deformed/undeformed volume "
                    f"{smallest:.3g}): the solid's displacements reach its cells' size, where the small-strain "
                    f"model no longer holds and the solid's surface can let particles through",
                    f"the solid is far too soft for its loads: check solids[{index}]'s material youngs_modulus "
                    f"(in Pa), its supports (fixed:) and loads (gravity, tractions, the particles on it); past "
                    f"the point-load limit that `pdemfem check` warns about use coupling.transfer: auto or "
                    f"blended")
        if problem is None and self.energy_check_skipped is None:
            problem = self._energy_problem(energies)
        if problem is None:
            problem = overlap_problem
        if problem is None:
            return
        raise SolverError(f"run stopped at step {sim.step_count} (t = {sim.time:.6g} s)",
                          problem, self.diagnosis(fastest))

    def _overlap_problem(self):
        """Collective: the deepest overlaps since the last check (one Allreduce MAX); stop past the smaller
        radius between two spheres, warn once past PEAK_OVERLAP_WARNING."""
        from mpi4py import MPI

        system = self.sim.particle_system
        deepest = system.deepest_overlaps.copy()
        system.deepest_overlaps[:] = 0.0
        if self.sim.comm.size > 1:
            self.sim.comm.Allreduce(MPI.IN_PLACE, deepest, op=MPI.MAX)
        pair, wall = float(deepest[0]), float(max(deepest[1], deepest[2]))
        if pair > 1.0:
            return (f"two particles overlapped by {pair:.3g} of the smaller radius: their centres can cross, and "
                    f"they pass through each other (the contact is far too soft for the speeds)")
        if max(pair, wall) > derived.PEAK_OVERLAP_WARNING and not self.overlap_warned:
            self.overlap_warned = True
            if self.sim.comm.rank == 0:
                where = ("two particles" if pair >= wall else
                         "a particle and a plane wall" if deepest[1] >= deepest[2] else
                         "a particle and a triangle surface (a mesh wall or a solid's contact surface)")
                log.warning("by step %d %s overlapped by %.3g of the smaller radius (want <= %g): the contact law "
                            "is a small-overlap law; use stiffer materials (youngs_modulus, normal_stiffness) or "
                            "lower the speeds (`pdemfem check` estimates the overlap at the impact speed)",
                            self.sim.step_count, where, max(pair, wall), derived.PEAK_OVERLAP_WARNING)
        return None

    def _energy_problem(self, energies: dict):
        system = self.sim.particle_system
        if system.lost_particles != self.baseline["lost"]:
            # Removed particles take their energy out of the bookkeeping: restart the comparison.
            self._take_baseline(energies)
            return None
        baseline = self.baseline
        potential = _potential(energies)
        self.lowest_potential = min(self.lowest_potential, potential)
        available = (baseline["stored"] + (baseline["potential"] - self.lowest_potential)
                     + abs(energies["wall_work"] - baseline["wall_work"])
                     + abs(energies.get("thermoelastic_work", 0.0) - baseline["thermoelastic_work"])
                     + abs(energies.get("frame_work", 0.0) - baseline["frame_work"])
                     + abs(energies.get("support_work", 0.0) - baseline["support_work"])
                     + abs(energies.get("stream_energy", 0.0) - baseline["stream_energy"]))
        created = total_energy(energies) - baseline["total"]
        floor = ROUND_OFF * max(baseline["magnitude"], _mechanical_magnitude(energies))
        if created > available + floor:
            return (f"the simulation diverged: the energy total grew by {created:.3g} J, more than the "
                    f"{available:.3g} J of kinetic, elastic and potential energy and wall work the scene had "
                    f"available since step {baseline['step']}")
        # Test 7: energy given back by the dashpots.  The mechanical energy (total minus dissipated) cannot grow by
        # more than what was available unless the dissipated energy fell: a stable step errs by a fraction of the
        # energy that moves, so growth past all of it (the bound of test 4) is divergence, and the fall (beyond
        # the round-off floor) names the dashpots.  The fall itself is not compared: healthy resting contacts
        # book falls up to ~all the energy they release (see the module docstring).
        dissipated = energies["dissipated_energy"]
        self.highest_dissipated = max(self.highest_dissipated, dissipated)
        fallen = self.highest_dissipated - dissipated
        grown = (total_energy(energies) - dissipated) - baseline["mechanical"]
        if fallen > floor and grown > available + floor:
            self.dissipation_fell = True
            return (f"the simulation diverged: the mechanical energy (kinetic, rotational, potential, elastic, the "
                    f"solids') grew by {grown:.3g} J, more than the {available:.3g} J of kinetic, elastic and potential "
                    f"energy and wall work the scene had available since step {baseline['step']}, while the dissipated "
                    f"energy fell by {fallen:.3g} J (to {dissipated:.3g} J): dashpots and friction can only dissipate, "
                    f"so a contact dashpot gave energy back to the motion (an unstable explicit dashpot)")
        return None

    # ------------------------------------------------------------------ diagnosis
    def diagnosis(self, fastest: float) -> str:
        """The likely causes, from the scene and the step, as the error's fix line."""
        causes = likely_causes(self.sim.scene, self.sim.dt, fastest, self.smallest_radius, self.thin_surfaces)
        if self.dissipation_fell and not any(cause.startswith("the restitution is too small") for cause in causes):
            # The scene's pairs at the expected and the fastest speed pass the dashpot limit, yet a dashpot gave
            # energy back: a contact the estimate does not cover (a slower, stiffer or lighter one).
            none_known = causes[-1].startswith("none of the known limits")
            causes = ([] if none_known else causes) + [
                "a contact dashpot is unstable at this step (c dt / m* past its limit: the explicit dashpot "
                "overshoots and gives energy back); lower time.dt (or use dt: auto), or raise the restitution"]
        coupled = list(getattr(self.sim, "coupling_warnings", []))
        if coupled and causes[-1].startswith("none of the known limits"):
            causes = coupled
        else:
            causes += coupled
        return "likely cause: " + "; ".join(causes)


def likely_causes(scene, dt: float, fastest: float, smallest_radius: float, thin_surfaces) -> list:
    """Plain-language causes of a divergence that the scene and the step show, each with its fix."""
    causes = []
    rayleigh = derived.rayleigh_time(scene)
    if rayleigh is not None and dt > derived.RAYLEIGH_LIMIT * rayleigh:
        causes.append(f"dt = {dt:.3g} s is {dt / rayleigh:.2f} x the Rayleigh time {rayleigh:.3g} s, above the "
                      f"elastic wave limit {derived.RAYLEIGH_LIMIT} (use dt: auto)")
    speed = max(derived.expected_impact_speed(scene), fastest if math.isfinite(fastest) else 0.0)
    resolvable = speed < math.inf and rayleigh is not None
    for limit, why in derived.contact_step_limits(scene, speed) if resolvable else []:
        if dt > limit:
            if why.startswith("dashpot"):
                causes.append(f"the restitution is too small for the step: the {why} needs dt <= {limit:.3g} s "
                              f"(use dt: auto, or raise the restitution)")
            else:
                causes.append(f"dt is above the contact limit: {why} needs dt <= {limit:.3g} s (use dt: auto)")
    if thin_surfaces and math.isfinite(fastest) and fastest * dt > derived.TUNNEL_TRAVEL * smallest_radius:
        causes.append(f"tunnelling through {', '.join(thin_surfaces)}: at {fastest:.3g} m/s a particle moves "
                      f"{fastest * dt / smallest_radius:.2f} radii per step (lower dt, or set "
                      f"time.expected_impact_speed to the real impact speed with dt: auto)")
    # The overlaps at the faster of the measured and the expected speed: a diverged run's own speeds may be
    # NaN, and check's warning for the expected impact speed names the same cause.
    overlap_speed = speed if math.isfinite(speed) else None
    if overlap_speed:
        for ratio, label in derived.thin_surface_overlaps(scene, overlap_speed):
            if ratio > 1.0:
                causes.append(f"tunnelling: {label} at {overlap_speed:.3g} m/s overlaps {ratio:.2g} radii (the "
                              f"material is too soft for that speed: raise youngs_modulus or lower the speed)")
        for ratio, kind, label, _ in derived.contact_overlaps(scene, overlap_speed):
            if ratio > 1.0 and kind == "particle_particle":
                causes.append(f"contacts {label} at {overlap_speed:.3g} m/s overlap {ratio:.2g} of the smaller radius "
                              f"(the material is too soft for that speed: raise youngs_modulus or lower the speed)")
    thermal = derived.thermal_step_limit(scene)
    if thermal is not None and dt > thermal[0]:
        causes.append(f"dt = {dt:.3g} s is {dt / thermal[0]:.3g} x the estimated thermal step limit {thermal[0]:.3g} s "
                      f"of group '{thermal[1]}' (explicit conduction: temperatures overshoot and blow up); raise "
                      f"heat_capacity, lower conductivity or dt (docs/heat.md)")
    causes.extend(derived.start_inside_walls(scene))
    if not math.isfinite(fastest):
        causes.append("a particle has an infinite or NaN velocity (check the initial velocities)")
    if not causes:
        causes.append("none of the known limits is exceeded at the expected impact speed: lower time.dt or "
                      "time.dt_factor, set time.expected_impact_speed, and check the run with `pdemfem check`")
    return list(dict.fromkeys(causes))  # one line per cause, however many walls share it


def _min_op():
    from mpi4py import MPI

    return MPI.MIN
