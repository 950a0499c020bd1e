"""Per-material-pair contact constants, precomputed once into small tables.

Kernels index these tables by the two materials of a contact, so no physics
constant is recomputed per contact except what depends on the overlap.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pdemfem.contact.restitution import normal_damping_coefficient

MODEL_CODES = {"hertz_mindlin": 0, "linear_spring_dashpot": 1}


@dataclass
class ContactTables:
    material_names: list
    effective_modulus: np.ndarray        # E*  [Pa]
    effective_shear_modulus: np.ndarray  # G*  [Pa]
    damping_coefficient: np.ndarray      # gamma: calibrated so the rebound ratio equals `restitution`
    friction: np.ndarray                 # mu (Coulomb)
    rolling_friction: np.ndarray         # mu_r (constant directional torque)
    model_code: np.ndarray               # 0 Hertz-Mindlin, 1 linear spring-dashpot
    normal_stiffness: np.ndarray         # linear model: k_n [N/m]; 0 = derive per contact
    tangential_ratio: np.ndarray         # linear model: k_t / k_n
    characteristic_speed: float          # impact speed that defines a derived linear stiffness

    @property
    def rolling_enabled(self) -> bool:
        return bool(np.any(self.rolling_friction > 0.0))


def build_contact_tables(scene, characteristic_speed: float) -> ContactTables:
    names = list(scene.materials)
    count = len(names)
    shape = (count, count)
    tables = ContactTables(
        material_names=names,
        effective_modulus=np.zeros(shape),
        effective_shear_modulus=np.zeros(shape),
        damping_coefficient=np.zeros(shape),
        friction=np.zeros(shape),
        rolling_friction=np.zeros(shape),
        model_code=np.zeros(shape, dtype=np.int32),
        normal_stiffness=np.zeros(shape),
        tangential_ratio=np.zeros(shape),
        characteristic_speed=float(characteristic_speed),
    )
    for a, name_a in enumerate(names):
        material_a = scene.materials[name_a]
        for b, name_b in enumerate(names):
            material_b = scene.materials[name_b]
            interaction = scene.interaction(name_a, name_b)
            compliance = 0.0
            shear_compliance = 0.0
            for material in (material_a, material_b):
                e, nu = material.youngs_modulus, material.poisson_ratio
                compliance += (1.0 - nu * nu) / e
                shear_compliance += 2.0 * (2.0 - nu) * (1.0 + nu) / e
            tables.effective_modulus[a, b] = 1.0 / compliance
            tables.effective_shear_modulus[a, b] = 1.0 / shear_compliance
            tables.damping_coefficient[a, b] = normal_damping_coefficient(interaction.model, interaction.restitution)
            tables.friction[a, b] = interaction.friction
            tables.rolling_friction[a, b] = interaction.rolling_friction
            tables.model_code[a, b] = MODEL_CODES[interaction.model]
            tables.normal_stiffness[a, b] = interaction.normal_stiffness or 0.0
            tables.tangential_ratio[a, b] = interaction.tangential_stiffness_ratio
    return tables
