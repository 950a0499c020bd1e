"""Quantities derived from a scene before anything is built (pure functions, no arrays).

Used by `pdemfem check`, by the simulation to pick dt, and in the docs:

    rayleigh_time(scene)              critical-step scale T_R = pi r sqrt(rho/G) / (0.1631 nu + 0.8766)
    time_step(scene)                  dt, or dt_factor * T_R when dt is "auto"
    expected_impact_speed(scene)      largest impact speed the scene should see
    hertz_contact_duration(scene, v)  shortest Hertz contact durations (particle-particle, particle-wall)
    contact_duration(scene, v)        the same for the model each pair uses (Hertz or linear spring)
    particle_count(scene), memory_estimate_bytes(scene), warnings(scene)

All in SI units.  "Smallest particle" means the smallest radius a group can have
(radius.min for a spread, min(radii) for a list).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, Optional, Tuple

import numpy as np

from pdemfem.contact.restitution import normal_damping_coefficient
from pdemfem.contact.registry import damping_law
from pdemfem.errors import SceneError
from pdemfem.scene.schema import MaterialConfig, ParticleGroupConfig, RadiusRange, Scene, WallConfig

__all__ = [
    "rayleigh_time",
    "time_step",
    "time_step_choice",
    "steps_per_contact_required",
    "damping_stable_step",
    "contact_step_limits",
    "solids_critical_step",
    "expected_impact_speed",
    "impact_speed_estimate",
    "hertz_contact_duration",
    "contact_duration",
    "ContactDurations",
    "particle_count",
    "group_counts",
    "memory_estimate_bytes",
    "bytes_per_particle",
    "sphere_count",
    "warnings",
    "DT_PER_CONTACT",
    "MAX_STEP_TRAVEL",
    "TUNNEL_TRAVEL",
    "PEAK_OVERLAP_WARNING",
]

# Hertz contact duration prefactor: t_c = 2.868 (m*^2 / (R* E*^2 v))^(1/5).
HERTZ_DURATION_FACTOR = 2.868
# A contact is resolved by at least this many steps whatever its damping (peak force and
# duration of an elastic contact to ~1 %).
DT_PER_CONTACT = 30.0
# Steps per contact for a 1 % restitution error: STEPS_PER_DAMPING * gamma_lin^1.5 (gamma_lin: the
# calibrated damping as the linear law's coefficient).  Measured: the mean error over the touch phase
# falls as 1/N; its 1 % crossing is at 72 gamma^1.5 (e = 0.1), 75 (0.2), ~80 (0.3, a wall, 24 touch phases:
# -1.005 % at 80), 64 (0.5) for the linear law and 55-61 for Hertz (docs/stability.md has the table); 90 keeps
# the largest, ~80, 12 % inside.
STEPS_PER_DAMPING = 90.0
# Below this restitution the step is that of e = 0.1: the relative error then grows, but the
# absolute error e_obtained - e stays below 1 % of 0.1 (it falls as e^(1/4) at a fixed step).
RESTITUTION_ACCURACY_FLOOR = 0.1
# dt auto keeps the step at half the dashpot stability limit at the expected impact speed: the
# limit scales as v^(-1/5) (Hertz peak stiffness), so impacts up to 2^5 = 32 x faster stay stable.
DAMPING_STABILITY_MARGIN = 0.5
# An explicit dt above this fraction of the Rayleigh time is near the elastic wave stability limit.
RAYLEIGH_LIMIT = 0.3
# Poisson ratio from which a solid counts as nearly incompressible (lambda/mu >= 9; see solid_warnings).
NEARLY_INCOMPRESSIBLE_NU = 0.45
# A particle should move at most this fraction of its radius per step at the impact speed.
MAX_STEP_TRAVEL = 0.1
# Mesh walls have no thickness: warn when a particle moves more than this fraction of its radius per
# step relative to a mesh wall (first-contact overlap up to the travel; beyond ~r the centre crosses).
TUNNEL_TRAVEL = 0.5
# The contact laws assume overlaps small beside the radii (Hertz: contact radius a = sqrt(R* delta) << R).
# Softened DEM materials reach 5-10 % of the radius at their impact speeds; beyond a quarter the contact
# has left its law's range (check warns; the run monitor warns once), and two spheres overlapping by more
# than the smaller radius can pass through each other (the run stops).
PEAK_OVERLAP_WARNING = 0.25


# --------------------------------------------------------------------------- per-group helpers


def group_radius_range(group: ParticleGroupConfig) -> Tuple[float, float]:
    """(smallest, largest) radius a group can have (a clump group: of its member spheres)."""
    if group.clump is not None:
        from pdemfem.clumps.template import clump_spheres

        radii = clump_spheres(group.clump)[1]
        return float(radii.min()), float(radii.max())
    if group.insert.kind == "list" and group.insert.radii:
        return float(min(group.insert.radii)), float(max(group.insert.radii))
    if isinstance(group.radius, RadiusRange):
        return float(group.radius.min), float(group.radius.max)
    return float(group.radius), float(group.radius)


def group_counts(scene: Scene) -> List[int]:
    """Particles each group inserts at the start, in scene order (a stream inserts later: 0)."""
    counts = []
    for group in scene.particles:
        insert = group.insert
        counts.append(len(insert.positions or ()) if insert.kind == "list"
                      else 0 if insert.kind == "stream" else int(insert.count or 0))
    return counts


def contact_counts(scene: Scene) -> List[int]:
    """How many particles of each group can take part in contacts during the run: group_counts, with a stream
    counted as the most it inserts (its `count`; 2 without one: any two of its particles may meet).  The
    time step and check's contact warnings look at every pair this admits."""
    return [(2 if group.insert.count is None else int(group.insert.count)) if group.insert.kind == "stream" else count
            for group, count in zip(scene.particles, group_counts(scene))]


def particle_count(scene: Scene) -> int:
    """Total number of particles the scene inserts."""
    return int(sum(group_counts(scene)))


def _shear_modulus(material: MaterialConfig) -> float:
    return material.youngs_modulus / (2.0 * (1.0 + material.poisson_ratio))


def _mass(material: MaterialConfig, radius: float) -> float:
    return 4.0 / 3.0 * math.pi * radius**3 * material.density


def group_reach(group: ParticleGroupConfig) -> float:
    """How far a group's particles reach from their insertion point: the largest radius, or a clump's
    bounding radius about its centre of mass."""
    if group.clump is not None:
        return clump_group_template(group, None).extent
    return group_radius_range(group)[1]


def clump_group_template(group: ParticleGroupConfig, material: Optional[MaterialConfig]):
    """The ClumpTemplate of a clump group (pdemfem.clumps.template); material None: a unit density (the
    geometry only)."""
    from pdemfem.clumps.template import clump_template

    return clump_template(group.clump, material.density if material is not None else 1.0)


def smallest_contact_mass(group: ParticleGroupConfig, material: MaterialConfig) -> float:
    """The lightest mass a contact on one of the group's particles acts on: the smallest sphere's mass;
    for clumps the smaller of the smallest member's mass share and the smallest effective mass at a
    member (pdemfem.clumps.template), so dt resolves a contact on the body as it moves."""
    if group.clump is not None:
        template = clump_group_template(group, material)
        return min(float(template.member_mass.min()), template.smallest_effective_mass)
    return _mass(material, group_radius_range(group)[0])


def _effective_modulus(a: MaterialConfig, b: Optional[MaterialConfig]) -> float:
    """1/E* = (1-nu_a^2)/E_a + (1-nu_b^2)/E_b (b None: body a's term only, as the contact tables)."""
    return 1.0 / sum((1.0 - m.poisson_ratio**2) / m.youngs_modulus for m in (a, b) if m is not None)


# --------------------------------------------------------------------------- time step


