"""Analytic cylinder walls (infinite length): particles inside (drum, pipe) or outside (post, roller).

Geometry per particle: rho = radial part of (x - axis point); inside, the gap to
the surface is R - |rho| and the normal points to the axis; outside, the gap is
|rho| - R and the normal points away from it.  The contact law is the shared one
(pdemfem.contact.forces.contact_response) with the wall as a flat rigid body
(R = inf, m = inf, the convention plane walls use): the curvature of the
cylinder is ignored in R*, which is accurate when R >> r (a drum) and
underestimates the stiffness of an outside contact with a thin post.

Motion: the axis point moves with `velocity`; `angular_velocity` rotates the
surface about the axis point (parallel to the axis: a rotating drum whose surface
drags the particles; otherwise the axis direction turns too).  The contact's
relative velocity uses the surface velocity v + w x (q - axis point) at the
contact point q.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from pdemfem import state_dict as kinds
from pdemfem.contact.conduction import contact_conductance
from pdemfem.contact.layout import COHESIVE, HEAT
from pdemfem.contact.response import (add_particle_loads, cohesive_contact_holds, released_energy,
                                      rigid_wall_contact)
from pdemfem.walls.base import ContributorWall, rotation_matrix


@njit(cache=True)
def cylinder_forces(first, last, point, direction, cylinder_radius, inside, velocity, angular_velocity,
                    wall_row, history, positions, velocities, angular_velocities, radii, mass, inverse_inertia,
                    material_index, coefficients, composition, dt, forces, torques, totals, temperatures, heat_flows,
                    wall_temperature):
    """Add the cylinder's contact forces on particles [first, last); history (count, 1, width + 1) per
    particle: the contact history, then the last step's overlap.  With heat on and a wall temperature
    (not NaN), the contacts conduct (heat_flows: pdemfem.particles.heat).

    Returns (elastic, dissipated, contacts, work done on the particles, heat [J] given to them)."""
    overlap_column = history.shape[2] - 1
    # One row per particle (a view per particle in the loop would cost reference counting every step).
    rows = history.reshape(history.shape[0], history.shape[2])
    elastic_total = 0.0
    dissipated_total = 0.0
    work = 0.0
    heat = 0.0
    conducting = (composition & HEAT) != 0 and wall_temperature == wall_temperature
    contacts = 0
    ex = direction[0]
    ey = direction[1]
    ez = direction[2]
    for i in range(first, last):
        radius = radii[i]
        # The contact's R*: outside (a post or roller) the two curvatures add, r R / (r + R); inside (a drum) the
        # wall convention R* = r (the concave mantle's r R / (R - r) is within r / R of it).
        contact_radius = radius if inside else radius * cylinder_radius / (radius + cylinder_radius)
        rx = positions[i, 0] - point[0]
        ry = positions[i, 1] - point[1]
        rz = positions[i, 2] - point[2]
        axial = rx * ex + ry * ey + rz * ez
        rx -= axial * ex
        ry -= axial * ey
        rz -= axial * ez
        rho = math.sqrt(rx * rx + ry * ry + rz * rz)
        distance = 0.0
        nx = 0.0
        ny = 0.0
        nz = 0.0
        touching = rho > 0.0
        if touching:
            if inside:
                distance = cylinder_radius - rho
                nx = -rx / rho
                ny = -ry / rho
                nz = -rz / rho
            else:
                distance = rho - cylinder_radius
                nx = rx / rho
                ny = ry / rho
                nz = rz / rho
            touching = distance < radius
            if not touching and composition & COHESIVE:
                touching = cohesive_contact_holds(composition, coefficients, material_index[i], wall_row,
                                                  radius - distance, contact_radius, rows, i)
        if not touching:
            in_use = False
            for column in range(overlap_column):
                if rows[i, column] != 0.0:
                    in_use = True
            if in_use:
                dissipated_total += released_energy(composition, coefficients, material_index[i], wall_row,
                                                    rows[i, overlap_column], mass[i], contact_radius, rows, i)
            for column in range(overlap_column + 1):
                rows[i, column] = 0.0
            continue
        lever = distance
        qx = positions[i, 0] - lever * nx
        qy = positions[i, 1] - lever * ny
        qz = positions[i, 2] - lever * nz
        # Surface velocity at q: v + w x (q - point).
        ax = qx - point[0]
        ay = qy - point[1]
        az = qz - point[2]
        sx = velocity[0] + angular_velocity[1] * az - angular_velocity[2] * ay
        sy = velocity[1] + angular_velocity[2] * ax - angular_velocity[0] * az
        sz = velocity[2] + angular_velocity[0] * ay - angular_velocity[1] * ax
        fx, fy, fz, tx, ty, tz, mx, my, mz, elastic, dissipated, _, _ = rigid_wall_contact(
            composition, coefficients, material_index[i], wall_row, nx, ny, nz, distance, sx, sy, sz,
            velocities[i, 0], velocities[i, 1], velocities[i, 2], angular_velocities[i, 0], angular_velocities[i, 1],
            angular_velocities[i, 2], radius, contact_radius, mass[i], inverse_inertia[i], rows, i, dt)
        add_particle_loads(forces, torques, i, fx, fy, fz, tx, ty, tz)
        rows[i, overlap_column] = radius - distance  # this step's overlap
        elastic_total += elastic
        dissipated_total += dissipated
        work += (fx * sx + fy * sy + fz * sz) * dt
        contacts += 1
        totals[0] -= fx
        totals[1] -= fy
        totals[2] -= fz
        totals[3] += -(qy * fz - qz * fy) - mx
        totals[4] += -(qz * fx - qx * fz) - my
        totals[5] += -(qx * fy - qy * fx) - mz
        if conducting:
            conductance = contact_conductance(composition, coefficients, material_index[i], wall_row,
                                              radius - distance, mass[i], contact_radius)
            flow = conductance * (wall_temperature - temperatures[i])
            heat_flows[i, 0] += flow
            heat_flows[i, 1] += conductance
            heat += flow * dt
    return elastic_total, dissipated_total, contacts, work, heat


class CylinderWall(ContributorWall):
    """An infinite analytic cylinder (see module docstring); a ParticleSystem contributor."""

    def __init__(self, name: str, point, direction, radius: float, inside: bool, material_index: int,
                 velocity=(0.0, 0.0, 0.0), angular_velocity=(0.0, 0.0, 0.0)):
        super().__init__(name)
        self.reference_point = np.asarray(point, dtype=float).reshape(3)
        direction = np.asarray(direction, dtype=float).reshape(3)
        self.reference_direction = direction / np.linalg.norm(direction)
        self.radius = float(radius)
        self.inside = bool(inside)
        self.material_index = int(material_index)
        self.velocity = np.asarray(velocity, dtype=float).reshape(3)
        self.angular_velocity = np.asarray(angular_velocity, dtype=float).reshape(3)
        self.time = 0.0
        self.point = self.reference_point.copy()
        self.direction = self.reference_direction.copy()
        self.contact_count = 0

    def move(self, dt: float) -> None:
        self.time += dt
        self.point = self.reference_point + self.time * self.velocity
        self.direction = rotation_matrix(self.angular_velocity * self.time) @ self.reference_direction

    def state_dict(self) -> dict:
        state = super().state_dict()
        state.update(time=kinds.scalar(float(self.time)), point=kinds.global_array(self.point),
                     direction=kinds.global_array(self.direction))
        return state

    def load_state_dict(self, state: dict) -> None:
        super().load_state_dict(state)
        self.time = float(state["time"])
        self.point = np.array(state["point"], dtype=float)
        self.direction = np.array(state["direction"], dtype=float)

    def add_forces(self, system, first: int, last: int):
        state, tables = system.state, system.tables
        # The contact history, then the last step's overlap (what an opening contact held).
        history = self._field(state, f"wall:{self.name}:history", (1, tables.history_width + 1), np.float64, 0.0)
        self.totals[:] = 0.0
        temperatures, heat_flows = self._heat_arrays(state)
        elastic, dissipated, contacts, work, self.step_heat = cylinder_forces(
            first, last, self.point, self.direction, self.radius, self.inside, self.velocity, self.angular_velocity,
            self.material_index, history, state.positions, state.velocities, state.angular_velocities,
            state.radii, state.mass, state.inverse_inertia, state.material_index, tables.coefficients,
            tables.composition, system.dt, state.forces, state.torques, self.totals, temperatures, heat_flows,
            self.temperature)
        self.contact_count = int(contacts)
        self._step_work = float(work)
        if system.comm.size == 1:
            self._book_step_work(self._step_work)
        return elastic, dissipated, contacts
