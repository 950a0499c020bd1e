"""The packed per-row-pair coefficient table the contact kernels read, built once per scene.

Kernels index ``coefficients[a, b, column]`` by the two rows of a contact (columns:
pdemfem.contact.layout), so no physics constant is recomputed per contact except what
depends on the overlap.  Each sub-model fills its own parameter block (its `parameters`).

Rows are the scene's materials, in scene order, followed -- with
`coupling.contact_modulus: particle` -- by one row per deformable solid's contact
surface.  Such a row carries the solid's material for the interaction
(restitution, friction) but not its compliance: a particle touching that surface
gets E*, G* of the particle's material alone, because the FE mesh already deforms
under the contact (docs/coupling.md, "Contact modulus of a deformable solid").
With `combined` (the default) a solid's surface uses its material's row, whose
E*, G* hold both materials' compliance, as for a rigid wall.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pdemfem.contact import conduction, damping_viscous, layout
from pdemfem.contact.registry import NORMAL_BY_NAME, ROLLING_BY_NAME, history_layout, normal_bit, rolling_bit


@dataclass
class ContactTables:
    material_names: list                 # row names: the materials, then any solid-surface rows
    coefficients: np.ndarray             # (rows, rows, layout.COLUMNS)
    composition: int                     # the sub-models in use (layout bits): what the kernels run
    characteristic_speed: float          # impact speed that defines a derived linear stiffness
    solid_surface_rows: dict = field(default_factory=dict)  # solid name -> its own row (contact_modulus particle)

    # Views of single columns, for code and tests that read one constant.
    @property
    def effective_modulus(self) -> np.ndarray:
        return self.coefficients[:, :, layout.EFFECTIVE_MODULUS]

    @property
    def effective_shear_modulus(self) -> np.ndarray:
        return self.coefficients[:, :, layout.EFFECTIVE_SHEAR_MODULUS]

    @property
    def damping_coefficient(self) -> np.ndarray:
        return self.coefficients[:, :, layout.DAMPING]

    @property
    def friction(self) -> np.ndarray:
        return self.coefficients[:, :, layout.FRICTION]

    @property
    def rolling_friction(self) -> np.ndarray:
        return self.coefficients[:, :, layout.ROLLING_FRICTION]

    @property
    def cohesion_reach(self) -> float:
        """The largest distance beyond touching at which some pair still interacts [m] (0: none)."""
        return float(self.coefficients[:, :, layout.COHESION_REACH].max()) if self.coefficients.size else 0.0

    @property
    def history_width(self) -> int:
        """Columns of one contact's history (tangential spring, rolling spring, touching flag)."""
        return int(history_layout(self.composition)[3])

    def surface_row(self, solid_name: str, material: str) -> int:
        """The row a solid's contact surface uses: its own row with contact_modulus particle, else its material's."""
        return self.solid_surface_rows.get(solid_name, self.material_names.index(material))


def _compliances(material) -> tuple:
    """Normal and tangential Hertz-Mindlin compliances of one body: (1 - nu^2) / E and 2 (2 - nu)(1 + nu) / E."""
    e, nu = material.youngs_modulus, material.poisson_ratio
    return (1.0 - nu * nu) / e, 2.0 * (2.0 - nu) * (1.0 + nu) / e


def build_contact_tables(scene, characteristic_speed: float, largest_radius: float = 0.0) -> ContactTables:
    """The packed table of `scene`; `largest_radius` [m] bounds the reach of cohesive pairs.  With heat on
    (scene.heat_enabled) every contact also conducts (pdemfem.contact.conduction)."""
    heat = scene.heat_enabled
    # Each row: (name, material name for the interaction, does the row's body add its compliance to E*, G*).
    rows = [(name, name, True) for name in scene.materials]
    surface_rows = {}
    if scene.coupling.contact_modulus == "particle":
        for solid in scene.solids:
            if solid.contact:
                surface_rows[solid.name] = len(rows)
                rows.append((f"{solid.material} (surface of solid {solid.name})", solid.material, False))
    count = len(rows)
    coefficients = np.zeros((count, count, layout.COLUMNS))
    composition = 0
    for a, (_, name_a, compliant_a) in enumerate(rows):
        for b, (_, name_b, compliant_b) in enumerate(rows):
            interaction = scene.interaction(name_a, name_b)
            # Two surface rows never touch each other (surfaces contact particles only); they keep the
            # combined value so every entry stays finite.
            surfaces_only = not (compliant_a or compliant_b)
            compliance = shear_compliance = 0.0
            for name, compliant in ((name_a, compliant_a), (name_b, compliant_b)):
                if compliant or surfaces_only:
                    normal, tangential = _compliances(scene.materials[name])
                    compliance += normal
                    shear_compliance += tangential
            normal_model = NORMAL_BY_NAME[interaction.model]
            row = coefficients[a, b]
            row[layout.EFFECTIVE_MODULUS] = 1.0 / compliance
            row[layout.EFFECTIVE_SHEAR_MODULUS] = 1.0 / shear_compliance
            row[layout.NORMAL_MODEL] = normal_model.CODE
            row[layout.DAMPING] = damping_viscous.coefficient(normal_model.DAMPING_LAW, interaction.restitution)
            row[layout.FRICTION] = interaction.friction
            row[layout.ROLLING_FRICTION] = interaction.rolling_friction
            parameters = normal_model.parameters(interaction, row[layout.EFFECTIVE_MODULUS], characteristic_speed)
            assert len(parameters) <= layout.NORMAL_PARAMETER_COUNT
            row[layout.NORMAL_PARAMETERS:layout.NORMAL_PARAMETERS + len(parameters)] = parameters
            composition |= normal_bit(normal_model)
            if heat:
                row[layout.CONTACT_CONDUCTIVITY] = conduction.pair_conductivity(
                    scene.materials[name_a].conductivity, scene.materials[name_b].conductivity)
            if normal_model.COHESIVE:
                composition |= layout.COHESIVE
                # Without a radius (tables built for their composition or width alone) there is no reach.
                row[layout.COHESION_REACH] = normal_model.pull_off_distance(
                    row[layout.NORMAL_PARAMETERS:], row[layout.EFFECTIVE_MODULUS], largest_radius) \
                    if largest_radius > 0.0 else 0.0
            if interaction.friction > 0.0:
                composition |= layout.TANGENTIAL
            if interaction.rolling_friction > 0.0:
                rolling_model = ROLLING_BY_NAME[interaction.rolling_model]
                row[layout.ROLLING_MODEL] = rolling_model.CODE
                rolling_parameters = rolling_model.parameters(interaction)
                assert len(rolling_parameters) <= layout.ROLLING_PARAMETER_COUNT
                row[layout.ROLLING_PARAMETERS:layout.ROLLING_PARAMETERS + len(rolling_parameters)] = rolling_parameters
                composition |= rolling_bit(rolling_model)
    if heat:
        composition |= layout.HEAT
    return ContactTables(material_names=[row[0] for row in rows], coefficients=coefficients,
                         composition=int(composition), characteristic_speed=float(characteristic_speed),
                         solid_surface_rows=surface_rows)
