"""`pdemfem check` lines for coupled scenes: the DEM step, each solid's FE critical step, the sub-cycling,
and the coupled scheme's stability figures (docs/stability.md, docs/coupling.md)."""
from __future__ import annotations

import math

import numpy as np

# Above this, the contact's held elastic force could overshoot an unsupported surface node within one
# interval (central difference of the contact spring on the node's mass: S_n h^2 / m <= 4).
HELD_FORCE_LIMIT = 1.0
# dt auto on a yielding surface takes this fraction of the interval HELD_FORCE_LIMIT allows (the margin dt auto
# keeps to the dashpot's stability limit too): at the limit itself the surface node is marginally stable.
HELD_FORCE_MARGIN = 0.5
# The contact springs over the FE sub-steps act on a window of several DEM steps (fem_every > 1) while the window
# is within this fraction of the interval HELD_FORCE_LIMIT allows (pdemfem.coupling.dampers; measured in
# docs/coupling.md, "Contact springs over the FE sub-steps").
WINDOW_SPRING_SHARE = 0.5
# Above this, one contact displaces the surface as much as the solid resists it (S_n vs E l): the surface
# then follows the contact force within the interval and the held force lags it.
SURFACE_COMPLIANCE_LIMIT = 0.1
# Above this, one contact deforms the surface under it more than the overlap (S_n / (E l) ~ the surface
# displacement per unit overlap under the point load on one triangle's nodes).  Measured on a heavy sphere
# resting on a clamped block (docs/coupling.md): 0.63 conserves energy, 0.77 gains 1.5 J in 2 s at e = 1,
# 2.5 gains 56 J in 1 s, 5 diverges.
POINT_LOAD_LIMIT = 0.5


def build_solids(scene, base_dir, comm=None) -> dict:
    """The scene's solids by name (mesh, operators; no static solve): collective on `comm` (default COMM_SELF)."""
    from mpi4py import MPI

    from pdemfem.fem.solid import Solid

    comm = comm if comm is not None else MPI.COMM_SELF
    return {config.name: Solid(config, scene.materials[config.material], gravity=scene.gravity, comm=comm,
                               base_dir=base_dir) for config in scene.solids}


def held_force_step_limit(scene, solids: dict) -> tuple:
    """(the longest interval fem_every x dt the held contact force allows over all yielding solid surfaces [s],
    the solid that sets it); (inf, None) when no surface yields to its contacts.  dt auto takes
    HELD_FORCE_MARGIN of it."""
    limits = {}
    for config in scene.solids:
        if config.contact and scene.particles:
            _contact_figures(scene, config, solids[config.name], 1.0, None, limits)
    if not limits:
        return math.inf, None
    name = min(limits, key=limits.get)
    return limits[name], name


# A damping that shrinks the FE step by more than this is named by `check` (its cost is that factor in FE sub-steps).
DAMPING_STEP_SHRINK = 2.0


def coupling_report(scene, base_dir, dt: float, comm=None, warnings=None, solids=None) -> list:
    """Lines naming, per solid, the FE critical step, how the coupling covers a DEM step and the contact's
    stiffness and damping against the surface nodes; appends stability warnings to `warnings`.

    Builds each solid unless `solids` (build_solids) are given: collective on `comm` (default COMM_SELF)."""
    if not scene.solids:
        return []
    solids = solids if solids is not None else build_solids(scene, base_dir, comm)
    k = scene.coupling.fem_every
    interval = k * dt
    lines = [f"coupling: DEM dt = {dt:.3g} s; fem_every = {k}: the solids advance every {k} DEM step(s) "
             f"over {interval:.3g} s with the mean contact load"]
    for index, config in enumerate(scene.solids):
        solid = solids[config.name]
        critical = solid.critical_time_step()
        substeps = solid.substeps(interval)
        lines.append(f"solid {config.name}: {3 * solid.n_global_nodes} DOF ({config.element}, {config.mass} mass), "
                     f"FE critical step {critical:.3g} s = {critical / dt:.3g} x DEM dt -> {substeps} FE sub-step(s) "
                     f"of {interval / substeps:.3g} s per advance; contact groups {list(config.contact)}")
        if warnings is not None:
            warnings.extend(_damping_cost(index, config, solid, substeps))
        if config.contact and scene.particles:
            lines.extend(_contact_figures(scene, config, solid, interval, warnings))
            if warnings is not None:
                warnings.extend(_facing_away(index, config, solid, scene))
    return lines


