"""The validated scene model: YAML keys map one-to-one onto these fields.

Key names are a public contract (external scripts write scene files); add keys,
never rename them.  Validation is pydantic's; pdemfem.scene.loader turns its
errors into one message per problem that names the key path and the fix.
"""
from __future__ import annotations

import difflib
import re
from typing import Annotated, Dict, List, Literal, Optional, Tuple, Union

from pydantic import Field, PrivateAttr, field_validator, model_validator

from pdemfem.config_types import Box, NonNegativeFloat, PositiveFloat, StrictModel, Vector3  # noqa: F401 (re-exported)
from pdemfem.contact.registry import NORMAL_BY_NAME, ROLLING_BY_NAME
from pdemfem.fem.config import SolidConfig

# Names of particle groups, walls, solids and outlets: they go into history columns (force_<name>_x) and a
# solid's into its output files' names (<name>.h5), so no separators, commas or path parts.
NAME_PATTERN = re.compile(r"[A-Za-z0-9_-][A-Za-z0-9_.-]*")
SERIES_NAMES = ("particles", "clumps")  # the particle and clump series' files in the output directory
NORMAL_MODEL_NAMES = tuple(NORMAL_BY_NAME)
ROLLING_MODEL_NAMES = tuple(ROLLING_BY_NAME)


class TimeConfig(StrictModel):
    end: PositiveFloat = Field(description="simulated end time [s]")
    dt: Union[PositiveFloat, Literal["auto"]] = Field("auto", description='time step [s] or "auto"')
    dt_factor: Annotated[float, Field(gt=0, le=1)] = Field(
        0.2, description="upper bound of dt auto as a fraction of the Rayleigh time (0.1-0.3 usual); "
                         "dt auto also resolves every contact (docs/stability.md)"
    )
    expected_impact_speed: Optional[PositiveFloat] = Field(
        None, description="largest impact speed [m/s] for the contact-duration check; estimated when absent"
    )

    @model_validator(mode="after")
    def _step_within_the_run(self):
        if self.dt != "auto" and self.dt > self.end:
            raise ValueError(f"dt = {self.dt:g} s is longer than end = {self.end:g} s: the run could not take one step "
                             "of it; give a dt below end (the contacts want far smaller: dt: auto derives it)")
        return self


class MaterialConfig(StrictModel):
    density: PositiveFloat = Field(description="mass density [kg/m^3] (particle mass = 4/3 pi r^3 density)")
    youngs_modulus: PositiveFloat = Field(
        description="Young's modulus E [Pa]; the time step scales as 1/sqrt(E)")
    poisson_ratio: Annotated[float, Field(gt=-1.0, lt=0.5)] = Field(description="Poisson's ratio nu (dimensionless)")
    thermal_expansion: NonNegativeFloat = Field(
        0.0, description="linear thermal expansion coefficient [1/K] (solids; unused by particles)")
    conductivity: Optional[PositiveFloat] = Field(
        None, description="thermal conductivity k [W/(m K)]; needed by every particle material (and by walls and "
                          "solids that exchange heat) when heat is on (docs/heat.md)")
    heat_capacity: Optional[PositiveFloat] = Field(
        None, description="specific heat c [J/(kg K)]; needed by every particle material (and by solids) when heat "
                          "is on; a smaller c heats faster and lowers the thermal step limit (docs/heat.md)")