def rayleigh_time(scene: Scene) -> Optional[float]:
    """Smallest Rayleigh time over the particle groups, or None when the scene has no particles.

    T_R = pi r sqrt(rho / G) / (0.1631 nu + 0.8766), G = E / (2 (1 + nu)), with r
    each group's smallest radius.
    """
    times = []
    for group in scene.particles:
        material = scene.materials[group.material]
        radius, _ = group_radius_range(group)
        nu = material.poisson_ratio
        times.append(math.pi * radius * math.sqrt(material.density / _shear_modulus(material)) / (0.1631 * nu + 0.8766))
    return min(times) if times else None


def linear_equivalent_damping(model: str, restitution: float) -> float:
    """The calibrated damping coefficient as the linear law's gamma (Hertz: sqrt(6/5) gamma_hertz,
    docs/restitution.md identity 2): the measure of how hard the dashpot works during a contact."""
    gamma = normal_damping_coefficient(model, restitution)
    return gamma * math.sqrt(1.2) if damping_law(model) == "hertz_mindlin" else gamma


def steps_per_contact_required(model: str, restitution: float) -> float:
    """Steps per contact for the restitution to come out within 1 % (mean over where in a step the
    contact starts): max(DT_PER_CONTACT, STEPS_PER_DAMPING * gamma_lin^1.5) with gamma_lin the
    linear-equivalent calibrated damping of max(restitution, RESTITUTION_ACCURACY_FLOOR).

    The error of a resolved contact is first order in dt (the dashpot acts for a whole step at
    the first touch and the last one), so it falls as 1/N; STEPS_PER_DAMPING is the measured
    1 % crossing (docs/stability.md)."""
    gamma = linear_equivalent_damping(model, max(restitution, RESTITUTION_ACCURACY_FLOOR))
    return max(DT_PER_CONTACT, STEPS_PER_DAMPING * gamma**1.5)


def required_steps_per_contact(scene: Scene) -> float:
    """The most steps per contact any pair of the scene needs (`steps_per_contact_required`)."""
    return max((steps_per_contact_required(scene.interaction(a, b).model, scene.interaction(a, b).restitution)
                for _, a, b, *_ in _pairs(scene)), default=DT_PER_CONTACT)


def _peak_overlap(m_eff: float, r_eff: float, e_eff: float, speed: float) -> float:
    """Hertz peak overlap of an elastic impact at `speed`: (15 m* v^2 / (16 E* sqrt(R*)))^(2/5)."""
    return (15.0 * m_eff * speed**2 / (16.0 * e_eff * math.sqrt(r_eff))) ** 0.4


def _explicit_damped_limit(omega: float, beta: float) -> float:
    """Largest dt for which velocity Verlet on x'' = -omega^2 x - beta x' (damping on the
    half-step velocity, as the kernel does) does not grow: (omega dt)^2 + 2 beta dt <= 4."""
    if omega <= 0.0:
        return math.inf
    # Positive root of omega^2 dt^2 + 2 beta dt - 4 = 0, written without cancellation.
    return 4.0 / (beta + math.sqrt(beta * beta + 4.0 * omega * omega))


def damping_stable_step(scene: Scene, speed: float) -> Optional[Tuple[float, str]]:
    """(dt, pair) below which every contact's spring-dashpot stays stable at impact speed `speed`,
    with DAMPING_STABILITY_MARGIN applied; None without contact pairs.

    Per pair the contact is linearised at the Hertz peak overlap of an impact at `speed` (the
    stiffest point; linear law: its constant k).  Normal: omega^2 = S_n / m*, beta = gamma
    sqrt(S_n / m*) (the dashpot is gamma sqrt(m* S_n)).  Tangential, while friction holds the
    contact: the spring S_t and dashpot gamma sqrt(m* S_t) act on the rolling-coupled mass
    2/7 m* of two solid spheres (or a sphere on a wall).  The step must satisfy
    (omega dt)^2 + 2 beta dt <= 4 for both (`_explicit_damped_limit`).  A linear spring without a
    normal_stiffness has the one the contact tables derive from `expected_impact_speed`, whatever `speed`."""
    if speed <= 0.0:
        return None
    best = None
    characteristic = expected_impact_speed(scene)
    for kind, name_a, name_b, m_eff, r_eff, e_eff, g_eff in _pairs(scene, with_shear=True):
        interaction = scene.interaction(name_a, name_b)
        gamma = normal_damping_coefficient(interaction.model, interaction.restitution)
        delta = _peak_overlap(m_eff, r_eff, e_eff, speed)
        if interaction.model == "linear_spring_dashpot":
            if interaction.normal_stiffness:
                stiffness = interaction.normal_stiffness
            elif characteristic > 0.0:
                stiffness = m_eff * characteristic**2 / _peak_overlap(m_eff, r_eff, e_eff, characteristic)**2
            else:
                continue  # no stiffness at all: the contact tables refuse the scene
            tangential = interaction.tangential_stiffness_ratio * stiffness
        else:
            contact_radius = math.sqrt(r_eff * delta)
            stiffness = 2.0 * e_eff * contact_radius
            tangential = 8.0 * g_eff * contact_radius
        omega = math.sqrt(stiffness / m_eff)
        limit = _explicit_damped_limit(omega, gamma * omega)
        if interaction.friction > 0.0:
            rolling_mass = 2.0 / 7.0 * m_eff
            limit = min(limit, _explicit_damped_limit(math.sqrt(tangential / rolling_mass),
                                                      gamma * math.sqrt(m_eff * tangential) / rolling_mass))
        limit *= DAMPING_STABILITY_MARGIN
        if best is None or limit < best[0]:
            best = (limit, f"{name_a}-{name_b} ({interaction.model}, restitution {interaction.restitution:g})")
    return best


def settling_speed(scene: Scene) -> float:
    """sqrt(4 |g| r_min): the speed of a drop by one diameter of the smallest particle, the agitation of a
    pile settling under gravity (0 without gravity or particles).  Its impact's peak overlap is the static
    overlap under ~175 times the particle's weight: the contacts at the bottom of a resting pile are no
    stiffer than that."""
    if not scene.particles:
        return 0.0
    smallest = min(group_radius_range(group)[0] for group in scene.particles)
    return math.sqrt(4.0 * _norm(scene.gravity) * smallest)


def contact_step_limits(scene: Scene, speed: float) -> List[Tuple[float, str]]:
    """[(dt limit, why)] a contact at impact speed `speed` puts on the step: its duration over the
    steps it needs (`steps_per_contact_required`), and dashpot stability (`damping_stable_step`).  The
    dashpot must also stay stable in the contacts of particles at rest under gravity, whatever the impact
    speed (a resting sphere with e = 1e-4 chattered for ever and booked negative dissipation): its limit
    is taken at least at the `settling_speed`."""
    limits = []
    dashpot_speed = max(speed, settling_speed(scene))
    stable = damping_stable_step(scene, dashpot_speed)
    if stable is not None:
        limits.append((stable[0], f"dashpot stability of {stable[1]} at {dashpot_speed:.3g} m/s"
                                  + (" (particles settling under gravity)" if dashpot_speed > speed else "")))
    if speed <= 0.0:
        return limits
    for kind, name_a, name_b, m_eff, r_eff, e_eff in _pairs(scene):
        interaction = scene.interaction(name_a, name_b)
        duration = _pair_duration(interaction, m_eff, r_eff, e_eff, speed)
        steps = steps_per_contact_required(interaction.model, interaction.restitution)
        limits.append((duration / steps, f"{steps:.0f} steps per {kind.replace('_', '-')} contact "
                                         f"({name_a}-{name_b}, {duration:.3g} s at {speed:.3g} m/s, "
                                         f"restitution {interaction.restitution:g})"))
    return limits


