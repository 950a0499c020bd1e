"""Scene keys of one deformable solid (one entry of the scene's `solids:` list).

Key names are a public contract: add keys, never rename them.  The meaning and
cost of every knob is documented in docs/fem.md.
"""
from __future__ import annotations

from typing import Annotated, Dict, List, Literal, Optional, Tuple, Union

from pydantic import AfterValidator, Field, field_validator, model_validator

from pdemfem.config_types import Box, NonNegativeFloat, PositiveFloat, StrictModel, Vector3

BOX_FACES = ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")

# A vector whose null components are left free: [0, null, null] is a roller
# that holds x and lets y and z move.
PartialVector3 = Tuple[Optional[float], Optional[float], Optional[float]]
CellCount = Annotated[int, Field(gt=0)]


class BoxMeshConfig(StrictModel):
    """A box [[x0,y0,z0],[x1,y1,z1]] split into nx*ny*nz hexahedra of 6 tetrahedra each (gmsh)."""

    box: Box = Field(description="[[x0,y0,z0],[x1,y1,z1]] [m]")
    cells: Tuple[CellCount, CellCount, CellCount] = Field(description="hexahedra along x, y and z (6 tetrahedra each)")


class DampingConfig(StrictModel):
    """Rayleigh damping C = alpha M + beta K."""

    alpha: NonNegativeFloat = Field(0.0, description="mass-proportional coefficient [1/s]")
    beta: NonNegativeFloat = Field(0.0, description="stiffness-proportional coefficient [s]")


class PrescribedConfig(StrictModel):
    """Prescribed motion of a group: constant velocity or constant displacement (null = free component)."""

    group: str = Field(description="a physical group of the mesh, a box face xmin..zmax, or a region")
    velocity: Optional[PartialVector3] = Field(None, description="constant velocity [m/s]; null components are free")
    displacement: Optional[PartialVector3] = Field(
        None, description="constant displacement [m]; null components are free")

    @model_validator(mode="after")
    def _one_kind(self):
        if (self.velocity is None) == (self.displacement is None):
            raise ValueError(f"prescribed group '{self.group}': give exactly one of velocity: [...] or displacement: [...]")
        values = self.velocity if self.velocity is not None else self.displacement
        if all(v is None for v in values):
            raise ValueError(f"prescribed group '{self.group}': every component is null; prescribe at least one")
        return self


class TractionConfig(StrictModel):
    """A uniform surface traction (force per area, global axes) [Pa] on a boundary group."""

    group: str = Field(description="a boundary group of the mesh, or a box face xmin..zmax")
    traction: Vector3 = Field(description="force per area in global axes [Pa]")


class PointForceConfig(StrictModel):
    """A constant force [N] on the mesh node nearest to `point`."""

    point: Vector3 = Field(description="the force acts on the mesh node nearest to this point [m]")
    force: Vector3 = Field(description="constant force [N]")


class FixedTemperatureConfig(StrictModel):
    """A group held at a constant temperature (Dirichlet)."""

    group: str = Field(description="a boundary group of the mesh, or a box face xmin..zmax")
    temperature: PositiveFloat = Field(description="the group's temperature [K]")


class HeatFluxConfig(StrictModel):
    """A uniform heat flux through a surface group."""

    group: str = Field(description="a boundary group of the mesh, or a box face xmin..zmax")
    flux: float = Field(description="heat flux into the solid [W/m^2] (negative: out of it)")


class ConvectionConfig(StrictModel):
    """Newton cooling of a surface group: heat flux h (T_ambient - T) into the solid."""

    group: str = Field(description="a boundary group of the mesh, or a box face xmin..zmax")
    coefficient: NonNegativeFloat = Field(description="heat transfer coefficient h [W/(m^2 K)]")
    ambient: PositiveFloat = Field(description="ambient temperature [K]")