class InteractionConfig(StrictModel):
    model: Literal[NORMAL_MODEL_NAMES] = Field(
        "hertz_mindlin", description="normal contact model: hertz_mindlin (Hertz + Mindlin), linear_spring_dashpot, "
                                     "jkr (Hertz with JKR adhesion, needs work_of_adhesion)")
    restitution: Annotated[float, Field(gt=0, le=1)] = Field(
        0.5, description="coefficient of restitution of a head-on impact (calibrates the normal dashpot exactly)")
    friction: NonNegativeFloat = Field(0.5, description="Coulomb friction coefficient mu (0: no tangential force "
                                                        "and no tangential history)")
    rolling_friction: NonNegativeFloat = Field(0.0, description="rolling resistance mu_r: the rolling moment is at "
                                                                "most mu_r R* F_n (0: none)")
    rolling_model: Literal[ROLLING_MODEL_NAMES] = Field(
        "constant_torque", description="constant_torque (a constant moment against rolling) or elastic_plastic "
                                       "(a rolling spring-dashpot capped at the limit: bodies come to a true rest)")
    rolling_damping: Annotated[float, Field(ge=0)] = Field(
        0.3, description="elastic_plastic only: the rolling dashpot as a fraction of critical, for a body "
                         "rocking about its contact point")
    work_of_adhesion: NonNegativeFloat = Field(0.0, description="jkr only: work of adhesion W [J/m^2] "
                                                                "(twice the surface energy of like bodies)")
    # Linear spring-dashpot only: when absent, derived from the materials so that
    # the peak overlap at `expected_impact_speed` equals Hertz's.
    normal_stiffness: Optional[PositiveFloat] = Field(
        None, description="linear_spring_dashpot only: k_n [N/m]; absent: the stiffness giving Hertz's peak "
                          "overlap at expected_impact_speed")
    tangential_stiffness_ratio: Annotated[float, Field(gt=0)] = Field(
        2.0 / 7.0, description="k_t / k_n for the linear model (2/7 matches normal and tangential periods)"
    )

    @model_validator(mode="after")
    def _model_parameters(self):
        if self.model == "jkr" and self.work_of_adhesion <= 0.0:
            raise ValueError("model jkr needs work_of_adhesion > 0 [J/m^2] (e.g. 0.1); for no adhesion use "
                             "model hertz_mindlin")
        if self.model != "jkr" and self.work_of_adhesion > 0.0:
            raise ValueError(f"work_of_adhesion is used by model jkr only (this interaction's model is "
                             f"{self.model}): set model: jkr or remove work_of_adhesion")
        return self


class RadiusRange(StrictModel):
    min: PositiveFloat = Field(description="smallest radius [m]")
    max: PositiveFloat = Field(description="largest radius [m] (radii are uniformly distributed between the two)")

    @model_validator(mode="after")
    def _ordered(self):
        if self.max < self.min:
            raise ValueError(f"max ({self.max}) is smaller than min ({self.min}); swap them")
        return self


class BoxRegion(StrictModel):
    box: Box = Field(description="[[x0,y0,z0],[x1,y1,z1]] [m]: particle centres lie at least a radius inside it")


# Keys only kind stream reads (insertion over time, pdemfem.particles.stream; docs/streams.md).
STREAM_KEYS = ("rate", "mass_rate", "start", "stop", "interval")