def time_step_choice(scene: Scene, solid_critical_step: Optional[float] = None) -> Tuple[float, str]:
    """(dt, what set it).  time.dt when given.  "auto" with particles: the smallest of
    dt_factor x Rayleigh time and the contact limits at the expected impact speed
    (`contact_step_limits`).  "auto" without particles: the solids' FE critical step
    (`solid_critical_step`, the smallest over the solids; the FE advance sub-steps below it)."""
    if scene.time.dt != "auto":
        return float(scene.time.dt), "time.dt"
    rayleigh = rayleigh_time(scene)
    if rayleigh is None:
        if scene.solids and solid_critical_step is not None:
            return float(solid_critical_step), "the solids' FE critical step"
        raise SceneError(
            "time.dt",
            'dt "auto" derives the step from the particles or the solids, but the scene has neither'
            if not scene.solids else 'dt "auto" without particles needs the solids\' critical step',
            "give time.dt in seconds",
        )
    choices = [(scene.time.dt_factor * rayleigh,
                f"dt_factor {scene.time.dt_factor:g} x Rayleigh time {rayleigh:.3g} s")]
    speed = expected_impact_speed(scene)
    if not math.isfinite(speed):
        raise SceneError("time.dt", f'dt "auto" cannot resolve contacts at the impact speed {speed:g} m/s',
                         "check the particles' initial velocities (their squares overflow) and "
                         "time.expected_impact_speed")
    choices += contact_step_limits(scene, speed)
    dt, why = min(choices, key=lambda choice: choice[0])
    if not (dt > 0.0 and math.isfinite(dt)):
        raise SceneError("time.dt", f'dt "auto" comes out as {dt:g} s from the {why} at the impact speed {speed:g} m/s',
                         "check the particles' initial velocities and time.expected_impact_speed, or give time.dt")
    return dt, why


def time_step(scene: Scene, solid_critical_step: Optional[float] = None, base_dir=None) -> float:
    """The step: time.dt in seconds, or the "auto" step of `time_step_choice`.  A scene with
    solids and no particles needs the solids' critical step: pass it, or `base_dir` to build the
    solids here (on this process only)."""
    if (scene.time.dt == "auto" and solid_critical_step is None and not scene.particles and scene.solids):
        solid_critical_step = solids_critical_step(scene, base_dir)
    dt, why = time_step_choice(scene, solid_critical_step)
    if dt > scene.time.end:  # (an explicit time.dt above end is refused when the scene is read)
        raise SceneError("time.end", f"{scene.time.end:g} s is shorter than one step of dt auto ({dt:.3g} s, from the "
                                     f"{why}): the run could not take one step of it (it ran one whole step past the end)",
                         f"raise time.end to at least {dt:.3g} s, or give a time.dt below time.end")
    return dt


def steps_to_end(end: float, dt: float) -> int:
    """The steps a run takes to time.end: the last one may end past it by less than a step (the 1e-9: an end
    that is a whole number of steps, up to the division's round-off, takes that number)."""
    return int(math.ceil(end / dt - 1e-9))


def solids_critical_step(scene: Scene, base_dir=None) -> Optional[float]:
    """Smallest FE critical step over the scene's solids (builds them on this process only)."""
    if not scene.solids:
        return None
    from mpi4py import MPI

    from pdemfem.fem.solid import Solid

    steps = [Solid(config, scene.materials[config.material], gravity=scene.gravity, comm=MPI.COMM_SELF,
                   base_dir=base_dir if base_dir is not None else ".").critical_time_step()
             for config in scene.solids]
    return min(steps)


# --------------------------------------------------------------------------- impact speed


def _up(scene: Scene) -> Optional[Tuple[float, float, float]]:
    g = math.sqrt(sum(c * c for c in scene.gravity))
    if g == 0.0:
        return None
    return tuple(-c / g for c in scene.gravity)


def _dot(a, b) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _norm(a) -> float:
    return math.sqrt(_dot(a, a))


def _group_bottoms(group: ParticleGroupConfig, up) -> List[Tuple[float, float, float]]:
    """Lowest points (along -up) of particles at the extremes of where a group starts.

    A listed particle: its centre minus r up.  A region: the particles lie inside
    the box, so the smallest particle's centre ranges over the box shrunk by r_min;
    the corners of that box, minus r_min up, bound every particle's lowest point
    from above (top corners) and are exact at the bottom.
    """
    insert = group.insert
    if group.clump is not None:  # a clump's lowest point lies within its bounding radius of its centre
        reach = group_reach(group)
        if insert.kind == "list":
            return [tuple(c - reach * u for c, u in zip(p, up)) for p in insert.positions or ()]
        (x0, y0, z0), (x1, y1, z1) = insert.region.box
        corners = [(x, y, z) for x in (x0 + reach, x1 - reach) for y in (y0 + reach, y1 - reach)
                   for z in (z0 + reach, z1 - reach)]
        return [tuple(c - reach * u for c, u in zip(corner, up)) for corner in corners]
    if insert.kind == "list":
        smallest, _ = group_radius_range(group)
        radii = insert.radii or [group.radius if not isinstance(group.radius, RadiusRange) else smallest] * len(
            insert.positions or ())
        return [tuple(c - r * u for c, u in zip(p, up)) for p, r in zip(insert.positions or (), radii)]
    r, _ = group_radius_range(group)
    (x0, y0, z0), (x1, y1, z1) = insert.region.box
    corners = [(x, y, z) for x in (x0 + r, x1 - r) for y in (y0 + r, y1 - r) for z in (z0 + r, z1 - r)]
    return [tuple(c - r * u for c, u in zip(corner, up)) for corner in corners]


def _group_points(group: ParticleGroupConfig) -> List[Tuple[float, float, float]]:
    """Points bounding where a group's particles start: region box corners or list positions."""
    insert = group.insert
    if insert.kind == "list":
        return [tuple(p) for p in insert.positions or ()]
    (x0, y0, z0), (x1, y1, z1) = insert.region.box
    return [(x, y, z) for x in (x0, x1) for y in (y0, y1) for z in (z0, z1)]


def _initial_velocities(group: ParticleGroupConfig) -> List[Tuple[float, float, float]]:
    insert = group.insert
    if insert.kind == "list" and insert.velocities:
        return [tuple(v) for v in insert.velocities]
    return [tuple(insert.velocity)]


def _velocity_spread(velocities: List[Tuple[float, float, float]]) -> float:
    """Largest |v_i - v_j| over the initial velocities (exact for up to 2000 distinct ones,
    else the bound 2 max |v - mean|)."""
    distinct = list(dict.fromkeys(velocities))
    if len(distinct) < 2:
        return 0.0
    if len(distinct) <= 2000:
        return max(
            _norm(tuple(a - b for a, b in zip(u, v))) for i, u in enumerate(distinct) for v in distinct[i + 1:]
        )
    mean = tuple(sum(v[k] for v in distinct) / len(distinct) for k in range(3))
    return 2.0 * max(_norm(tuple(a - b for a, b in zip(v, mean))) for v in distinct)


def fall_height(scene: Scene) -> float:
    """Largest free-fall height h of the scene (the rule `expected_impact_speed` uses).

    Heights are measured against gravity, from the lowest point of each particle
    at the extremes of where it starts (listed particles: centre minus radius;
    regions: the top of the region minus the smallest diameter, see
    `_group_bottoms`).  Each such point drops to the first plane wall below it
    that faces upwards (normal . up > 0, e.g. a floor or a tilted chute), or to
    a solid's contact surface generated as a box (`mesh: {box: ...}`; a solid
    meshed from a file is not known before its mesh is read, and `warnings`
    says so), measured along the vertical, so tilted planes count where the
    point is.  Where nothing lies below a point, it drops to the lowest
    starting point of all particles (particles then only hit each other).  h is
    the largest drop; 0 without gravity or particles.
    """
    up = _up(scene)
    if up is None or not scene.particles:
        return 0.0
    points = [point for group in scene.particles for point in _group_bottoms(group, up)]
    if not points:
        return 0.0
    lowest = min(_dot(point, up) for point in points)
    height = 0.0
    for point in points:
        drops = [drop for wall in scene.walls for drop in (_drop_to_wall(point, up, wall),) if drop is not None]
        drops += [drop for solid in scene.solids for drop in (_drop_to_box_solid(point, up, solid),)
                  if drop is not None]
        height = max(height, min(drops) if drops else _dot(point, up) - lowest)
    return height


# The faces of a generated box mesh, by axis and side (the group names a solid's `contact` lists).
_BOX_FACES = (("xmin", "xmax"), ("ymin", "ymax"), ("zmin", "zmax"))