class ThermalConfig(StrictModel):
    """Transient heat conduction rho c dT/dt = div(k grad T) in the solid (material conductivity, heat_capacity)."""

    scheme: Literal["explicit", "implicit"] = Field(
        "explicit", description="explicit: lumped capacity, forward Euler, sub-stepped below its stability limit; "
                                "implicit: theta-scheme, one CG solve per advance")
    theta: Annotated[float, Field(ge=0.5, le=1.0)] = Field(
        1.0, description="implicit only: 1 = backward Euler (1st order, monotone), 0.5 = Crank-Nicolson "
                         "(2nd order, oscillates for steps far above the explicit limit)")
    fixed: List[FixedTemperatureConfig] = Field(default_factory=list, description="groups held at a temperature (Dirichlet)")
    flux: List[HeatFluxConfig] = Field(default_factory=list, description="surface groups with a uniform heat flux into the solid")
    convection: List[ConvectionConfig] = Field(
        default_factory=list, description="convective surface groups (Newton cooling toward an ambient temperature)")

    def groups(self) -> List[Tuple[str, int, str]]:
        """(kind, index, group) of every boundary entry, in the order fixed, flux, convection."""
        return [(kind, index, entry.group) for kind in ("fixed", "flux", "convection")
                for index, entry in enumerate(getattr(self, kind))]


def _region_box(box):
    low, high = box
    if any(h < l for l, h in zip(low, high)):
        raise ValueError("a region box must be [[xmin,ymin,zmin],[xmax,ymax,zmax]] with every max >= min "
                         "(max = min selects a plane of nodes)")
    return box


# A region's box may be flat (max = min on an axis): the nodes on a plane, a line or a point.
RegionBox = Annotated[Tuple[Vector3, Vector3], AfterValidator(_region_box)]


class CylinderRegionConfig(StrictModel):
    """An infinite cylinder: the points within `radius` of the line through `point` along `direction`."""

    point: Vector3 = Field(description="a point on the cylinder's axis [m]")
    direction: Vector3 = Field(description="the axis direction (any length, not zero)")
    radius: PositiveFloat = Field(description="the cylinder's radius [m]")

    @field_validator("direction")
    @classmethod
    def _nonzero(cls, value):
        if not any(value):
            raise ValueError("the cylinder's direction is the zero vector; give the axis direction, e.g. [0, 1, 0]")
        return value


class RegionConfig(StrictModel):
    """A node group chosen by a region of space: exactly one of box or cylinder (docs/fem.md)."""

    box: Optional[RegionBox] = Field(
        None, description="[[x0,y0,z0],[x1,y1,z1]]: the nodes inside this box [m] (may be flat: x0 = x1 is a plane)")
    cylinder: Optional[CylinderRegionConfig] = Field(None, description="the nodes inside this infinite cylinder")

    @model_validator(mode="after")
    def _one_shape(self):
        if (self.box is None) == (self.cylinder is None):
            raise ValueError("give exactly one of box: [[x0,y0,z0],[x1,y1,z1]] or cylinder: {point, direction, radius}")
        return self


class MotionConfig(StrictModel):
    """A prescribed rigid motion carrying the solid (rotation about an axis plus translation, both constant);
    the solid deforms elastically (small strain) relative to this moving frame (docs/fem.md)."""

    axis_point: Vector3 = Field(description="a point of the rotation axis at t = 0 [m] (e.g. the wheel's hub centre)")
    angular_velocity: Vector3 = Field(
        (0.0, 0.0, 0.0), description="rotation vector [rad/s]: the axis direction times the spin rate (right-handed)")
    velocity: Vector3 = Field((0.0, 0.0, 0.0), description="translation velocity of the axis [m/s]")
    start: NonNegativeFloat = Field(
        0.0, description="time [s] the motion begins: before it the solid rests at its mesh position (no spin, "
                         "the axis held), e.g. while a bed settles; then it starts at full speed")
    carried_mass: Optional[PositiveFloat] = Field(
        None, description="free sinkage: the axis moves freely along z (its z velocity starts at velocity[2]) "
                          "carrying this mass [kg] (the wheel's own and its load: weight carried_mass x |g|) "
                          "against the particles' forces; absent: the axis follows `velocity` exactly")