class InsertConfig(StrictModel):
    kind: Literal["list", "lattice", "random", "stream"] = Field(
        description="list: explicit positions; lattice: simple cubic in a box; random: random sequential addition "
                    "(no initial overlap); stream: particles inserted over time in region (docs/streams.md)")
    region: Optional[BoxRegion] = Field(None, description="lattice, random: the box the particles are placed in")
    count: Optional[Annotated[int, Field(gt=0)]] = Field(
        None, description="lattice, random: number of particles; stream: the most it inserts in all (optional)")
    seed: int = Field(0, description="random seed for radii, jitter and random positions (runs are reproducible)")
    # kind: list
    positions: Optional[List[Vector3]] = Field(None, description="list: particle centres [m]")
    velocities: Optional[List[Vector3]] = Field(
        None, description="list: one initial velocity per position [m/s]; default: velocity")
    angular_velocities: Optional[List[Vector3]] = Field(
        None, description="list: one initial angular velocity per position [rad/s]; default zero")
    radii: Optional[List[PositiveFloat]] = Field(
        None, description="list: one radius per position [m], overriding the group's radius")
    orientations: Optional[List[Tuple[float, float, float, float]]] = Field(
        None, description="list, clump groups: one orientation per position, a unit quaternion [w, x, y, z] turning "
                          "the clump's frame into the world's; default: each clump as given in its frame")
    orientation: Optional[Tuple[float, float, float, float]] = Field(
        None, description="lattice, random, clump groups: the orientation [w, x, y, z] of every clump; default: "
                          "uniformly random orientations drawn from seed")
    # kind: lattice / random
    velocity: Vector3 = Field((0.0, 0.0, 0.0), description="initial velocity of every particle [m/s]")
    spacing: Optional[PositiveFloat] = Field(
        None, description="lattice: site spacing [m]; default largest diameter * 1.05")
    jitter: Annotated[float, Field(ge=0, le=1)] = Field(
        0.0, description="lattice: random offset of each site as a fraction of the gap spacing - largest diameter")
    max_attempts: Annotated[int, Field(gt=0)] = Field(
        1000, description="random, stream: tries per particle before the insertion gives up (stream: until the next "
                          "insertion event)")
    # kind: stream
    rate: Optional[PositiveFloat] = Field(None, description="stream: particles inserted per second [1/s]")
    mass_rate: Optional[PositiveFloat] = Field(None, description="stream: mass inserted per second [kg/s]")
    start: NonNegativeFloat = Field(0.0, description="stream: time of the first insertion event [s]")
    stop: Optional[PositiveFloat] = Field(None, description="stream: time the stream ends [s]; default: never")
    interval: Optional[PositiveFloat] = Field(
        None, description="stream: time between insertion events [s]; default: the time a particle takes to leave "
                          "the region (docs/streams.md)")

    @model_validator(mode="after")
    def _complete(self):
        if self.kind != "stream":
            foreign = sorted(key for key in STREAM_KEYS if key in self.model_fields_set)
            if foreign:
                raise ValueError(f"kind {self.kind} does not use {', '.join(foreign)}; remove it, or use kind: stream "
                                 f"to insert particles over time")
        if self.kind == "stream":
            if self.region is None:
                raise ValueError("kind stream needs region: {box: [[x0,y0,z0],[x1,y1,z1]]} (where particles appear)")
            if (self.rate is None) == (self.mass_rate is None):
                raise ValueError("kind stream needs exactly one of rate [1/s] and mass_rate [kg/s]"
                                 + ("; remove one" if self.rate is not None else "; add one, e.g. rate: 1000"))
            if self.stop is not None and self.stop <= self.start:
                raise ValueError(f"stop ({self.stop:g} s) is not after start ({self.start:g} s); make stop > start")
            for key in ("positions", "velocities", "angular_velocities", "radii", "spacing", "jitter", "orientations",
                        "orientation"):
                if key in self.model_fields_set:
                    raise ValueError(f"kind stream does not use {key}; remove it")
        elif self.kind == "list":
            if not self.positions:
                raise ValueError("kind list needs positions: [[x,y,z], ...]")
            for key in ("velocities", "angular_velocities", "radii", "orientations"):
                values = getattr(self, key)
                if values is not None and len(values) != len(self.positions):
                    raise ValueError(f"{key} has {len(values)} entries but positions has {len(self.positions)}")
            if self.orientation is not None:
                raise ValueError("kind list takes orientations: (one per position), not orientation")
        else:
            if self.orientations is not None:
                raise ValueError(f"kind {self.kind} takes orientation: [w, x, y, z] (one for every clump), not "
                                 f"orientations")
            if self.region is None:
                raise ValueError(f"kind {self.kind} needs region: {{box: [[x0,y0,z0],[x1,y1,z1]]}}")
            if self.count is None:
                raise ValueError(f"kind {self.kind} needs count: the number of particles to insert")
        return self


class ClumpSphere(StrictModel):
    position: Vector3 = Field(description="the sphere's centre in the clump's own frame [m]")
    radius: PositiveFloat = Field(description="the sphere's radius [m]")


