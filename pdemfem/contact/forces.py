"""Contact force kernels: sphere-sphere pairs from the Verlet list, and plane walls.

One small inline function per sub-model (normal, tangential, rolling), composed
by `contact_response`; the loops over pairs and walls are single numba calls
per step.  Sign conventions: n points from the partner (j or wall) to particle
i, `relative_velocity` is i's contact-point velocity minus the partner's, and
every returned force/torque acts on i (the partner gets the opposite force).

The Verlet velocities are half-step values (v^{n+1/2}), so v * dt is exactly the
relative displacement of the step, which is what the tangential spring needs.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

HERTZ_MINDLIN = 0
LINEAR_SPRING_DASHPOT = 1


@njit(inline="always", cache=True)
def normal_stiffnesses(model, overlap, effective_mass, effective_radius, effective_modulus,
                       effective_shear_modulus, constant_stiffness, tangential_ratio, characteristic_speed):
    """(elastic normal force, normal stiffness S_n, tangential stiffness S_t, normal elastic energy)."""
    if model == HERTZ_MINDLIN:
        contact_radius = math.sqrt(effective_radius * overlap)
        normal_stiffness = 2.0 * effective_modulus * contact_radius
        elastic_force = (4.0 / 3.0) * effective_modulus * contact_radius * overlap
        tangential_stiffness = 8.0 * effective_shear_modulus * contact_radius
        elastic_energy = 0.4 * elastic_force * overlap  # 8/15 E* sqrt(R*) delta^(5/2)
        return elastic_force, normal_stiffness, tangential_stiffness, elastic_energy
    stiffness = constant_stiffness
    if stiffness <= 0.0:
        # Derived: the same peak overlap as Hertz at the characteristic impact speed.
        speed_squared = characteristic_speed * characteristic_speed
        peak_overlap = (15.0 * effective_mass * speed_squared
                        / (16.0 * effective_modulus * math.sqrt(effective_radius))) ** 0.4
        stiffness = effective_mass * speed_squared / (peak_overlap * peak_overlap)
    return stiffness * overlap, stiffness, tangential_ratio * stiffness, 0.5 * stiffness * overlap * overlap


@njit(inline="always", cache=True)
def released_spring_energy(model, previous_overlap, xi_squared, effective_mass, effective_radius,
                           effective_modulus, effective_shear_modulus, constant_stiffness, tangential_ratio,
                           characteristic_speed):
    """Energy 1/2 S_t |xi|^2 the tangential spring held at the previous step's overlap.

    Booked as dissipated when a contact opens with a loaded spring (the history is
    zeroed), and used as the spring energy before the update while it stays closed.
    """
    if xi_squared == 0.0 or previous_overlap <= 0.0:
        return 0.0
    tangential_stiffness = normal_stiffnesses(
        model, previous_overlap, effective_mass, effective_radius, effective_modulus, effective_shear_modulus,
        constant_stiffness, tangential_ratio, characteristic_speed)[2]
    return 0.5 * tangential_stiffness * xi_squared


@njit(inline="always", cache=True)
def contact_response(nx, ny, nz, overlap, vx, vy, vz, wx, wy, wz, effective_mass, effective_radius,
                     effective_modulus, effective_shear_modulus, damping, friction, rolling_friction, model,
                     constant_stiffness, tangential_ratio, characteristic_speed, effective_inertia,
                     history, row, dt, rolling_enabled):
    """Force and rolling torque on i for one contact; updates history[row].

    Returns (fx, fy, fz, rolling torque x, y, z, elastic energy, dissipated energy this step,
    normal and tangential dashpot coefficients in effect).  The dashpots' force on i is
    -(c_n n n^T + c_t (I - n n^T)) v; c_n is 0 when the normal force was clamped at zero and c_t is 0
    when the contact slides (the force is then not linear in v).  A deformable surface applies the
    dashpot to its own nodes at its own rate (pdemfem.coupling.dampers).
    """
    elastic_force, normal_stiffness, tangential_stiffness, normal_energy = normal_stiffnesses(
        model, overlap, effective_mass, effective_radius, effective_modulus, effective_shear_modulus,
        constant_stiffness, tangential_ratio, characteristic_speed)

    # Normal: spring + dashpot, never attractive.
    normal_speed = vx * nx + vy * ny + vz * nz
    approach_rate = -normal_speed
    normal_damping = damping * math.sqrt(effective_mass * normal_stiffness)
    normal_force = elastic_force + normal_damping * approach_rate
    if normal_force < 0.0:
        normal_force = 0.0
        normal_damping = 0.0
    # Velocity Verlet gives the force of this evaluation the mean of the half-step velocities before and
    # after it; this contact alone changes the approach rate by dt F_n / m* over the step, so the dashpot's
    # work is booked at approach - dt F_n / (2 m*) (exact for an isolated contact; with the half-step rate
    # alone, strong damping (e = 1e-4) booked 5-36 % more than the energy lost).
    dissipated = (normal_force - elastic_force) * (approach_rate - 0.5 * dt * normal_force / effective_mass) * dt

    # Tangential: incremental spring xi, rotated into the current tangent plane.
    tx = vx - normal_speed * nx
    ty = vy - normal_speed * ny
    tz = vz - normal_speed * nz
    xi_x = history[row, 0]
    xi_y = history[row, 1]
    xi_z = history[row, 2]
    old_length_squared = xi_x * xi_x + xi_y * xi_y + xi_z * xi_z
    if old_length_squared > 0.0:
        along_normal = xi_x * nx + xi_y * ny + xi_z * nz
        xi_x -= along_normal * nx
        xi_y -= along_normal * ny
        xi_z -= along_normal * nz
        new_length_squared = xi_x * xi_x + xi_y * xi_y + xi_z * xi_z
        if new_length_squared > 0.0:
            scale = math.sqrt(old_length_squared / new_length_squared)
            xi_x *= scale
            xi_y *= scale
            xi_z *= scale
    # The spring energy booked last step used last step's stiffness (Hertz: S_t ~ sqrt(delta)); v is the
    # step's displacement / dt, so that step's overlap was overlap - approach_rate * dt.
    spring_energy_before = 0.0
    if old_length_squared > 0.0:
        spring_energy_before = released_spring_energy(
            model, overlap - approach_rate * dt, xi_x * xi_x + xi_y * xi_y + xi_z * xi_z, effective_mass,
            effective_radius, effective_modulus, effective_shear_modulus, constant_stiffness, tangential_ratio,
            characteristic_speed)
    xi_x += tx * dt
    xi_y += ty * dt
    xi_z += tz * dt
    tangential_damping = damping * math.sqrt(effective_mass * tangential_stiffness)
    fx = -tangential_stiffness * xi_x - tangential_damping * tx
    fy = -tangential_stiffness * xi_y - tangential_damping * ty
    fz = -tangential_stiffness * xi_z - tangential_damping * tz
    tangential_force_squared = fx * fx + fy * fy + fz * fz
    friction_limit = friction * normal_force
    # Squares compared: the square root is only needed by sliding contacts.
    if tangential_force_squared > friction_limit * friction_limit:
        tangential_force = math.sqrt(tangential_force_squared)
        # Coulomb slip: cap the force and let the spring alone hold it (S_t xi = -F_t).  Folding the
        # dashpot into xi as well, xi = -(F_t + c v_t) / S_t, points xi against the force whenever
        # c |v_t| > mu F_n; with S_t growing (Hertz) the next step's force then pushes along the slip.
        scale = friction_limit / tangential_force
        tangential_damping = 0.0
        fx *= scale
        fy *= scale
        fz *= scale
        if tangential_stiffness > 0.0:
            xi_x = -fx / tangential_stiffness
            xi_y = -fy / tangential_stiffness
            xi_z = -fz / tangential_stiffness
    history[row, 0] = xi_x
    history[row, 1] = xi_y
    history[row, 2] = xi_z
    spring_energy = 0.5 * tangential_stiffness * (xi_x * xi_x + xi_y * xi_y + xi_z * xi_z)
    # Work taken from the relative motion minus what the spring stored.
    dissipated += -(fx * tx + fy * ty + fz * tz) * dt - (spring_energy - spring_energy_before)

    fx += normal_force * nx
    fy += normal_force * ny
    fz += normal_force * nz

    # Rolling resistance: constant directional torque against relative rolling,
    # capped so that it cannot reverse the rolling within one step.
    mx = 0.0
    my = 0.0
    mz = 0.0
    if rolling_enabled and rolling_friction > 0.0:
        along_normal = wx * nx + wy * ny + wz * nz
        rx = wx - along_normal * nx
        ry = wy - along_normal * ny
        rz = wz - along_normal * nz
        rolling_speed = math.sqrt(rx * rx + ry * ry + rz * rz)
        if rolling_speed > 0.0:
            torque = rolling_friction * effective_radius * normal_force
            torque_limit = effective_inertia * rolling_speed / dt
            if torque > torque_limit:
                torque = torque_limit
            mx = -torque * rx / rolling_speed
            my = -torque * ry / rolling_speed
            mz = -torque * rz / rolling_speed
            dissipated += torque * rolling_speed * dt
    return fx, fy, fz, mx, my, mz, normal_energy + spring_energy, dissipated, normal_damping, tangential_damping


@njit(inline="always", cache=True)
def rigid_wall_contact(i, nx, ny, nz, distance, surface_vx, surface_vy, surface_vz, wall_material, history, slot,
                       velocities, angular_velocities, radii, mass, inverse_inertia, material_index,
                       effective_modulus, effective_shear_modulus, damping, friction, rolling_friction, model_code,
                       normal_stiffness, tangential_ratio, characteristic_speed, dt, rolling_enabled, forces, torques):
    """Contact of particle i with a rigid wall (R = inf, m = inf): plane, cylinder or triangle.

    n is the wall's normal at the contact point, which lies `distance` below the centre
    along -n and moves with the surface velocity.  Adds the force and torque to particle i
    and returns (fx, fy, fz, mx, my, mz, elastic, dissipated, c_n, c_t): the force and rolling couple
    on the particle (the wall gets the opposite), the contact's energies and its dashpot coefficients.
    """
    lever = distance
    wx = angular_velocities[i, 0]
    wy = angular_velocities[i, 1]
    wz = angular_velocities[i, 2]
    vx = velocities[i, 0] - surface_vx - lever * (wy * nz - wz * ny)
    vy = velocities[i, 1] - surface_vy - lever * (wz * nx - wx * nz)
    vz = velocities[i, 2] - surface_vz - lever * (wx * ny - wy * nx)
    material_i = material_index[i]
    fx, fy, fz, mx, my, mz, elastic, dissipated, normal_damping, tangential_damping = contact_response(
        nx, ny, nz, radii[i] - distance, vx, vy, vz, wx, wy, wz, mass[i], radii[i],
        effective_modulus[material_i, wall_material], effective_shear_modulus[material_i, wall_material],
        damping[material_i, wall_material], friction[material_i, wall_material],
        rolling_friction[material_i, wall_material], model_code[material_i, wall_material],
        normal_stiffness[material_i, wall_material], tangential_ratio[material_i, wall_material],
        characteristic_speed, 1.0 / inverse_inertia[i], history, slot, dt, rolling_enabled)
    forces[i, 0] += fx
    forces[i, 1] += fy
    forces[i, 2] += fz
    torques[i, 0] += -lever * (ny * fz - nz * fy) + mx
    torques[i, 1] += -lever * (nz * fx - nx * fz) + my
    torques[i, 2] += -lever * (nx * fy - ny * fx) + mz
    return fx, fy, fz, mx, my, mz, elastic, dissipated, normal_damping, tangential_damping


@njit(cache=True)
def pair_forces(row_particles, neighbor_offsets, neighbor_partners, pair_history, ids, owned_count,
                positions, velocities, angular_velocities, radii, mass, inverse_inertia, material_index,
                effective_modulus, effective_shear_modulus, damping, friction, rolling_friction, model_code,
                normal_stiffness, tangential_ratio, characteristic_speed, dt, rolling_enabled,
                forces, torques):
    """Add the forces of all sphere-sphere contacts of the half list (row r is particle row_particles[r]).

    A pair with a ghost is computed on both ranks that own one of its particles
    (each keeps the force on its own particle); its energy and count are booked
    only on the rank owning the lower id, so sums over ranks count it once.
    Returns (elastic energy, dissipated energy of this step, number of contacts).
    """
    elastic_total = 0.0
    dissipated_total = 0.0
    contacts = 0
    for r in range(row_particles.shape[0]):
        i = row_particles[r]
        i_owned = i < owned_count
        xi = positions[i, 0]
        yi = positions[i, 1]
        zi = positions[i, 2]
        radius_i = radii[i]
        material_i = material_index[i]
        for row in range(neighbor_offsets[r], neighbor_offsets[r + 1]):
            j = neighbor_partners[row]
            if i_owned:
                booked = j < owned_count or ids[i] < ids[j]
            else:
                booked = ids[j] < ids[i]
            dx = xi - positions[j, 0]
            dy = yi - positions[j, 1]
            dz = zi - positions[j, 2]
            distance_squared = dx * dx + dy * dy + dz * dz
            radius_sum = radius_i + radii[j]
            if distance_squared >= radius_sum * radius_sum:
                xi_squared = pair_history[row, 0] ** 2 + pair_history[row, 1] ** 2 + pair_history[row, 2] ** 2
                if xi_squared > 0.0:
                    if booked:
                        # The contact opened this step: its spring energy (booked as elastic) is lost.
                        ex = dx - dt * (velocities[i, 0] - velocities[j, 0])
                        ey = dy - dt * (velocities[i, 1] - velocities[j, 1])
                        ez = dz - dt * (velocities[i, 2] - velocities[j, 2])
                        material_j = material_index[j]
                        dissipated_total += released_spring_energy(
                            model_code[material_i, material_j], radius_sum - math.sqrt(ex * ex + ey * ey + ez * ez),
                            xi_squared, mass[i] * mass[j] / (mass[i] + mass[j]), radius_i * radii[j] / radius_sum,
                            effective_modulus[material_i, material_j], effective_shear_modulus[material_i, material_j],
                            normal_stiffness[material_i, material_j], tangential_ratio[material_i, material_j],
                            characteristic_speed)
                    # Only springs in use are reset: most listed pairs are apart and already zero.
                    pair_history[row, 0] = 0.0
                    pair_history[row, 1] = 0.0
                    pair_history[row, 2] = 0.0
                continue
            distance = math.sqrt(distance_squared)
            overlap = radius_sum - distance
            nx = dx / distance
            ny = dy / distance
            nz = dz / distance
            lever_i = radius_i - 0.5 * overlap
            lever_j = radii[j] - 0.5 * overlap
            wxi = angular_velocities[i, 0]
            wyi = angular_velocities[i, 1]
            wzi = angular_velocities[i, 2]
            wxj = angular_velocities[j, 0]
            wyj = angular_velocities[j, 1]
            wzj = angular_velocities[j, 2]
            # Contact-point velocities: v_i + w_i x (-lever_i n) minus v_j + w_j x (lever_j n).
            sx = lever_i * wxi + lever_j * wxj
            sy = lever_i * wyi + lever_j * wyj
            sz = lever_i * wzi + lever_j * wzj
            vx = velocities[i, 0] - velocities[j, 0] - (sy * nz - sz * ny)
            vy = velocities[i, 1] - velocities[j, 1] - (sz * nx - sx * nz)
            vz = velocities[i, 2] - velocities[j, 2] - (sx * ny - sy * nx)
            material_j = material_index[j]
            effective_mass = mass[i] * mass[j] / (mass[i] + mass[j])
            effective_radius = radius_i * radii[j] / radius_sum
            effective_inertia = 1.0 / (inverse_inertia[i] + inverse_inertia[j])
            fx, fy, fz, mx, my, mz, elastic, dissipated, _, _ = contact_response(
                nx, ny, nz, overlap, vx, vy, vz, wxi - wxj, wyi - wyj, wzi - wzj,
                effective_mass, effective_radius,
                effective_modulus[material_i, material_j], effective_shear_modulus[material_i, material_j],
                damping[material_i, material_j], friction[material_i, material_j],
                rolling_friction[material_i, material_j], model_code[material_i, material_j],
                normal_stiffness[material_i, material_j], tangential_ratio[material_i, material_j],
                characteristic_speed, effective_inertia, pair_history, row, dt, rolling_enabled)
            if booked:
                elastic_total += elastic
                dissipated_total += dissipated
                contacts += 1
            forces[i, 0] += fx
            forces[i, 1] += fy
            forces[i, 2] += fz
            forces[j, 0] -= fx
            forces[j, 1] -= fy
            forces[j, 2] -= fz
            # Torque of F at the contact point: (-lever n) x F on i, (lever n) x (-F) on j.
            cx = ny * fz - nz * fy
            cy = nz * fx - nx * fz
            cz = nx * fy - ny * fx
            torques[i, 0] += -lever_i * cx + mx
            torques[i, 1] += -lever_i * cy + my
            torques[i, 2] += -lever_i * cz + mz
            torques[j, 0] += -lever_j * cx - mx
            torques[j, 1] += -lever_j * cy - my
            torques[j, 2] += -lever_j * cz - mz
    return elastic_total, dissipated_total, contacts


@njit(cache=True)
def plane_wall_forces(candidate_particles, candidate_walls, wall_points, wall_normals, wall_velocities,
                      wall_material, wall_history, positions, velocities, angular_velocities, radii, mass,
                      inverse_inertia, material_index, effective_modulus, effective_shear_modulus, damping, friction,
                      rolling_friction, model_code, normal_stiffness, tangential_ratio, characteristic_speed,
                      dt, rolling_enabled, forces, torques, wall_forces):
    """Add the forces of the candidate (particle, plane wall) pairs.

    Candidates are the owned particles within radius + skin of a wall at the last
    list build (every other pair cannot touch before the next one).  A wall is a
    flat rigid body (R = inf, m = inf); wall_forces[w] receives the force the
    particles exert on wall w.  Returns (elastic, dissipated, contacts).
    """
    elastic_total = 0.0
    dissipated_total = 0.0
    contacts = 0
    for candidate in range(candidate_particles.shape[0]):
        i = candidate_particles[candidate]
        w = candidate_walls[candidate]
        radius = radii[i]
        nx = wall_normals[w, 0]
        ny = wall_normals[w, 1]
        nz = wall_normals[w, 2]
        distance = ((positions[i, 0] - wall_points[w, 0]) * nx
                    + (positions[i, 1] - wall_points[w, 1]) * ny
                    + (positions[i, 2] - wall_points[w, 2]) * nz)
        overlap = radius - distance
        if overlap <= 0.0:
            xi_squared = wall_history[i, w, 0] ** 2 + wall_history[i, w, 1] ** 2 + wall_history[i, w, 2] ** 2
            if xi_squared > 0.0:
                # The contact opened this step: its spring energy (booked as elastic) is lost.
                previous_distance = distance - dt * ((velocities[i, 0] - wall_velocities[w, 0]) * nx
                                                     + (velocities[i, 1] - wall_velocities[w, 1]) * ny
                                                     + (velocities[i, 2] - wall_velocities[w, 2]) * nz)
                material_i = material_index[i]
                material_w = wall_material[w]
                dissipated_total += released_spring_energy(
                    model_code[material_i, material_w], radius - previous_distance, xi_squared, mass[i], radius,
                    effective_modulus[material_i, material_w], effective_shear_modulus[material_i, material_w],
                    normal_stiffness[material_i, material_w], tangential_ratio[material_i, material_w],
                    characteristic_speed)
            wall_history[i, w, 0] = 0.0
            wall_history[i, w, 1] = 0.0
            wall_history[i, w, 2] = 0.0
            continue
        # Contact point on the plane, `distance` below the centre.
        fx, fy, fz, _, _, _, elastic, dissipated, _, _ = rigid_wall_contact(
            i, nx, ny, nz, distance, wall_velocities[w, 0], wall_velocities[w, 1], wall_velocities[w, 2],
            wall_material[w], wall_history[i], w, velocities, angular_velocities, radii, mass, inverse_inertia,
            material_index, effective_modulus, effective_shear_modulus, damping, friction, rolling_friction,
            model_code, normal_stiffness, tangential_ratio, characteristic_speed, dt, rolling_enabled,
            forces, torques)
        elastic_total += elastic
        dissipated_total += dissipated
        contacts += 1
        wall_forces[w, 0] -= fx
        wall_forces[w, 1] -= fy
        wall_forces[w, 2] -= fz
    return elastic_total, dissipated_total, contacts