def _damping_cost(index: int, config, solid, substeps: int) -> list:
    """A warning when the solid's Rayleigh damping shrinks its FE critical step by more than DAMPING_STEP_SHRINK.
    Stiffness-proportional damping (beta) damps a mode of frequency omega at beta omega / 2 of critical, so
    the mesh's highest mode, which sets the explicit step, is overdamped long before the modes that matter."""
    from pdemfem.fem.stability import critical_step

    omega = solid.largest_frequency_bound()
    undamped = critical_step(omega, 0.0, 0.0)
    critical = solid.critical_time_step()
    if not critical * DAMPING_STEP_SHRINK < undamped:
        return []
    return [f"solids[{index}] ({config.name}): damping (alpha {solid.damping_alpha:g}, beta {solid.damping_beta:g}) "
            f"shrinks the FE critical step {undamped / critical:.3g}x, from {undamped:.3g} s to {critical:.3g} s "
            f"({substeps} FE sub-steps per advance): beta damps the mesh's highest mode (omega_max {omega:.3g} rad/s) "
            f"at {solid.damping_beta * omega / 2.0:.3g} x critical; beta <= 1/omega_max = {1.0 / omega:.3g} s keeps "
            f"at least 0.62 of the undamped step, and alpha (mass-proportional) damps the low modes at no cost in "
            f"step (docs/fem.md, 'Damping')"]


def blended_transfer(scene, solid_name: str, point_loaded: set) -> bool:
    """Whether a solid's contact surface uses the blended gap: coupling.transfer blended, or auto and the
    surface yields to a point load (`point_loaded`: the solids past POINT_LOAD_LIMIT)."""
    transfer = scene.coupling.transfer
    return transfer == "blended" or (transfer == "auto" and solid_name in point_loaded)


def _contact_figures(scene, config, solid, interval: float, warnings, limits=None, point_loaded=None) -> list:
    """Per solid: the stiffest particle contact (impact or resting under its weight) against the lightest
    surface node and the surface element size; appends the warnings; adds the solid's name to
    `point_loaded` when the contact is stiffer than the surface under it (S_n/(E l) > POINT_LOAD_LIMIT)."""
    from pdemfem.contact.restitution import normal_damping_coefficient
    from pdemfem.scene import derived

    from mpi4py import MPI

    surface = solid.contact_surface()
    indices, positions, _ = solid.surface_state()  # collective: every rank gets all surface nodes
    start, end = solid.global_node_range
    owned = (indices >= start) & (indices < end)
    masses = solid.lumped_mass.getArray(readonly=True).reshape(-1, 3)[np.asarray(indices[owned]) - start, 0]
    node_mass = solid.comm.allreduce(float(masses.min()) if len(masses) else math.inf, op=MPI.MIN)
    triangles = np.asarray(surface.triangles)
    edges = np.linalg.norm(positions[triangles] - positions[np.roll(triangles, 1, axis=1)], axis=2)
    element_size = float(np.median(edges))
    speed = max(derived.expected_impact_speed(scene), 1e-3)
    gravity = math.sqrt(sum(component * component for component in scene.gravity))
    solid_material = scene.materials[config.material]
    worst = None
    for group in scene.particles:
        material = scene.materials[group.material]
        _, radius = derived.group_radius_range(group)
        mass = derived._mass(material, radius)
        # The E* the contact law uses: without the solid's compliance with coupling.contact_modulus particle.
        solid_term = None if scene.coupling.contact_modulus == "particle" else solid_material
        modulus = derived._effective_modulus(material, solid_term)
        # The deeper of the impact's peak overlap and the overlap of the particle resting under its weight.
        impact = derived._peak_overlap(mass, radius, modulus, speed)
        resting = (mass * gravity / (4.0 / 3.0 * modulus * math.sqrt(radius))) ** (2.0 / 3.0)
        overlap = max(impact, resting)
        stiffness = 2.0 * modulus * math.sqrt(radius * overlap)
        interaction = scene.interaction(group.material, config.material)
        dashpot = normal_damping_coefficient(interaction.model, interaction.restitution) * math.sqrt(mass * stiffness)
        compliance = stiffness / (solid_material.youngs_modulus * element_size)
        if worst is None or compliance > worst[2]:
            worst = (stiffness * interval**2 / (4.0 * node_mass), dashpot * interval / node_mass, compliance,
                     group.name, stiffness)
    held, damping_ratio, compliance, name, stiffness = worst
    lines = [f"solid {config.name}: contact vs surface (group {name}, at {speed:.3g} m/s or resting, lightest node "
             f"{node_mass:.3g} kg, element {element_size:.3g} m): held force S_n h^2/(4 m) = {held:.3g} "
             f"(limit {HELD_FORCE_LIMIT:g}), dashpot c h / m = {damping_ratio:.3g} (implicit on the nodes: any value), "
             f"surface compliance S_n/(E l) = {compliance:.3g} (limit {POINT_LOAD_LIMIT:g})"]
    held_limit = (2.0 * math.sqrt(HELD_FORCE_LIMIT * node_mass / stiffness)
                  if compliance > SURFACE_COMPLIANCE_LIMIT else math.inf)
    if limits is not None:
        limits[config.name] = held_limit
    if warnings is None:
        return lines
    if compliance > POINT_LOAD_LIMIT and point_loaded is not None:
        point_loaded.add(config.name)
    if compliance > POINT_LOAD_LIMIT:
        coarsest = stiffness / (POINT_LOAD_LIMIT * solid_material.youngs_modulus)
        # With the blended gap the dimpled surface no longer feeds energy in (docs/coupling.md): the
        # surface's indentation under the contact then limits the contact's accuracy, not the run's stability.
        if scene.coupling.transfer == "nearest":
            consequence = ("its force reaches the solid as a point load on one triangle's nodes, which a mesh this "
                           "fine does not resolve; the coupled energy then grows with refinement (docs/coupling.md). "
                           " Set coupling.transfer: auto or blended, or use")
        else:
            chosen = " (coupling.transfer auto chose it)" if scene.coupling.transfer == "auto" else ""
            consequence = (f"run uses the blended gap for this solid{chosen}, which keeps the energy bounded; the "
                           f"surface's indentation under the contact adds to its compliance (docs/coupling.md).  "
                           f"For accuracy use")
        warnings.append(
            f"solid {config.name}: a contact of group {name} is stiffer than the surface under it "
            f"(S_n/(E l) = {compliance:.3g} > {POINT_LOAD_LIMIT:g}): {consequence} surface elements of at least "
            f"{coarsest:.3g} m there, or a stiffer solid material")
    if held > HELD_FORCE_LIMIT and compliance > SURFACE_COMPLIANCE_LIMIT:
        dt = interval / scene.coupling.fem_every
        action = (f"run lowers fem_every to {math.floor(held_limit / dt)}" if dt <= held_limit else
                  f"run refuses the scene: time.dt must be <= {held_limit:.3g} s")
        warnings.append(
            f"solid {config.name}: the contact force held over an interval of {interval:.3g} s can overshoot its "
            f"lightest surface node (S_n h^2/(4 m) = {held:.3g} > {HELD_FORCE_LIMIT:g}) on a surface that yields "
            f"to the contact (S_n/(E l) = {compliance:.3g} > {SURFACE_COMPLIANCE_LIMIT:g}): the interval "
            f"fem_every x dt must be <= {held_limit:.3g} s; {action}")
    return lines