class SolidConfig(StrictModel):
    name: str = Field(description="unique solid name (shares one namespace with the walls)")
    mesh: Union[str, BoxMeshConfig] = Field(
        description="gmsh .msh, or a gmsh .geo file (meshed in 3-D when the scene is read), or any meshio-readable "
                    "tetrahedral mesh, relative to the scene file; or a generated box"
    )
    material: str = Field(description="a name under materials")
    element: Literal["P1", "P2"] = Field("P1", description="linear (P1) or quadratic (P2) tetrahedra")
    mass: Literal["lumped", "consistent"] = Field(
        "lumped", description="lumped: diagonal mass, no solve per step; consistent: a mass solve per step")
    damping: DampingConfig = Field(default_factory=DampingConfig, description="Rayleigh damping")
    regions: Dict[str, RegionConfig] = Field(
        default_factory=dict, description="named node groups chosen by a box or cylinder, usable under fixed and "
                                          "prescribed (the nodes within 1e-3 x the shortest edge of the region)")
    fixed: List[str] = Field(default_factory=list, description="groups, box faces (xmin..zmax) or regions clamped in x, y and z")
    prescribed: List[PrescribedConfig] = Field(default_factory=list, description="groups with prescribed motion")
    contact: List[str] = Field(default_factory=list, description="surface groups that particles may touch")
    transport_velocity: Vector3 = Field(
        (0.0, 0.0, 0.0), description="conveyor: the contact surface's material moves with this velocity [m/s] "
                                     "(its part along the contact's tangent plane) while the mesh stays")
    motion: Optional[MotionConfig] = Field(
        None, description="prescribed rigid motion (rotation + translation) the solid deforms relative to "
                          "(a rolling wheel or tread); needs mass: lumped")
    tractions: List[TractionConfig] = Field(default_factory=list, description="constant surface tractions")
    point_forces: List[PointForceConfig] = Field(default_factory=list, description="constant nodal forces")
    initial_temperature: Optional[PositiveFloat] = Field(
        None, description="uniform initial temperature [K]; default: the reference temperature (no thermal load)"
    )
    reference_temperature: Optional[PositiveFloat] = Field(
        None, description="stress-free temperature T0 [K]; default: the initial temperature"
    )
    thermal: Optional[ThermalConfig] = Field(
        None, description="heat conduction in the solid and its boundary conditions; absent: the temperature "
                          "stays as set (unless the scene's heat switch is on)")

    @model_validator(mode="after")
    def _distinct_groups(self):
        prescribed = [entry.group for entry in self.prescribed]
        clash = sorted(set(self.fixed) & set(prescribed))
        if clash:
            raise ValueError(f"groups {clash} are both fixed and prescribed; keep each group in one list")
        if self.motion is not None:
            if self.mass != "lumped":
                raise ValueError("motion: needs mass: lumped (the frame's inertial forces are applied per node with "
                                 "the lumped mass); set mass: lumped")
            if any(self.transport_velocity):
                raise ValueError("motion: and transport_velocity: cannot be combined (the moving frame already moves "
                                 "the surface); remove transport_velocity")
        faces = sorted(set(self.regions) & set(BOX_FACES))
        if faces:
            raise ValueError(f"regions {faces} are named like box faces; choose another name")
        # A region is a set of nodes: loads per area and contact need the faces of a surface group.
        surface_keys = [(f"tractions[{i}].group", t.group) for i, t in enumerate(self.tractions)]
        surface_keys += [(f"contact[{i}]", group) for i, group in enumerate(self.contact)]
        if self.thermal is not None:
            surface_keys += [(f"thermal.{kind}[{i}].group", group) for kind, i, group in self.thermal.groups()]
        for key, group in surface_keys:
            if group in self.regions:
                raise ValueError(f"{key}: '{group}' is a region (a set of nodes); tractions, contact and thermal "
                                 "boundaries need a surface group of the mesh (a gmsh physical group or a box face)")
        return self

    def temperatures(self) -> Tuple[Optional[float], Optional[float]]:
        """(initial, reference) temperatures with the documented defaults (None, None: no thermal load)."""
        initial = self.initial_temperature
        reference = self.reference_temperature
        if initial is None:
            initial = reference
        if reference is None:
            reference = initial
        return initial, reference