class ClumpConfig(StrictModel):
    spheres: Union[List[ClumpSphere], Annotated[int, Field(gt=0)]] = Field(
        description="the member spheres [{position: [x, y, z], radius: r}, ...] in the clump's frame [m]; with file: "
                    "how many spheres fill the surface (docs/shapes.md)")
    file: Optional[str] = Field(
        None, description="a closed surface (STL, .msh) the clump fills with `spheres` spheres, in its frame")
    scale: PositiveFloat = Field(
        1.0, description="file: factor applied to the surface's coordinates (e.g. 1e-3 for mm)")
    mass: Optional[PositiveFloat] = Field(
        None, description="the clump's mass [kg]; default: the union of its spheres at the material's density "
                          "(a given mass scales the inertia with it)")
    inertia: Optional[Union[Vector3, Tuple[Vector3, Vector3, Vector3]]] = Field(
        None, description="principal moments [I1, I2, I3] or a 3 x 3 tensor about the centre of mass in the clump "
                          "frame [kg m^2]; default: that of the union of its spheres")
    # The file resolved against the scene file's folder (set by pdemfem.scene.loader.load_scene).
    _resolved_file: Optional[str] = PrivateAttr(None)

    @model_validator(mode="after")
    def _one_source(self):
        if self.file is not None and not isinstance(self.spheres, int):
            raise ValueError("with file, spheres is the number of spheres that fill the surface (e.g. spheres: 8), "
                             "not a list")
        if self.file is None and isinstance(self.spheres, int):
            raise ValueError("spheres: a number needs file: (the surface to fill); without a file give the spheres "
                             "as [{position: [x, y, z], radius: r}, ...]")
        if self.file is None and not self.spheres:
            raise ValueError("spheres is empty: give at least one {position: [x, y, z], radius: r}")
        if self.file is None and "scale" in self.model_fields_set:
            raise ValueError("scale applies to file only; give the spheres in metres or use file:")
        return self


class ParticleGroupConfig(StrictModel):
    name: str = Field(description="unique group name")
    material: str = Field(description="a name under materials")
    radius: Optional[Union[PositiveFloat, RadiusRange]] = Field(
        None, description="one radius [m], or {min, max} for radii uniformly distributed between the two (spheres; "
                          "a clump group gives clump instead)")
    clump: Optional[ClumpConfig] = Field(
        None, description="the group's particles are rigid clumps of these spheres instead of single spheres "
                          "(docs/shapes.md); insertion positions are the clumps' centres of mass")
    insert: InsertConfig = Field(description="how the particles are placed at the start (or, kind stream, over time)")
    initial_temperature: Optional[PositiveFloat] = Field(
        None, description="starting temperature [K]; giving it switches heat on (docs/heat.md); with heat on "
                          "and no value: heat.default_temperature")

    @model_validator(mode="after")
    def _sphere_or_clump(self):
        if self.clump is None:
            if self.radius is None:
                raise ValueError("a particle group needs radius: [m] (spheres) or clump: {spheres: [...]} (clumps)")
            for key in ("orientations", "orientation"):
                if getattr(self.insert, key) is not None:
                    raise ValueError(f"insert.{key} is for clump groups (spheres have no orientation); remove it")
            return self
        if self.radius is not None:
            raise ValueError("a clump group takes its sizes from clump.spheres: remove radius")
        if self.insert.kind == "stream":
            raise ValueError("clump groups cannot be inserted by a stream yet; use kind list, lattice or random")
        if self.insert.radii is not None:
            raise ValueError("insert.radii does not apply to clumps (their spheres are given in clump.spheres); "
                             "remove it")
        return self


class CylinderAxis(StrictModel):
    point: Vector3 = Field((0.0, 0.0, 0.0), description="a point on the cylinder's axis [m]")
    direction: Vector3 = Field((0.0, 0.0, 1.0), description="axis direction (any length)")

    @field_validator("direction")
    @classmethod
    def _nonzero(cls, direction):
        if sum(c * c for c in direction) == 0.0:
            raise ValueError("direction must be a non-zero vector")
        return direction


# The keys each wall kind reads (besides name, kind, material, velocity); see docs/walls.md.
WALL_KIND_KEYS = {
    "plane": ("point", "normal", "temperature", "transport_velocity"),
    "mesh": ("file", "scale", "angular_velocity", "center", "one_sided", "smooth_angle", "temperature",
             "transport_velocity"),
    "cylinder": ("axis", "radius", "inside", "angular_velocity", "temperature"),
}