def _facing_away(index: int, config, solid, scene) -> list:
    """`check` (one process, the whole surface): a warning when no triangle of the solid's contact surface faces any
    point where the particles start (a region's corners, listed positions).  Contact is one-sided, from the outside: particles that come
    from behind a contact face pass into the solid (a block's bottom listed under contact, the grains above it
    fell through the block and rested inside it, with no warning)."""
    from pdemfem.scene.derived import _group_points

    points = np.array([point for group in scene.particles for point in _group_points(group)], dtype=float)
    if not len(points):
        return []
    # The corners of the box around them: a few points however many particles are listed.
    low, high = points.min(axis=0), points.max(axis=0)
    starts = np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1]) for z in (low[2], high[2])])
    nodes, positions, _ = solid.surface_state()
    triangles = np.searchsorted(nodes, solid.surface_triangles())
    if len(positions) != len(nodes) or (triangles.size and triangles.max() >= len(positions)):
        return []  # a rank holding part of the surface only (check under mpiexec): the check is check's, serial
    a, b, c = positions[triangles[:, 0]], positions[triangles[:, 1]], positions[triangles[:, 2]]
    normals = np.cross(b - a, c - a)  # outward, |n| = twice the area
    sides = np.einsum("tj,ptj->pt", normals, starts[:, None, :] - ((a + b + c) / 3.0)[None, :, :])
    if np.any(sides > 0.0):
        return []
    return [f"solids[{index}] ({config.name}): no face of its contact surface ({', '.join(config.contact)}) faces "
            f"where the particles start (every outward normal points away from them); contact is one-sided, from "
            f"outside, so particles reaching it pass into the solid: list the faces they land on under "
            f"solids[{index}].contact"]


def coupling_assessment(scene, solids: dict, dt: float) -> tuple:
    """Collective, for already built solids (run): (the coupled-stability warnings of `pdemfem check`,
    the longest interval fem_every x dt the held contact force allows over all solids [s], the names of
    the solids whose surface yields to a point load (coupling.transfer auto blends their gap))."""
    found = []
    limits = {}
    point_loaded = set()
    interval = scene.coupling.fem_every * dt
    for index, config in enumerate(scene.solids):
        solid = solids[config.name]
        found.extend(_damping_cost(index, config, solid, solid.substeps(interval)))
        if config.contact and scene.particles:
            _contact_figures(scene, config, solid, interval, found, limits, point_loaded)
    return found, min(limits.values(), default=math.inf), point_loaded
