"""The shape of a scene's clump group: member spheres, mass properties, what the step and dt need.

    spheres = clump_spheres(group.clump)                 # (centres (n, 3), radii (n,)), clump frame
    template = clump_template(group.clump, density, where="particles[0].clump")

A template holds what every clump of the group shares: the members relative to the centre of
mass in the body principal frame (what pdemfem.clumps.rigid_body takes), the mass, the principal
moments, the rotation principal frame -> clump frame, the bounding radius about the centre of mass,
each member's mass share and the smallest effective mass a contact on a member can meet.

Member mass shares: the body's mass split in proportion to the members' sphere volumes r^3 (they
add up to the body's mass).  A member's row in the particle state carries its share as its mass:
the contact laws take it as the member's mass in the effective mass of the damping, and the heat
content m c T of the members adds up to the body's.  A clump resting on k equal members carries
a share per contact, so a symmetric clump landing flat on its members bounces with the asked
restitution (tests/test_clumps_system.py); a one-sphere clump's share is its whole mass, as a sphere's.

Smallest effective mass: a contact force along the unit normal n through a member centre (lever
o, the member's offset from the centre of mass) accelerates the contact point as a mass
m_eff = 1 / (1/M + (o x n)^T I^-1 (o x n)); its minimum over n is 1 / (1/M + lambda_max(A)),
A = [o]x^T I^-1 [o]x.  The time step takes the smaller of that and the member's share
(pdemfem.scene.derived), so the contact is resolved on the lightest mass it can act on.

Results are cached per (clump keys, density): a group's shape is computed (a file filled) once.
"""
from __future__ import annotations

import functools
import json
from dataclasses import dataclass

import numpy as np

from pdemfem.clumps.shape import sphere_union_mass_properties


@dataclass(frozen=True)
class ClumpTemplate:
    member_offsets: np.ndarray        # (n, 3) member centres - centre of mass, body principal frame
    member_radii: np.ndarray          # (n,)
    member_mass: np.ndarray           # (n,) mass shares, sum = mass
    mass: float
    principal_moments: np.ndarray     # (3,)
    principal_orientation: np.ndarray  # (4,) body principal frame -> clump frame
    center_of_mass: np.ndarray        # (3,) clump frame
    extent: float                     # bounding radius about the centre of mass: max |offset| + r
    smallest_effective_mass: float    # smallest m_eff of a contact on a member (module docstring)
    method: str                       # how the mass properties were computed


def _key(clump) -> str:
    return json.dumps([clump.model_dump(mode="json"), clump._resolved_file], sort_keys=True)


def clump_spheres(clump):
    """(centres (n, 3), radii (n,)) of a clump's members in its own frame (a file is filled, cached)."""
    return _spheres(_key(clump))


@functools.lru_cache(maxsize=64)
def _spheres(key: str):
    keys, resolved = json.loads(key)
    if keys.get("file") is None:
        centres = np.array([sphere["position"] for sphere in keys["spheres"]], dtype=np.float64).reshape(-1, 3)
        radii = np.array([sphere["radius"] for sphere in keys["spheres"]], dtype=np.float64)
        return centres, radii
    from pdemfem.clumps.fill import fill_surface_file

    fill = fill_surface_file(resolved or keys["file"], int(keys["spheres"]), scale=float(keys["scale"]))
    return np.asarray(fill.positions, dtype=np.float64), np.asarray(fill.radii, dtype=np.float64)


def clump_template(clump, density: float, where: str = "clump") -> ClumpTemplate:
    """The group's ClumpTemplate (module docstring); SceneError naming `where` for an impossible inertia."""
    return _template(_key(clump), float(density), where)


@functools.lru_cache(maxsize=64)
def _template(key: str, density: float, where: str) -> ClumpTemplate:
    keys, _ = json.loads(key)
    centres, radii = _spheres(key)
    inertia = keys.get("inertia")
    properties = sphere_union_mass_properties(centres, radii, density, mass=keys.get("mass"),
                                              inertia=None if inertia is None else np.asarray(inertia, dtype=float),
                                              where=where)
    offsets = properties.member_offsets(centres)
    volumes = radii ** 3
    shares = properties.mass * (volumes / volumes.sum())
    extent = float(np.max(np.linalg.norm(offsets, axis=1) + radii))
    inverse_inertia = np.diag(1.0 / properties.principal_moments)
    smallest = np.inf
    for offset in offsets:
        cross = np.array([[0.0, -offset[2], offset[1]], [offset[2], 0.0, -offset[0]], [-offset[1], offset[0], 0.0]])
        largest = float(np.linalg.eigvalsh(cross.T @ inverse_inertia @ cross).max())
        smallest = min(smallest, 1.0 / (1.0 / properties.mass + max(largest, 0.0)))
    return ClumpTemplate(np.ascontiguousarray(offsets), radii.copy(), shares, float(properties.mass),
                         np.asarray(properties.principal_moments, dtype=float).copy(),
                         np.asarray(properties.principal_orientation, dtype=float).copy(),
                         np.asarray(properties.center_of_mass, dtype=float).copy(), extent, float(smallest),
                         properties.method)