class WallConfig(StrictModel):
    """One wall: kind plane (analytic), mesh (triangle surface from a file) or cylinder (analytic)."""

    name: str = Field(description="unique wall name (history.csv columns force_<name>_x/_y/_z, wall_force(name))")
    kind: Literal["plane", "mesh", "cylinder"] = Field(
        description="plane: infinite analytic plane; mesh: triangle surface from a file; cylinder: analytic")
    material: str = Field(description="a name under materials (the contact uses the pair's interaction)")
    point: Vector3 = Field((0.0, 0.0, 0.0), description="a point on the plane [m]")
    normal: Vector3 = Field((0.0, 0.0, 1.0), description="plane normal pointing to the particles' side (any length)")
    velocity: Vector3 = Field((0.0, 0.0, 0.0), description="prescribed wall velocity [m/s]")
    temperature: Optional[PositiveFloat] = Field(
        None, description="fixed wall temperature [K]: touching particles exchange heat with it (switches heat on); "
                          "absent: the wall is adiabatic (docs/heat.md)")
    # kind: plane and mesh
    transport_velocity: Vector3 = Field(
        (0.0, 0.0, 0.0), description="conveyor: the surface moves with this velocity [m/s] (its part along the "
                                     "surface) while the geometry stays in place (docs/streams.md)")
    # kind: mesh
    file: Optional[str] = Field(None, description="surface mesh (STL, gmsh .msh, a gmsh .geo file meshed in 2-D "
                                                            "when the scene is read, or any meshio format), relative to the scene")
    scale: PositiveFloat = Field(1.0, description="factor applied to the file's coordinates (e.g. 0.001 for mm)")
    center: Vector3 = Field((0.0, 0.0, 0.0), description="rotation centre at t = 0 (moves with velocity) [m]")
    one_sided: bool = Field(False, description="contact only on the side the triangle normals point to")
    smooth_angle: Annotated[float, Field(ge=0, lt=90)] = Field(
        1.0, description="triangles meeting at less than this angle [deg] form one smooth patch (one contact)")
    # kind: mesh and cylinder
    angular_velocity: Vector3 = Field((0.0, 0.0, 0.0), description="rotation rate [rad/s] about center (mesh) or the axis point (cylinder)")
    # kind: cylinder
    axis: Optional[CylinderAxis] = None
    radius: Optional[PositiveFloat] = Field(None, description="cylinder radius [m]")
    inside: bool = Field(True, description="particles inside the cylinder (a drum or pipe); false: outside (a post)")

    @field_validator("normal")
    @classmethod
    def _nonzero(cls, normal):
        if sum(c * c for c in normal) == 0.0:
            raise ValueError("normal must be a non-zero vector")
        return normal

    @model_validator(mode="after")
    def _kind_keys(self):
        common = {"name", "kind", "material", "velocity"}
        foreign = sorted(key for key in self.model_fields_set
                         if key not in common and key not in WALL_KIND_KEYS[self.kind])
        if foreign:
            raise ValueError(f"kind {self.kind} does not use {', '.join(foreign)}; remove it "
                             f"(keys of kind {self.kind}: {', '.join(sorted(common) + list(WALL_KIND_KEYS[self.kind]))})")
        if self.kind == "mesh" and not self.file:
            raise ValueError("kind mesh needs file: the surface mesh (e.g. file: hopper.stl)")
        if self.kind == "cylinder":
            if self.radius is None:
                raise ValueError("kind cylinder needs radius: [m]")
            if self.axis is None:
                raise ValueError("kind cylinder needs axis: {point: [x, y, z], direction: [dx, dy, dz]}")
        return self


ParticleOutputField = Literal["positions", "velocities", "radii", "ids", "forces", "temperature",
                              "angular_velocities", "torques", "materials"]
SolidOutputField = Literal["displacements", "velocities", "von_mises", "temperature"]


# A directory key: "" would silently mean the current directory.
DirectoryName = Annotated[str, Field(min_length=1)]


class OutputConfig(StrictModel):
    dir: DirectoryName = Field("out", description="output directory, relative to the scene file (run -o overrides)")
    every: Optional[PositiveFloat] = Field(None, description="output interval [s]; default end/100")
    particles: List[ParticleOutputField] = Field(
        default_factory=lambda: ["positions", "velocities", "radii", "ids", "forces", "temperature"],
        description="per-particle fields written to <dir>/particles.h5 + .xdmf every interval; [] writes none")
    solids: List[SolidOutputField] = Field(
        default_factory=lambda: ["displacements", "velocities", "von_mises", "temperature"],
        description="fields of each solid written to <dir>/<solid>.h5 + .xdmf every interval; [] writes none")