def _drop_to_box_solid(point, up, solid) -> Optional[float]:
    """Distance from `point` straight down (along -up) to where it enters a solid meshed as a box, when the
    face it enters is one of the solid's contact groups; None otherwise (not below, a face particles pass
    through, a mesh file, or a point inside the box)."""
    box = getattr(getattr(solid, "mesh", None), "box", None)
    if box is None or not solid.contact:
        return None
    entry, exit_, entry_face = -math.inf, math.inf, None
    for axis in range(3):
        low, high = box[0][axis], box[1][axis]
        direction = -up[axis]
        if abs(direction) < 1e-15:
            if not low <= point[axis] <= high:
                return None
            continue
        near, far = (low, high) if direction > 0 else (high, low)
        t_near = (near - point[axis]) / direction
        t_far = (far - point[axis]) / direction
        if t_near > entry:
            entry, entry_face = t_near, _BOX_FACES[axis][0 if direction > 0 else 1]
        exit_ = min(exit_, t_far)
    if entry_face is None or entry > exit_ or entry < 0.0 or entry_face not in solid.contact:
        return None
    return entry


def _drop_to_wall(point, up, wall) -> Optional[float]:
    """Distance from `point` straight down (along -up) to `wall`, or None when it is not below.

    Planes facing upwards and cylinders are exact; mesh walls are not known
    without reading their file and are skipped (`warnings` says so).
    """
    kind = getattr(wall, "kind", "plane")
    if kind == "plane":
        normal = wall.normal
        facing = _dot(normal, up)
        if facing <= 1e-12:
            return None
        # Move from `point` along -up until n . (x - p0) = 0.
        drop = (_dot(normal, point) - _dot(normal, wall.point)) / facing
        if drop >= -1e-12 * max(1.0, abs(_dot(normal, point))):
            return max(drop, 0.0)
        return None
    if kind == "cylinder" and getattr(wall, "axis", None) is not None and getattr(wall, "radius", None):
        length = _norm(wall.axis.direction)
        direction = tuple(c / length for c in wall.axis.direction)
        offset = tuple(p - a for p, a in zip(point, wall.axis.point))
        q = tuple(o - _dot(offset, direction) * d for o, d in zip(offset, direction))  # offset across the axis
        u = tuple(c - _dot(up, direction) * d for c, d in zip(up, direction))  # up across the axis
        a = _dot(u, u)
        if a <= 1e-12:
            return None  # vertical axis: the mantle is never below a point
        # |q - t u|^2 = R^2  ->  a t^2 - 2 (q.u) t + |q|^2 - R^2 = 0
        b = _dot(q, u)
        c = _dot(q, q) - wall.radius**2
        discriminant = b * b - a * c
        if discriminant < 0.0:
            return None
        roots = sorted(((b - math.sqrt(discriminant)) / a, (b + math.sqrt(discriminant)) / a))
        if getattr(wall, "inside", True):
            return max(roots[1], 0.0) if c <= 0.0 else None  # inside: down to the far side of the mantle
        return roots[0] if roots[0] >= 0.0 else None  # outside (a post): onto its top
    return None


def _wall_speed(wall) -> float:
    """Largest speed of a wall's surface: its velocity, plus |omega| R for a rotating cylinder."""
    speed = _norm(wall.velocity)
    if getattr(wall, "kind", "plane") == "cylinder" and getattr(wall, "radius", None):
        speed += _norm(getattr(wall, "angular_velocity", (0.0, 0.0, 0.0))) * wall.radius
    return speed


def _moving_solid_speed(solid) -> Optional[float]:
    """Largest surface speed of a solid under `motion:`, |V| + |omega| r_max, when its extent is known
    without reading a mesh file (a box mesh); None for a file mesh; 0 without motion."""
    motion = getattr(solid, "motion", None)
    if motion is None:
        return 0.0
    spin = _norm(motion.angular_velocity)
    speed = _norm(motion.velocity)
    if spin == 0.0:
        return speed
    if isinstance(solid.mesh, str):
        return None
    low, high = solid.mesh.box
    reach = max(_norm([corner[axis] - motion.axis_point[axis] for axis in range(3)])
                for corner in ((x, y, z) for x in (low[0], high[0]) for y in (low[1], high[1])
                               for z in (low[2], high[2])))
    return speed + spin * reach


def impact_speed_estimate(scene: Scene) -> Tuple[float, str]:
    """(speed, how it was obtained) -- see `expected_impact_speed`."""
    if scene.time.expected_impact_speed is not None:
        return float(scene.time.expected_impact_speed), "time.expected_impact_speed"
    velocities = [v for group in scene.particles for v in _initial_velocities(group)]
    initial = max((_norm(v) for v in velocities), default=0.0)
    spread = _velocity_spread(velocities)
    wall_speed = max([_wall_speed(wall) for wall in scene.walls]
                     + [_moving_solid_speed(solid) or 0.0 for solid in scene.solids], default=0.0)
    height = fall_height(scene)
    fall = math.sqrt(2.0 * _norm(scene.gravity) * height)
    on_walls = initial + wall_speed + fall
    between = spread + fall
    if between > on_walls:
        how = (f"estimated: largest initial relative speed of two particles {spread:.3g} m/s"
               f" + free fall sqrt(2 g h) over h = {height:.3g} m")
        return between, how
    how = (f"estimated: largest initial speed {initial:.3g} m/s + free fall sqrt(2 g h) over h = {height:.3g} m"
           + (f" + wall speed {wall_speed:.3g} m/s" if wall_speed else ""))
    return on_walls, how


def expected_impact_speed(scene: Scene) -> float:
    """Largest impact speed [m/s] the scene should see.

    time.expected_impact_speed when set; otherwise the larger of
    (a) on walls: the largest initial particle speed + the largest wall speed, and
    (b) between particles: the largest initial speed difference of two particles,
    each plus the free-fall speed sqrt(2 |g| h), h = `fall_height(scene)`.
    A lower bound is never useful here, so every term is the worst case.
    """
    return impact_speed_estimate(scene)[0]


# --------------------------------------------------------------------------- contact duration


@dataclass(frozen=True)
class ContactDurations:
    """Shortest contact durations [s]; None when there is no such pair in the scene."""

    particle_particle: Optional[float]
    particle_wall: Optional[float]

    @property
    def shortest(self) -> Optional[float]:
        values = [value for value in (self.particle_particle, self.particle_wall) if value is not None]
        return min(values) if values else None


def _hertz_duration(m_eff: float, r_eff: float, e_eff: float, speed: float) -> float:
    return HERTZ_DURATION_FACTOR * (m_eff**2 / (r_eff * e_eff**2 * speed)) ** 0.2


def _effective_shear_modulus(a: MaterialConfig, b: Optional[MaterialConfig]) -> float:
    """1/G* = 2 (2 - nu_a)(1 + nu_a)/E_a + 2 (2 - nu_b)(1 + nu_b)/E_b (as the contact tables; b None: a's only)."""
    return 1.0 / sum(2.0 * (2.0 - m.poisson_ratio) * (1.0 + m.poisson_ratio) / m.youngs_modulus
                     for m in (a, b) if m is not None)


def _pairs(scene: Scene, with_shear: bool = False, with_smaller_radius: bool = False, with_surface: bool = False):
    """(kind, material_a, material_b, m*, R*, E*[, G*][, smaller radius][, surface]) for the smallest particle of
    each pair of groups and each group against each wall and each contact solid; `surface`: the wall's or
    solid's name ('wall floor', 'solid plate'), None for a particle pair."""
    for pair in _pairs_with_radius(scene, with_shear):
        surface = pair[-1]
        pair = pair[:-1]
        pair = pair if with_smaller_radius else pair[:-1]
        yield pair + (surface,) if with_surface else pair


