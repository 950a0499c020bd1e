"""Per-material-pair contact constants, precomputed once into small tables.

Kernels index these tables by the two materials of a contact, so no physics
constant is recomputed per contact except what depends on the overlap.

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

from pdemfem.contact.restitution import normal_damping_coefficient

MODEL_CODES = {"hertz_mindlin": 0, "linear_spring_dashpot": 1}


@dataclass
class ContactTables:
    material_names: list                 # row names: the materials, then any solid-surface rows
    effective_modulus: np.ndarray        # E*  [Pa]
    effective_shear_modulus: np.ndarray  # G*  [Pa]
    damping_coefficient: np.ndarray      # gamma: calibrated so the rebound ratio equals `restitution`
    friction: np.ndarray                 # mu (Coulomb)
    rolling_friction: np.ndarray         # mu_r (constant directional torque)
    model_code: np.ndarray               # 0 Hertz-Mindlin, 1 linear spring-dashpot
    normal_stiffness: np.ndarray         # linear model: k_n [N/m]; 0 = derive per contact
    tangential_ratio: np.ndarray         # linear model: k_t / k_n
    characteristic_speed: float          # impact speed that defines a derived linear stiffness
    solid_surface_rows: dict = field(default_factory=dict)  # solid name -> its own row (contact_modulus particle)

    @property
    def rolling_enabled(self) -> bool:
        return bool(np.any(self.rolling_friction > 0.0))

    def surface_row(self, solid_name: str, material: str) -> int:
        """The row a solid's contact surface uses: its own row with contact_modulus particle, else its material's."""
        return self.solid_surface_rows.get(solid_name, self.material_names.index(material))


def _compliances(material) -> tuple:
    """Normal and tangential Hertz-Mindlin compliances of one body: (1 - nu^2) / E and 2 (2 - nu)(1 + nu) / E."""
    e, nu = material.youngs_modulus, material.poisson_ratio
    return (1.0 - nu * nu) / e, 2.0 * (2.0 - nu) * (1.0 + nu) / e


def build_contact_tables(scene, characteristic_speed: float) -> ContactTables:
    # Each row: (name, material name for the interaction, does the row's body add its compliance to E*, G*).
    rows = [(name, name, True) for name in scene.materials]
    surface_rows = {}
    if scene.coupling.contact_modulus == "particle":
        for solid in scene.solids:
            if solid.contact:
                surface_rows[solid.name] = len(rows)
                rows.append((f"{solid.material} (surface of solid {solid.name})", solid.material, False))
    count = len(rows)
    shape = (count, count)
    tables = ContactTables(
        material_names=[row[0] for row in rows],
        effective_modulus=np.zeros(shape),
        effective_shear_modulus=np.zeros(shape),
        damping_coefficient=np.zeros(shape),
        friction=np.zeros(shape),
        rolling_friction=np.zeros(shape),
        model_code=np.zeros(shape, dtype=np.int32),
        normal_stiffness=np.zeros(shape),
        tangential_ratio=np.zeros(shape),
        characteristic_speed=float(characteristic_speed),
        solid_surface_rows=surface_rows,
    )
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
            tables.effective_modulus[a, b] = 1.0 / compliance
            tables.effective_shear_modulus[a, b] = 1.0 / shear_compliance
            tables.damping_coefficient[a, b] = normal_damping_coefficient(interaction.model, interaction.restitution)
            tables.friction[a, b] = interaction.friction
            tables.rolling_friction[a, b] = interaction.rolling_friction
            tables.model_code[a, b] = MODEL_CODES[interaction.model]
            tables.normal_stiffness[a, b] = interaction.normal_stiffness or 0.0
            tables.tangential_ratio[a, b] = interaction.tangential_stiffness_ratio
    return tables