class CheckpointConfig(StrictModel):
    every: Optional[PositiveFloat] = Field(
        None, description="checkpoint interval [s] (rounded to whole steps), and one at the end; none: only on SIGTERM/SIGUSR1")
    keep: Annotated[int, Field(ge=1)] = Field(2, description="newest checkpoints kept (older ones are deleted)")
    dir: Optional[DirectoryName] = Field(None, description="checkpoint directory; default <output dir>/checkpoints")


class NeighborConfig(StrictModel):
    skin: Optional[PositiveFloat] = Field(
        None, description="Verlet skin [m]; default 0.3 * smallest radius (larger: rarer rebuilds, longer lists)"
    )


class DomainConfig(StrictModel):
    box: Optional[Box] = Field(
        None, description="simulation domain [[xmin,ymin,zmin],[xmax,ymax,zmax]] [m]; particles leaving it are removed "
                          "and counted (lost_particles); needed for periodic axes")
    periodic: List[Literal["x", "y", "z"]] = Field(default_factory=list, description="periodic axes, e.g. [x]")

    @model_validator(mode="after")
    def _box_for_periodic(self):
        if self.periodic and self.box is None:
            raise ValueError("periodic axes need box: [[xmin,ymin,zmin],[xmax,ymax,zmax]] to set the period")
        return self


class OutletConfig(StrictModel):
    """A sink: particles whose centre crosses the plane (to the side the normal points to) or enters the box
    are removed and counted (history mass_out, mass_out_<name>; docs/streams.md)."""

    name: str = Field(description="unique outlet name (history column mass_out_<name>)")
    kind: Literal["plane", "box"] = Field(description="plane: a half-space beyond point along normal; box: a box")
    point: Optional[Vector3] = Field(None, description="plane: a point on the plane [m]")
    normal: Optional[Vector3] = Field(None, description="plane: points out of the simulation, into the removed side")
    box: Optional[Box] = Field(None, description="box: [[x0,y0,z0],[x1,y1,z1]] [m]: particles whose centre is "
                                                 "inside are removed")

    @model_validator(mode="after")
    def _kind_keys(self):
        used = {"plane": ("point", "normal"), "box": ("box",)}[self.kind]
        foreign = sorted(key for key in ("point", "normal", "box") if key in self.model_fields_set and key not in used)
        if foreign:
            raise ValueError(f"kind {self.kind} does not use {', '.join(foreign)}; remove it "
                             f"(keys of kind {self.kind}: name, kind, {', '.join(used)})")
        missing = [key for key in used if getattr(self, key) is None]
        if missing:
            example = {"point": "point: [0, 0, 0]", "normal": "normal: [0, 0, -1]",
                       "box": "box: [[x0,y0,z0],[x1,y1,z1]]"}
            raise ValueError(f"kind {self.kind} needs {', '.join(missing)} (e.g. "
                             f"{', '.join(example[key] for key in missing)})")
        if self.normal is not None and sum(c * c for c in self.normal) == 0.0:
            raise ValueError("normal must be a non-zero vector")
        return self


class ParallelConfig(StrictModel):
    rebalance_threshold: Annotated[float, Field(ge=1.0)] = Field(
        1.2, description="re-partition the particles when max/mean rank cost exceeds this (checked at list rebuilds)")


def _unknown_material(key: str, name: str, known) -> str:
    """'key: problem; fix' for a material name not under materials (a close name is suggested)."""
    close = difflib.get_close_matches(name, sorted(known), n=1)
    hint = f"did you mean '{close[0]}'? otherwise " if close else ""
    return f"{key}: unknown material '{name}'; {hint}define it under materials (known: {sorted(known)})"