def _merged_surfaces(entries):
    """[(value, kind, label, partner)] with the entries that differ only in their surface (walls of one material
    and shape) merged into one, whose label names them all: 'glass on glass (walls floor, x_low)'."""
    merged = {}
    for value, kind, label, partner, surface in entries:
        key = (kind, label, partner, float(f"{value:.6g}"))
        if key not in merged:
            merged[key] = [value, kind, label, partner, []]
        if surface is not None:
            merged[key][4].append(surface)
    found = []
    for value, kind, label, partner, surfaces in merged.values():
        if surfaces:
            walls = [name[5:] for name in surfaces if name.startswith("wall ")]
            solids = [name[6:] for name in surfaces if name.startswith("solid ")]
            parts = ([("walls " if len(walls) > 1 else "wall ") + ", ".join(walls)] if walls else []) + (
                [("solids " if len(solids) > 1 else "solid ") + ", ".join(solids)] if solids else [])
            label = f"{label} ({'; '.join(parts)})"
        found.append((value, kind, label, partner))
    return found


def _pairs_with_radius(scene: Scene, with_shear: bool):
    smallest = []
    # Streams' particles too: a scene fed by a stream alone needs the contact limits of dt as much.
    for group, count in zip(scene.particles, contact_counts(scene)):
        material = scene.materials[group.material]
        radius, _ = group_radius_range(group)
        smallest.append((group.material, material, radius, smallest_contact_mass(group, material), count))
    for i, (name_a, a, r_a, m_a, count_a) in enumerate(smallest):
        for j, (name_b, b, r_b, m_b, count_b) in enumerate(smallest[i:], start=i):
            if count_a == 0 or count_b == 0 or (i == j and count_a < 2):
                continue  # no such pair in the scene
            pair = ("particle_particle", name_a, name_b, m_a * m_b / (m_a + m_b), r_a * r_b / (r_a + r_b),
                    _effective_modulus(a, b))
            pair = pair + (_effective_shear_modulus(a, b),) if with_shear else pair
            yield pair + (min(r_a, r_b), None)
        if count_a == 0:
            continue
        # Solids' contact surfaces are walls to the particle (their mass is far larger).
        surfaces = list(scene.walls) + [solid for solid in scene.solids if solid.contact]
        for wall in surfaces:
            w = scene.materials[wall.material]
            # A wall has m = inf, so m* = m.  Flat (planes, mesh faces) and concave (inside a
            # cylinder) walls are taken as flat, R* = r, the shorter contact; the outside of a
            # cylinder (a post) is convex, R* = r R / (r + R).
            r_eff = r_a
            surface = f"solid {wall.name}" if any(wall is solid for solid in scene.solids) else f"wall {wall.name}"
            if getattr(wall, "kind", "plane") == "cylinder" and not getattr(wall, "inside", True) and wall.radius:
                r_eff = r_a * wall.radius / (r_a + wall.radius)
            if any(wall is solid for solid in scene.solids) and scene.coupling.contact_modulus == "particle":
                # The contact tables leave the solid's compliance out (its FE mesh deforms instead).
                pair = ("particle_wall", name_a, wall.material, m_a, r_eff, _effective_modulus(a, None))
                pair = pair + (_effective_shear_modulus(a, None),) if with_shear else pair
                yield pair + (r_a, surface)
                continue
            pair = ("particle_wall", name_a, wall.material, m_a, r_eff, _effective_modulus(a, w))
            pair = pair + (_effective_shear_modulus(a, w),) if with_shear else pair
            yield pair + (r_a, surface)


def hertz_contact_duration(scene: Scene, speed: float) -> ContactDurations:
    """Shortest Hertz contact durations at impact speed `speed` [m/s].

    t_c = 2.868 (m*^2 / (R* E*^2 v))^(1/5) over the pairs of each group's smallest
    particle (particle-particle) and each group's smallest particle against each
    wall (particle-wall: R* = r, m* = m).
    """
    if speed <= 0.0:
        raise ValueError("impact speed must be positive")
    best = {"particle_particle": None, "particle_wall": None}
    for kind, _, _, m_eff, r_eff, e_eff in _pairs(scene):
        value = _hertz_duration(m_eff, r_eff, e_eff, speed)
        if best[kind] is None or value < best[kind]:
            best[kind] = value
    return ContactDurations(**best)


def _pair_duration(interaction, m_eff: float, r_eff: float, e_eff: float, speed: float) -> float:
    """Contact duration of one pair at impact speed `speed` for the model it uses (`contact_duration`)."""
    if interaction.model == "linear_spring_dashpot":
        if interaction.normal_stiffness is not None:
            return math.pi * math.sqrt(m_eff / interaction.normal_stiffness)
        return math.pi * _peak_overlap(m_eff, r_eff, e_eff, speed) / speed
    return _hertz_duration(m_eff, r_eff, e_eff, speed)


def contact_duration(scene: Scene, speed: float) -> ContactDurations:
    """Shortest contact durations for the model each pair uses.

    Hertz-Mindlin: as `hertz_contact_duration`.  Linear spring-dashpot with
    normal_stiffness k: the undamped half period pi sqrt(m*/k) (damping lengthens
    it slightly).  Linear without normal_stiffness derives k so that the peak
    overlap at the impact speed equals Hertz's, delta_max = (15 m* v^2 / (16 E* sqrt(R*)))^(2/5),
    giving pi delta_max / v.
    """
    if speed <= 0.0:
        raise ValueError("impact speed must be positive")
    best = {"particle_particle": None, "particle_wall": None}
    for kind, name_a, name_b, m_eff, r_eff, e_eff in _pairs(scene):
        value = _pair_duration(scene.interaction(name_a, name_b), m_eff, r_eff, e_eff, speed)
        if best[kind] is None or value < best[kind]:
            best[kind] = value
    return ContactDurations(**best)


def tightest_contact_resolution(scene: Scene, speed: float, dt: float) -> Optional[Tuple[str, float, float]]:
    """(pair, steps per contact at `speed`, steps its restitution needs) of the pair with the fewest steps for
    its need: 'particle-particle glass-glass' or 'particle-wall glass on steel (wall floor)'; None without pairs."""
    best = None
    for kind, name_a, name_b, m_eff, r_eff, e_eff, surface in _pairs(scene, with_surface=True):
        interaction = scene.interaction(name_a, name_b)
        steps = _pair_duration(interaction, m_eff, r_eff, e_eff, speed) / dt
        need = steps_per_contact_required(interaction.model, interaction.restitution)
        if best is None or steps / need < best[1] / best[2]:
            label = (f"{kind.replace('_', '-')} {name_a}-{name_b}" if surface is None
                     else f"{kind.replace('_', '-')} {name_a} on {name_b} ({surface})")
            best = (label, steps, need)
    return best


# --------------------------------------------------------------------------- memory

# Per particle, in bytes (see memory_estimate_bytes):
_STATE_BYTES = 14 * 8 + 3 * 8  # x, v, w, f (3 each), radius, mass: 14 float64; id, material, cell: 3 x 8
_NEIGHBOURS = 8  # half Verlet list entries per particle in a dense packing (12 contacts / 2 + skin)
_LIST_KEY_BYTES = 4 + 8  # int32 partner index, int64 partner id; then 8 bytes per contact history column
_LIST_OFFSET_BYTES = 8  # CSR row offset
_OVERHEAD = 1.4  # ghosts, the history remap buffer at rebuild, sort scratch


def bytes_per_particle(history_columns: int) -> int:
    """Estimated bytes per particle with `history_columns` float64 of contact history per list entry (7 with
    friction: the tangential spring, the force it applied and the springs' energy; 0 frictionless; up to 14
    with rolling and jkr): 963 B with friction, 571 B without, to the nearest 10."""
    entry = _LIST_KEY_BYTES + 8 * history_columns
    return int(round(_OVERHEAD * (_STATE_BYTES + _NEIGHBOURS * entry + _LIST_OFFSET_BYTES), -1))


def contact_history_columns(scene: Scene) -> int:
    """Float64 columns of contact history per list entry that the scene's contact laws keep."""
    from pdemfem.contact.tables import build_contact_tables

    return build_contact_tables(scene, characteristic_speed=expected_impact_speed(scene)).history_width


def memory_estimate_bytes(scene: Scene) -> int:
    """Estimated particle memory [bytes], summed over ranks.

    bytes = N * 1.4 * (14 * 8 + 3 * 8 + 8 * (4 + 8 + 8 c) + 8), c the contact history columns
    (`bytes_per_particle`): state arrays of 14 float64 (position, velocity, angular velocity, force,
    radius, mass... ) and 3 integers (8 bytes each) per particle, a half Verlet
    list of ~8 entries per particle (int32 partner index, int64 partner id, c float64 of contact
    history), its CSR offsets, and 40 % for ghosts, the history remap at list rebuild and sort scratch.
    Excludes the fixed cost of the interpreter, numba and PETSc (~150-250 MB per rank) and any FEM mesh.
    N counts spheres: a clump's member spheres each (their bodies' arrays are small beside them).
    """
    return sphere_count(scene) * bytes_per_particle(contact_history_columns(scene))


def sphere_count(scene: Scene) -> int:
    """Spheres inserted at t = 0: each particle, and each member sphere of a clump."""
    return sum(count * (len(clump_group_template(group, None).member_radii) if group.clump is not None else 1)
               for group, count in zip(scene.particles, group_counts(scene)))


# --------------------------------------------------------------------------- warnings


def _format_seconds(value: float) -> str:
    return f"{value:.3g} s"


def warnings(scene: Scene, solid_critical_step: Optional[float] = None, dt: Optional[float] = None) -> List[str]:
    """Plain-language warnings about accuracy, stability or cost; an empty list when none.

    Not errors: the scene runs, but probably not as intended.  `pdemfem check` prints them and
    `pdemfem run` repeats them before the first step.  dt: the step the run takes when it is known (a
    coupled scene's dt auto can be lowered by a solid's surface nodes); time_step(scene) otherwise.
    """
    found: List[str] = list(solid_warnings(scene))
    if scene.time.expected_impact_speed is None:
        for index, solid in enumerate(scene.solids):
            if _moving_solid_speed(solid) is None:
                found.append(f"solids[{index}] ({solid.name}): dt auto does not see the surface speed of this spinning "
                             f"solid (its mesh is a file): set time.expected_impact_speed to at least |velocity| + "
                             f"|angular_velocity| x its largest distance from motion.axis_point")
    count = particle_count(scene)
    if count == 0 and not any(group.insert.kind == "stream" for group in scene.particles):
        found.append("the scene has no particles")
        return found
    if dt is None:
        try:
            dt = time_step(scene, solid_critical_step)
        except SceneError:
            return found
    rayleigh = rayleigh_time(scene)
    if scene.time.dt != "auto" and rayleigh is not None and dt > RAYLEIGH_LIMIT * rayleigh:
        found.append(
            f"time.dt = {dt:.3g} s is {dt / rayleigh:.2f} x the Rayleigh time {rayleigh:.3g} s; "
            f"above ~{RAYLEIGH_LIMIT} the explicit integration may be unstable (use dt: auto, or "
            f"dt <= {0.2 * rayleigh:.3g} s)"
        )
    speed, _ = impact_speed_estimate(scene)
    smallest_radius = min(group_radius_range(group)[0] for group in scene.particles)
    if not math.isfinite(speed):
        found.append(f"the impact speed is {speed:g} m/s: an initial velocity's square overflows; the run stops "
                     f"at once (non-finite energy): check the particles' initial velocities")
        return found
    limits = contact_step_limits(scene, speed)
    # The binding (smallest) limit of each kind: resolution and dashpot stability.
    binding = [min(((limit, why) for limit, why in limits if why.startswith("dashpot") == dashpot),
                   default=None) for dashpot in (False, True)]
    for limit, why in [choice for choice in binding if choice is not None]:
        if dt > limit * (1.0 + 1e-9):  # 1e-9: dt auto equals its binding limit up to round-off
            if why.startswith("dashpot"):
                found.append(
                    f"dt = {dt:.3g} s is above the {why}: the contact can gain energy and blow up "
                    f"(need dt <= {limit:.3g} s; use dt: auto, or raise the restitution)"
                )
            else:
                found.append(
                    f"dt = {dt:.3g} s is above the {why} (need dt <= {limit:.3g} s): the restitution comes out "
                    f"wrong by more than 1 %; use dt: auto, or lower time.dt_factor or time.dt"
                )
    if speed > 0.0:
        if speed * dt > MAX_STEP_TRAVEL * smallest_radius:
            found.append(
                f"at the impact speed {speed:.3g} m/s a particle moves {speed * dt / smallest_radius:.2f} radii per "
                f"step (want <= {MAX_STEP_TRAVEL}): lower dt, or check the impact speed"
            )
    steps = scene.time.end / dt
    every = scene.output.every
    if every is not None and every > scene.time.end:
        found.append(f"output.every = {every:g} s is longer than time.end = {scene.time.end:g} s: only the start and "
                     f"the end are written")
    if every is not None and every < dt:
        found.append(f"output.every = {every:g} s is shorter than dt = {dt:.3g} s: one output per step")
    if steps > 1e7:
        found.append(f"{steps:.3g} steps to time.end: check time.end and dt")
    skin = scene.neighbors.skin
    if skin is not None and skin > 2.0 * smallest_radius:
        found.append(
            f"neighbors.skin = {skin:g} m is more than a particle diameter: the Verlet lists grow a lot "
            "(cost ~ (r + skin)^3) for fewer rebuilds; 0.1-0.5 radius is usual"
        )
    up = _up(scene)
    # A solid with contact surfaces may catch the particles too (its surface orientation is only known
    # once the mesh is read, so any contact solid counts).
    catching_solid = any(solid.contact for solid in scene.solids)
    if up is not None and not catching_solid and not any(_may_catch(wall, up) for wall in scene.walls):
        found.append("gravity is on but no wall or contact solid faces upwards: the particles fall freely")
    meshes = [wall.name for wall in scene.walls if getattr(wall, "kind", "plane") == "mesh"]
    if meshes and scene.time.expected_impact_speed is None:
        found.append(
            f"the impact-speed estimate cannot see mesh walls ({', '.join(meshes)}): set "
            "time.expected_impact_speed to the largest speed at which particles hit them"
        )
    meshed_solids = [solid.name for solid in scene.solids
                     if solid.contact and getattr(solid.mesh, "box", None) is None and solid.motion is None]
    if up is not None and meshed_solids and scene.time.expected_impact_speed is None:
        found.append(
            f"the impact-speed estimate cannot see the contact surfaces of solids meshed from a file "
            f"({', '.join(meshed_solids)}): set time.expected_impact_speed to the largest speed at which particles "
            "hit them (dt auto resolves impacts at that speed)"
        )
    found.extend(_tunnelling_warnings(scene, speed, dt, smallest_radius))
    for ratio, label in thin_surface_overlaps(scene, speed):
        if ratio > 1.0:
            found.append(f"{label}: at {speed:.3g} m/s the peak overlap is {ratio:.2g} radii, so the sphere passes "
                         f"through the thin surface whatever the step (the run stops when it happens): use stiffer "
                         f"materials (youngs_modulus) or lower the impact speed")
    thin = thin_surface_materials(scene)
    for ratio, kind, label, partner in contact_overlaps(scene, speed):
        if ratio > 1.0 and kind == "particle_particle":
            found.append(f"contacts {label}: at the impact speed {speed:.3g} m/s the peak overlap is {ratio:.2g} of "
                         f"the smaller radius, so the spheres pass through each other (the run stops when it "
                         f"happens): use stiffer materials (youngs_modulus, normal_stiffness) or lower the speed")
        elif ratio > PEAK_OVERLAP_WARNING and not (ratio > 1.0 and kind == "particle_wall" and partner in thin):
            # (a thin surface past 1 has its tunnelling warning above)
            found.append(f"contacts {label}: at the impact speed {speed:.3g} m/s the peak overlap is {ratio:.2g} of "
                         f"the smaller radius (want <= {PEAK_OVERLAP_WARNING}): the contact law is a small-overlap "
                         f"law, so forces and contact times are off; use stiffer materials (youngs_modulus, "
                         f"normal_stiffness) or lower the speed")
    found.extend(start_inside_walls(scene))
    found = list(dict.fromkeys(found))  # never the same line twice
    thermal = thermal_step_limit(scene)
    if thermal is not None and dt > thermal[0]:
        found.append(f"dt = {dt:.3g} s is above the estimated thermal step limit {thermal[0]:.3g} s of group "
                     f"'{thermal[1]}' (m c / sum of its contacts' conductances): temperatures may overshoot or "
                     f"blow up and the run stops when a particle passes it; raise heat_capacity, lower "
                     f"conductivity or dt (docs/heat.md)")
    return found