class CouplingConfig(StrictModel):
    fem_every: Annotated[int, Field(ge=1)] = Field(
        1, description="advance the solids every k DEM steps with the mean load of those steps "
                       "(k x cheaper FE work; the surface lags up to k steps)")
    contact_modulus: Literal["combined", "particle"] = Field(
        "combined", description="E*, G* of particle-solid contacts: combined = both materials' compliance (the "
                                "contact law holds the solid's local Hertz deformation; right when the mesh is "
                                "coarser than the contact radius), particle = the particle's only (the FE mesh "
                                "supplies the solid's deformation; docs/coupling.md)")
    transfer: Literal["auto", "nearest", "blended"] = Field(
        "auto", description="the particle-solid contact's gap: nearest = the distance to the nearest surface "
                            "point, its force on that triangle's nodes; blended = a smooth blend of the facets "
                            "under the particle, its elastic force spread over their nodes (stable where the "
                            "surface dimples under the contact; docs/coupling.md); auto = blended for the solids "
                            "whose surface yields to a point load (S_n/(E l) > 0.5, as check reports), else nearest")


class HeatConfig(StrictModel):
    """Heat conduction through the contacts, and in the solids (docs/heat.md)."""

    enabled: Optional[bool] = Field(
        None, description="true/false switch heat on/off; absent: on when a particle group gives "
                          "initial_temperature, a wall gives temperature or a solid gives thermal (a scene without "
                          "heat allocates, computes and writes no temperatures)")
    default_temperature: PositiveFloat = Field(
        293.15, description="starting temperature [K] of the particle groups that give none, when heat is on")