# Contacts of a particle in the thermal step estimate: a sphere touches at most 12 equal spheres (the kissing
# number); a wall takes some neighbours' places.  Random packings average ~6, so 12 covers a bed's best-connected
# particle.
THERMAL_CONTACTS = 12


def thermal_step_limit(scene: Scene) -> Optional[Tuple[float, str]]:
    """(dt, group) below which the explicit temperature update stays stable and overshoot-free,
    dt sum(H) / (m c) <= 1 (pdemfem.particles.heat), estimated for the smallest particle of each group in a
    resting bed that is hit: THERMAL_CONTACTS contacts, each as conductive as the group's best (H = 2 k* a),
    one of them at the peak overlap of an impact at the expected speed (at least that of a drop by one
    diameter of the smallest particle: the agitation of a pile settling), the others pressed by the bed's
    weight (`bed_contact_force`); None with heat off or no particles.

    Against the run-time guard's measure (tests/test_heat_particles.py): 17.7x above it for a sphere resting
    alone on a hot floor (12 contacts where it has one), 1.85x for a bed of 350 spheres settling onto a hot
    floor (the guard's largest ratio: impacts onto the pressed bottom layers); 15 contacts at the impact's
    overlap, the estimate before, were 101x and 8x above."""
    if not scene.heat_enabled or not scene.particles:
        return None
    speed = max(expected_impact_speed(scene), settling_speed(scene))
    if not (0.0 < speed < math.inf):
        return None
    bed_force = bed_contact_force(scene)
    hit, pressed = {}, {}  # the group material's best conductance [W/K] of each kind of contact
    for kind, name_a, name_b, m_eff, r_eff, e_eff in _pairs(scene):
        k_a, k_b = scene.materials[name_a].conductivity, scene.materials[name_b].conductivity
        if kind == "particle_wall" and not _wall_conducts(scene, name_b):
            continue
        if not k_a or not k_b:
            continue
        interaction = scene.interaction(name_a, name_b)
        twice_pair_conductivity = 4.0 * k_a * k_b / (k_a + k_b)  # H = 2 k* a
        impact_radius = math.sqrt(r_eff * pair_peak_overlap(interaction, m_eff, r_eff, e_eff, speed))
        hit[name_a] = max(hit.get(name_a, 0.0), twice_pair_conductivity * impact_radius)
        pressed[name_a] = max(pressed.get(name_a, 0.0),
                              twice_pair_conductivity * pressed_contact_radius(interaction, r_eff, e_eff, bed_force))
    limits = []
    for group in scene.particles:
        material = scene.materials[group.material]
        conductance = hit.get(group.material, 0.0) + (THERMAL_CONTACTS - 1) * pressed.get(group.material, 0.0)
        if conductance > 0.0 and material.heat_capacity:
            capacity = _mass(material, group_radius_range(group)[0]) * material.heat_capacity
            limits.append((capacity / conductance, group.name))
    return min(limits) if limits else None


def bed_contact_force(scene: Scene) -> float:
    """Force [N] on a contact low in a resting bed: the weight of a column of N^(1/3) of the scene's heaviest
    particles (N those it inserts at the start).  A bed no deeper than it is wide is at most N^(1/3) particles
    deep; the walls of a deeper, narrower column carry the weight beyond about its width by friction
    (Janssen).  0 without gravity."""
    gravity = _norm(scene.gravity)
    if gravity == 0.0 or not scene.particles:
        return 0.0
    heaviest = max(clump_group_template(group, scene.materials[group.material]).mass if group.clump is not None
                   else _mass(scene.materials[group.material], group_radius_range(group)[1])
                   for group in scene.particles)
    return max(particle_count(scene), 1) ** (1.0 / 3.0) * heaviest * gravity


def pressed_contact_radius(interaction, r_eff: float, e_eff: float, force: float) -> float:
    """Radius a [m] of a contact pressed by `force` at rest, for the pair's normal model: Hertz's
    (3 F R* / (4 E*))^(1/3) (also the linear law without normal_stiffness, matched to Hertz), JKR's
    (3 R* / (4 E*) (F + 2 F_c + 2 sqrt(F_c F + F_c^2)))^(1/3) with F_c = 3/2 pi W R* (adhesion widens it), or
    sqrt(R* F / k) for a linear spring k (its geometric contact radius, as the conductance takes it)."""
    if interaction.model == "linear_spring_dashpot" and interaction.normal_stiffness is not None:
        return math.sqrt(r_eff * force / interaction.normal_stiffness)
    load = force
    if interaction.model == "jkr":
        pull_off = 1.5 * math.pi * interaction.work_of_adhesion * r_eff
        load = force + 2.0 * pull_off + 2.0 * math.sqrt(pull_off * force + pull_off * pull_off)
    return (3.0 * load * r_eff / (4.0 * e_eff)) ** (1.0 / 3.0)


def _wall_conducts(scene: Scene, material: str) -> bool:
    """Whether some wall or solid of this material exchanges heat (a wall needs a temperature)."""
    return (any(wall.material == material and wall.temperature is not None for wall in scene.walls)
            or any(solid.material == material for solid in scene.solids))


def start_inside_walls(scene: Scene) -> List[str]:
    """Groups inserted in a region that reaches behind a plane wall (the wall pushes such particles
    out with the energy of the whole overlap).  Listed positions are checked one by one when the run
    starts (pdemfem.scene.inputs refuses overlaps past 0.05 radii; a particle resting at its static
    overlap is meant, and not warned about)."""
    found = []
    for index, group in enumerate(scene.particles):
        for wall in _plane_walls(scene):
            if _region_behind_wall(group, wall, wholly=group.insert.kind == "stream"):
                # A stream does not insert a candidate that touches a wall: behind one wholly, it inserts nothing.
                found.append(
                    f"particles[{index}] ({group.name}): the stream's region lies wholly behind wall '{wall.name}', "
                    f"so it inserts nothing (normal points into the domain): move the region or the wall"
                    if group.insert.kind == "stream" else
                    f"particles[{index}] ({group.name}) starts partly behind or inside wall '{wall.name}' "
                    f"(normal points into the domain): move the region or the wall"
                )
        if group.insert.kind == "stream" and group.insert.start >= scene.time.end:
            found.append(f"particles[{index}] ({group.name}): the stream starts at t = {group.insert.start:g} s, at "
                         f"or after time.end = {scene.time.end:g} s, so it inserts nothing: lower "
                         f"particles[{index}].insert.start or raise time.end")
    return found


def mesh_wall_warnings(scene: Scene, walls) -> List[str]:
    """Mesh walls smaller than one diameter of the smallest particle in every direction: almost surely a
    file in other units than its `scale` assumes (a belt exported in metres read with scale 0.001 is 0.1 mm
    long; every grain falls past it).  `walls`: the built contributor walls (MeshWall has `vertices`)."""
    if not scene.particles:
        return []
    diameter = 2.0 * min(group_radius_range(group)[0] for group in scene.particles)
    found = []
    indices = {wall.name: index for index, wall in enumerate(scene.walls)}
    for wall in walls:
        vertices = getattr(wall, "vertices", None)
        if vertices is None or not len(vertices):
            continue
        extent = float(np.max(np.ptp(vertices, axis=0)))
        if extent < diameter:
            index = indices[wall.name]
            scale = scene.walls[index].scale
            found.append(f"walls[{index}] ({wall.name}): the mesh spans only {extent:.3g} m (after scale {scale:g}), "
                         f"less than the smallest particle's diameter {diameter:.3g} m: is the file in other units "
                         f"than walls[{index}].scale assumes? (a file in millimetres needs scale: 0.001, one in "
                         f"metres scale: 1)")
    return found