class Scene(StrictModel):
    time: TimeConfig = Field(description="end time and time step")
    gravity: Vector3 = Field((0.0, 0.0, -9.81), description="gravitational acceleration [m/s^2]")
    materials: Dict[str, MaterialConfig] = Field(description="material name -> properties")
    interactions: Dict[str, InteractionConfig] = Field(
        default_factory=lambda: {"default": InteractionConfig()},
        description="contact laws: 'default' for every pair, 'a-b' for the pair of materials a and b")
    particles: List[ParticleGroupConfig] = Field(
        default_factory=list, description="particle groups, inserted in list order (ids follow that order)")
    walls: List[WallConfig] = Field(default_factory=list, description="rigid walls: plane, mesh, cylinder")
    outlets: List[OutletConfig] = Field(
        default_factory=list, description="sinks removing the particles that reach them (docs/streams.md)")
    output: OutputConfig = Field(default_factory=OutputConfig, description="history.csv and the XDMF series")
    checkpoint: CheckpointConfig = Field(default_factory=CheckpointConfig, description="restart files")
    neighbors: NeighborConfig = Field(default_factory=NeighborConfig, description="the Verlet neighbour list")
    domain: DomainConfig = Field(default_factory=DomainConfig, description="bounding box and periodic axes")
    parallel: ParallelConfig = Field(default_factory=ParallelConfig, description="load balance across ranks")
    solids: List[SolidConfig] = Field(default_factory=list, description="deformable FE solids (PETSc)")
    coupling: CouplingConfig = Field(default_factory=CouplingConfig, description="the DEM-FEM coupled step")
    heat: HeatConfig = Field(default_factory=HeatConfig, description="heat conduction (docs/heat.md)")

    @property
    def heat_enabled(self) -> bool:
        """Whether the scene conducts heat: heat.enabled, else whether a thermal key is given."""
        if self.heat.enabled is not None:
            return self.heat.enabled
        return (any(group.initial_temperature is not None for group in self.particles)
                or any(wall.temperature is not None for wall in self.walls)
                or any(getattr(solid, "thermal", None) is not None for solid in self.solids))

    @model_validator(mode="after")
    def _references(self):
        known = set(self.materials)
        for index, group in enumerate(self.particles):
            if group.material not in known:
                raise ValueError(_unknown_material(f"particles[{index}].material", group.material, known))
        for index, wall in enumerate(self.walls):
            if wall.material not in known:
                raise ValueError(_unknown_material(f"walls[{index}].material", wall.material, known))
        for key in self.interactions:
            if key == "default":
                continue
            names = key.split("-")
            if len(names) != 2 or any(name not in known for name in names):
                raise ValueError(
                    f"interactions.{key}: name 'default' or 'materialA-materialB' with known materials "
                    f"(known: {sorted(known)})"
                )
        for index, solid in enumerate(self.solids):
            if solid.material not in known:
                raise ValueError(_unknown_material(f"solids[{index}].material", solid.material, known))
        for kind, items in (("particles", self.particles), ("walls", self.walls), ("solids", self.solids),
                            ("outlets", self.outlets)):
            for index, item in enumerate(items):
                if not NAME_PATTERN.fullmatch(item.name):
                    raise ValueError(f"{kind}[{index}].name: {item.name!r} may hold only letters, digits, '_', '-' and "
                                     f"'.' (not first): it names history columns, and a solid's output files; rename it")
        for index, solid in enumerate(self.solids):
            if solid.name in SERIES_NAMES:
                raise ValueError(f"solids[{index}].name: '{solid.name}' is taken: {solid.name}.h5 and {solid.name}.xdmf "
                                 f"in the output directory hold the {solid.name} series, which the solid's would "
                                 f"overwrite; rename the solid")
        surface_names = [wall.name for wall in self.walls] + [solid.name for solid in self.solids]
        clashes = sorted({name for name in surface_names if surface_names.count(name) > 1})
        if clashes:
            raise ValueError(f"walls/solids: names {clashes} are used twice; wall and solid names share one "
                             f"namespace (wall_force, history columns): rename one")
        if self.heat_enabled:
            self._heat_materials()
            # heat_<name> is the heat wall or solid <name> gave the particles: these would read as heat_in, heat_out.
            carried = sorted(set(surface_names) & {"in", "out"})
            if carried:
                raise ValueError(f"walls/solids: with heat on the names {carried} are taken (history columns "
                                 f"heat_in and heat_out: heat the inserted particles brought in and the removed "
                                 f"ones took out); rename them")
        elif "temperature" in self.output.particles and "particles" in self.output.model_fields_set:
            raise ValueError("output.particles: temperature is written only with heat on; give a particle group "
                             "initial_temperature (or heat: {enabled: true}), or remove temperature from the list")
        clump_groups = [index for index, group in enumerate(self.particles) if group.clump is not None]
        if clump_groups and self.outlets:
            raise ValueError(f"particles[{clump_groups[0]}].clump: outlets cannot take clumps yet (an outlet removes "
                             f"single spheres); remove outlets or use spheres")
        if clump_groups and self.domain.periodic:
            raise ValueError(f"particles[{clump_groups[0]}].clump: clumps in a periodic domain are not supported yet; "
                             f"remove domain.periodic or use spheres")
        for kind, items in (("particles", self.particles), ("walls", self.walls), ("outlets", self.outlets)):
            names = [item.name for item in items]
            duplicates = sorted({name for name in names if names.count(name) > 1})
            if duplicates:
                raise ValueError(f"{kind}: duplicate names {duplicates}; give each entry its own name")
        return self

    def _heat_materials(self) -> None:
        """With heat on, every body that exchanges heat needs the material keys its law reads."""
        needs = {}  # material -> (keys, who)
        for index, group in enumerate(self.particles):
            needs.setdefault(group.material, [set(), f"particles[{index}]"])[0].update(("conductivity", "heat_capacity"))
        for index, wall in enumerate(self.walls):
            if wall.temperature is not None:
                needs.setdefault(wall.material, [set(), f"walls[{index}]"])[0].add("conductivity")
        for name, (keys, who) in needs.items():
            missing = sorted(key for key in keys if getattr(self.materials[name], key) is None)
            if missing:
                raise ValueError(f"materials.{name}: heat is on and {who} uses this material, which lacks "
                                 f"{' and '.join(missing)}; give {', '.join(f'{key}: ...' for key in missing)} "
                                 f"(units in docs/heat.md), or switch heat off with heat: {{enabled: false}}")

    def interaction(self, material_a: str, material_b: str) -> InteractionConfig:
        """The interaction for a pair of materials: 'a-b' or 'b-a', else 'default'."""
        for key in (f"{material_a}-{material_b}", f"{material_b}-{material_a}", "default"):
            if key in self.interactions:
                return self.interactions[key]
        return InteractionConfig()