def lame_ratio(poisson_ratio: float) -> float:
    """lambda / mu = 2 nu / (1 - 2 nu): how much stiffer the material is in volume than in shear."""
    return 2.0 * poisson_ratio / (1.0 - 2.0 * poisson_ratio)


def solid_warnings(scene: Scene) -> List[str]:
    """Nearly incompressible solids: P1 tetrahedra lock (too stiff in bending and shear) and the
    explicit critical step, ~ h / sqrt((lambda + 2 mu) / rho), shrinks against the shear waves
    that carry the physics by sqrt((lambda + 2 mu) / mu) = sqrt(2 (1 - nu) / (1 - 2 nu))."""
    found = []
    for index, solid in enumerate(scene.solids):
        nu = scene.materials[solid.material].poisson_ratio
        if nu < NEARLY_INCOMPRESSIBLE_NU:
            continue
        ratio = lame_ratio(nu)
        slowdown = math.sqrt(2.0 * (1.0 - nu) / (1.0 - 2.0 * nu)) / math.sqrt(2.0 * (1.0 - 0.3) / (1.0 - 0.6))
        text = (f"solids[{index}] ({solid.name}): poisson_ratio {nu:g} of material '{solid.material}' is nearly "
                f"incompressible (lambda/mu = {ratio:.3g}, >= {lame_ratio(NEARLY_INCOMPRESSIBLE_NU):.0f} from nu = "
                f"{NEARLY_INCOMPRESSIBLE_NU}): the FE critical step is {slowdown:.3g} x smaller than at nu = 0.3 and "
                f"the static solve needs more iterations")
        if solid.element == "P1":
            text += "; linear tetrahedra (P1) lock and come out too stiff: use element: P2"
        found.append(text)
    return found


def _may_catch(wall, up) -> bool:
    """Can this wall stop a falling particle? (planes facing up, non-vertical cylinders, meshes)."""
    kind = getattr(wall, "kind", "plane")
    if kind == "plane":
        return _dot(wall.normal, up) > 1e-12
    if kind == "cylinder" and getattr(wall, "axis", None) is not None:
        direction = wall.axis.direction
        return abs(_dot(direction, up)) < _norm(direction) * (1.0 - 1e-9)
    return True


def _plane_walls(scene: Scene) -> List[WallConfig]:
    return [wall for wall in scene.walls if wall.kind == "plane"]


def _tunnelling_warnings(scene: Scene, speed: float, dt: float, smallest_radius: float) -> List[str]:
    """Mesh walls and the solids' contact surfaces are thin: a sphere whose centre crosses a
    triangle's plane within one step is pushed out on the far side (two-sided) or not at all
    (one-sided).  Warn when the travel per step at the impact speed plus the surface's own speed
    exceeds TUNNEL_TRAVEL radii (the run stops when a particle really moves that fast)."""
    found = []
    surfaces = [(f"mesh wall '{wall.name}'", _norm(wall.velocity)) for wall in scene.walls if wall.kind == "mesh"]
    surfaces += [(f"solid '{solid.name}' (contact {', '.join(solid.contact)})", 0.0)
                 for solid in scene.solids if solid.contact]
    for label, surface_speed in surfaces:
        travel = (speed + surface_speed) * dt
        if travel > TUNNEL_TRAVEL * smallest_radius:
            found.append(
                f"{label}: at {speed + surface_speed:.3g} m/s (impact + surface speed) a particle moves "
                f"{travel / smallest_radius:.2f} radii per step (want <= {TUNNEL_TRAVEL}); it can tunnel through "
                f"the thin surface and the run stops when it does: use dt: auto, lower time.dt, or set "
                f"time.expected_impact_speed if it is lower"
            )
    return found


def thin_surface_materials(scene: Scene) -> set:
    """Materials of the thin surfaces: mesh walls and the solids' contact surfaces."""
    return ({wall.material for wall in scene.walls if wall.kind == "mesh"}
            | {solid.material for solid in scene.solids if solid.contact})


def thin_surface_overlaps(scene: Scene, speed: float) -> List[Tuple[float, str]]:
    """[(peak overlap / radius, label)] of an impact at `speed` on each thin surface (mesh walls, the
    solids' contact surfaces).  delta_max / r = (15 m v^2 / (16 E* sqrt(r)))^(2/5) / r does not depend
    on r (m ~ r^3); above 1 the sphere's centre reaches the surface before the contact stops it, so
    it passes through whatever the step (the Hertz law has left its range long before)."""
    thin = thin_surface_materials(scene)
    found = []
    if speed <= 0.0 or not math.isfinite(speed):
        return found
    surfaces = ({f"wall {wall.name}" for wall in scene.walls if wall.kind == "mesh"}
                | {f"solid {solid.name}" for solid in scene.solids if solid.contact})
    entries = []
    for kind, name_a, name_b, m_eff, r_eff, e_eff, surface in _pairs(scene, with_surface=True):
        if kind == "particle_wall" and name_b in thin and surface in surfaces:
            entries.append((_peak_overlap(m_eff, r_eff, e_eff, speed) / r_eff, kind, f"{name_a} on {name_b}", name_b,
                            surface))
    # One entry per group and material, naming its surfaces (several walls of one material gave one line each).
    return [(ratio, label) for ratio, _, label, _ in _merged_surfaces(entries)]


def pair_peak_overlap(interaction, m_eff: float, r_eff: float, e_eff: float, speed: float) -> float:
    """Peak overlap of an undamped head-on impact at `speed` for the pair's normal model: Hertz's
    (15 m* v^2 / (16 E* sqrt(R*)))^(2/5) (also the linear law without normal_stiffness, which is matched to
    it, and the JKR law, Hertz's at the overlaps that matter here), or v sqrt(m*/k) for a linear spring k."""
    if interaction.model == "linear_spring_dashpot" and interaction.normal_stiffness is not None:
        return speed * math.sqrt(m_eff / interaction.normal_stiffness)
    return _peak_overlap(m_eff, r_eff, e_eff, speed)


def contact_overlaps(scene: Scene, speed: float) -> List[Tuple[float, str, str, str]]:
    """[(peak overlap / smaller radius, kind, label, partner material)] of an impact at `speed` for each pair of
    groups (kind 'particle_particle') and each group on each wall or contact solid ('particle_wall').  The contact
    laws are small-overlap laws; two spheres overlapping by more than the smaller radius can pass through
    each other (their centres cross and the normal flips)."""
    found = []
    if speed <= 0.0 or not math.isfinite(speed):
        return found
    entries = []
    for kind, name_a, name_b, m_eff, r_eff, e_eff, smaller, surface in _pairs(scene, with_smaller_radius=True,
                                                                             with_surface=True):
        overlap = pair_peak_overlap(scene.interaction(name_a, name_b), m_eff, r_eff, e_eff, speed)
        joiner = "-" if kind == "particle_particle" else " on "
        entries.append((overlap / smaller, kind, f"{name_a}{joiner}{name_b}", name_b, surface))
    # Walls of one material (a box's five planes) give one entry naming them, not one identical line each.
    return _merged_surfaces(entries)


def _region_behind_wall(group: ParticleGroupConfig, wall: WallConfig, wholly: bool = False) -> bool:
    """True when the group's insertion region reaches behind the plane wall (`wholly`: lies entirely behind it,
    touching it at most), False for listed positions."""
    if group.insert.kind == "list":
        return False
    length = _norm(wall.normal)
    normal = tuple(c / length for c in wall.normal)
    # Region boxes bound the particles themselves (centres lie at least a radius inside).  Each corner's height
    # above the plane, against the round-off of its coordinate.
    heights = [(_dot(normal, corner) - _dot(normal, wall.point), 1e-12 * max(1.0, abs(_dot(normal, corner))))
               for corner in _group_points(group)]
    if wholly:
        return all(height <= round_off for height, round_off in heights)
    return any(height < -round_off for height, round_off in heights)
