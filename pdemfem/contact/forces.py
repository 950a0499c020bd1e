"""Contact force kernels: sphere-sphere pairs from the Verlet list, and plane walls.

The contact law is composed from the scene's sub-models (pdemfem.contact.response); the
loops over pairs and walls are single numba calls per step, given the scene's
*composition* (the sub-models it uses: pdemfem.contact.layout), or compiled for one
(COMPILED_COMPOSITION).  Sign conventions as in
pdemfem.contact.response; every returned force/torque acts on i (the partner gets the
opposite force).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from pdemfem.contact.conduction import contact_conductance
from pdemfem.contact.layout import COHESIVE, HEAT, ROLLING_ANY, TANGENTIAL
from pdemfem.contact.registry import history_layout
from pdemfem.contact.response import (add_particle_loads, clear_history, cohesive_contact_holds, contact_response,
                                      released_energy, rigid_wall_contact)

# The composition these kernels are compiled for; -1: the `composition` argument, read at run time.  The
# particle system runs a copy of this module with it set to the scene's (pdemfem.contact.specialized), so
# the compiler folds every composition test and drops the unused sub-models' code: the pair loop took
# 11 % less time on the settle benchmark's bed (results agree to round-off: the multiply-adds below are
# fused in other places once the code is folded).
COMPILED_COMPOSITION = -1

# Let the compiler fuse a multiply and an add into one instruction (FMA, one rounding instead of two): the
# pair loop took 12 % less time on the settle benchmark's bed.  The other fast-math licences stay off: no
# reassociation, no reciprocal approximations, and NaN and infinity keep their meaning (the run monitor
# stops a run on a non-finite value).  Results change in their last bits only.
CONTRACT = {"contract"}


# Room for the first evaluations the pair loop sets apart in one pass (pair_forces): more make it stop, compute
# them and go on from where it stopped.
SET_APART_CAPACITY = 4096


def set_apart_buffer():
    """The buffer pair_forces sets first evaluations apart in: (list slot, slot + 1, row particle) by column."""
    return np.empty((3, SET_APART_CAPACITY), dtype=np.int64)


def pair_forces(row_particles, pair_starts, pair_ends, neighbor_partners, pair_history, ids, owned_count,
                positions, velocities, angular_velocities, radii, mass, inverse_inertia, material_index,
                coefficients, composition, dt, forces, torques, temperatures, heat_flows, set_apart=None):
    """Add the forces of the sphere-sphere contacts of the half list's rows: row r is particle
    row_particles[r] and its pairs are the list slots pair_starts[r] .. pair_ends[r] - 1 (a CSR list:
    offsets[:-1], offsets[1:]; VerletList.interior / .boundary: its pairs without / with a ghost).

    With heat on (composition), every contact also conducts: heat_flows[i] gets (Q, H) and the partner
    (-Q, H) (pdemfem.particles.heat); temperatures and heat_flows are unused (may be empty) otherwise.

    A pair with a ghost is computed on both ranks that own one of its particles
    (each keeps the force on its own particle); its energy and count are booked
    only on the rank owning the lower id, so sums over ranks count it once.
    Returns (elastic energy, dissipated energy of this step, number of contacts, deepest overlap as a
    fraction of the pair's smaller radius).

    set_apart (set_apart_buffer(); the results are the same without it, in the last bits): the contacts'
    first evaluations, which apply the dashpot's onset factor (pdemfem.contact.response.dashpot_onset), are set
    apart there and computed after the others.  The factor's code, inlined for every contact, cost the settled
    bed's loop 13-16 %, though 12 of its 65,400 contacts were first evaluations.  The two passes are called from
    here, not from a compiled wrapper: compiled into one, the pair loop's first compile took 26.5 s against 7.2 s
    for the loop alone (the compiler compiled each specialization again inside the wrapper); from Python the
    loop with and without set_apart compile once each, and the second call is made only when there are first
    evaluations.
    """
    elastic_total = 0.0
    dissipated_total = 0.0
    contacts = 0
    deepest = 0.0
    resume_row = 0
    resume_slot = pair_starts[0] if len(pair_starts) else 0
    while True:
        elastic, dissipated, count, deepest_here, set_apart_count, resume_row, resume_slot = _pair_loop(
            row_particles, pair_starts, pair_ends, neighbor_partners, pair_history, ids, owned_count, positions,
            velocities, angular_velocities, radii, mass, inverse_inertia, material_index, coefficients, composition,
            dt, forces, torques, temperatures, heat_flows, resume_row, resume_slot, set_apart)
        elastic_total += elastic
        dissipated_total += dissipated
        contacts += count
        deepest = max(deepest, deepest_here)
        if set_apart is None:
            break
        if set_apart_count:
            elastic, dissipated, count, deepest_here, _, _, _ = _pair_loop(
                set_apart[2, :set_apart_count], set_apart[0, :set_apart_count], set_apart[1, :set_apart_count],
                neighbor_partners, pair_history, ids, owned_count, positions, velocities, angular_velocities, radii,
                mass, inverse_inertia, material_index, coefficients, composition, dt, forces, torques, temperatures,
                heat_flows, 0, set_apart[0, 0], None)
            elastic_total += elastic
            dissipated_total += dissipated
            contacts += count
            deepest = max(deepest, deepest_here)
        if resume_row >= len(row_particles):
            break
    return elastic_total, dissipated_total, contacts, deepest


@njit(cache=True, fastmath=CONTRACT)
def _pair_loop(row_particles, pair_starts, pair_ends, neighbor_partners, pair_history, ids, owned_count, positions,
               velocities, angular_velocities, radii, mass, inverse_inertia, material_index, coefficients, composition,
               dt, forces, torques, temperatures, heat_flows, first_row, first_slot, set_apart):
    """pair_forces' loop from row first_row's slot first_slot on.  With set_apart an array, first evaluations
    go there (and the loop stops when it is full); with None, every contact is computed, first evaluations
    with the onset factor.  Returns (elastic, dissipated, contacts, deepest, set-apart count, row and slot to
    go on from: the row count when done)."""
    if COMPILED_COMPOSITION >= 0:
        composition = COMPILED_COMPOSITION
    width = history_layout(composition)[3]
    elastic_total = 0.0
    dissipated_total = 0.0
    contacts = 0
    deepest = 0.0
    set_apart_count = 0
    for r in range(first_row, row_particles.shape[0]):
        i = row_particles[r]
        i_owned = i < owned_count
        xi = positions[i, 0]
        yi = positions[i, 1]
        zi = positions[i, 2]
        radius_i = radii[i]
        material_i = material_index[i]
        for row in range(first_slot if r == first_row else pair_starts[r], pair_ends[r]):
            j = neighbor_partners[row]
            dx = xi - positions[j, 0]
            dy = yi - positions[j, 1]
            dz = zi - positions[j, 2]
            distance_squared = dx * dx + dy * dy + dz * dz
            radius_j = radii[j]
            radius_sum = radius_i + radius_j
            apart = distance_squared >= radius_sum * radius_sum
            if apart and width == 0:
                continue
            if apart:
                in_use = False
                for column in range(width):
                    if pair_history[row, column] != 0.0:
                        in_use = True
                if not in_use:
                    # Most listed pairs are apart with an empty history.
                    continue
                material_j = material_index[j]
                effective_radius = radius_i * radius_j / radius_sum
                distance = math.sqrt(distance_squared)
                # A formed cohesive contact holds down to its pull-off overlap.
                if not (composition & COHESIVE) or not cohesive_contact_holds(
                        composition, coefficients, material_i, material_j, radius_sum - distance, effective_radius,
                        pair_history, row):
                    if i_owned:
                        booked = j < owned_count or ids[i] < ids[j]
                    else:
                        booked = ids[j] < ids[i]
                    if booked:
                        # The contact opened this step: what it held (booked as elastic) is lost.
                        ex = dx - dt * (velocities[i, 0] - velocities[j, 0])
                        ey = dy - dt * (velocities[i, 1] - velocities[j, 1])
                        ez = dz - dt * (velocities[i, 2] - velocities[j, 2])
                        dissipated_total += released_energy(
                            composition, coefficients, material_i, material_j,
                            radius_sum - math.sqrt(ex * ex + ey * ey + ez * ez),
                            mass[i] * mass[j] / (mass[i] + mass[j]), effective_radius, pair_history, row)
                    clear_history(composition, pair_history, row)
                    continue
            else:
                distance = math.sqrt(distance_squared)
                material_j = material_index[j]
            overlap = radius_sum - distance
            if set_apart is not None:
                # A first evaluation: the bodies closed by more than the overlap over the step.
                closing = -(dx * (velocities[i, 0] - velocities[j, 0]) + dy * (velocities[i, 1] - velocities[j, 1])
                            + dz * (velocities[i, 2] - velocities[j, 2]))
                if overlap > 0.0 and overlap * distance < closing * dt:
                    if set_apart_count == set_apart.shape[1]:
                        return (elastic_total, dissipated_total, contacts, deepest, set_apart_count, r, row)
                    set_apart[0, set_apart_count] = row
                    set_apart[1, set_apart_count] = row + 1
                    set_apart[2, set_apart_count] = i
                    set_apart_count += 1
                    continue
            if i_owned:
                booked = j < owned_count or ids[i] < ids[j]
            else:
                booked = ids[j] < ids[i]
            smaller = radius_i if radius_i < radius_j else radius_j
            if overlap > deepest * smaller:  # divides only when the record grows
                deepest = overlap / smaller
            inverse_distance = 1.0 / distance
            nx = dx * inverse_distance
            ny = dy * inverse_distance
            nz = dz * inverse_distance
            lever_i = radius_i - 0.5 * overlap
            lever_j = radius_j - 0.5 * overlap
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
            ux = velocities[i, 0] - velocities[j, 0]  # the centres' relative velocity
            uy = velocities[i, 1] - velocities[j, 1]
            uz = velocities[i, 2] - velocities[j, 2]
            vx = ux - (sy * nz - sz * ny)
            vy = uy - (sz * nx - sx * nz)
            vz = uz - (sx * ny - sy * nx)
            previous_vx = vx
            previous_vy = vy
            previous_vz = vz
            if composition & TANGENTIAL:
                # The same velocity at the previous evaluation's normal and levers (the centres a step
                # earlier, d - dt u, as the drift moved them): what the tangential force applied then worked on.
                # To first order in dt, without a square root: normal n - dt u_t / |d|, distance |d| - dt u.n.
                # What that leaves, O(dt^2 |u_t|^2 / |d|^2) in the normal, books O(dt^3) a step (the exact
                # reconstruction cost the 28k settle bed ~10 % of its pair time).
                closing = ux * nx + uy * ny + uz * nz
                turn = dt * inverse_distance
                ex = nx - turn * (ux - closing * nx)
                ey = ny - turn * (uy - closing * ny)
                ez = nz - turn * (uz - closing * nz)
                earlier_lever_i = lever_i - 0.5 * dt * closing
                earlier_lever_j = lever_j - 0.5 * dt * closing
                qx = earlier_lever_i * wxi + earlier_lever_j * wxj
                qy = earlier_lever_i * wyi + earlier_lever_j * wyj
                qz = earlier_lever_i * wzi + earlier_lever_j * wzj
                previous_vx = ux - (qy * ez - qz * ey)
                previous_vy = uy - (qz * ex - qx * ez)
                previous_vz = uz - (qx * ey - qy * ex)
            effective_mass = mass[i] * mass[j] / (mass[i] + mass[j])
            effective_radius = radius_i * radius_j / radius_sum
            effective_inertia = 0.0  # only rolling models use them: divisions saved per contact without them
            rolling_inertia = 0.0
            if composition & ROLLING_ANY:
                effective_inertia = 1.0 / (inverse_inertia[i] + inverse_inertia[j])
                # Each body's inertia about the contact point, I + m r^2, in series (Ai et al. 2011, eq. 27).
                about_contact_i = 1.0 / inverse_inertia[i] + mass[i] * radius_i * radius_i
                about_contact_j = 1.0 / inverse_inertia[j] + mass[j] * radius_j * radius_j
                rolling_inertia = about_contact_i * about_contact_j / (about_contact_i + about_contact_j)
            fx, fy, fz, mx, my, mz, elastic, dissipated, _, _ = contact_response(
                composition, coefficients, material_i, material_j, nx, ny, nz, overlap, vx, vy, vz,
                previous_vx, previous_vy, previous_vz, wxi - wxj, wyi - wyj, wzi - wzj, effective_mass,
                effective_radius, effective_inertia, rolling_inertia, pair_history, row, dt, set_apart is None)
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
            if composition & HEAT:
                conductance = contact_conductance(composition, coefficients, material_i, material_j, overlap,
                                                  effective_mass, effective_radius)
                flow = conductance * (temperatures[j] - temperatures[i])
                heat_flows[i, 0] += flow
                heat_flows[i, 1] += conductance
                heat_flows[j, 0] -= flow
                heat_flows[j, 1] += conductance
    return (elastic_total, dissipated_total, contacts, deepest, set_apart_count, row_particles.shape[0],
            0)


@njit(cache=True, fastmath=CONTRACT)
def plane_wall_forces(candidate_particles, candidate_walls, wall_points, wall_normals, wall_velocities,
                      wall_material, candidate_history, positions, velocities, angular_velocities, radii,
                      mass, inverse_inertia, material_index, coefficients, composition, dt, forces, torques, wall_forces,
                      temperatures, heat_flows, wall_temperatures, wall_heat):
    """Add the forces of the candidate (particle, plane wall) pairs.

    With heat on, a wall with a temperature (wall_temperatures[w], NaN: adiabatic) conducts to the
    particles touching it; wall_heat[w] accumulates the heat [J] the wall gives the particles (flow x dt).

    Candidates are the owned particles within reach of a wall at the last list build (every
    other pair cannot touch before the next one).  A wall is a flat rigid body (R = inf,
    m = inf); wall_forces[w] receives the force the particles exert on wall w.  candidate_history
    is (candidates, history width), a row per candidate pair.  Returns (elastic, dissipated, contacts, deepest
    overlap as a fraction of the particle's radius).
    """
    if COMPILED_COMPOSITION >= 0:
        composition = COMPILED_COMPOSITION
    width = candidate_history.shape[1]
    history = candidate_history
    elastic_total = 0.0
    dissipated_total = 0.0
    contacts = 0
    deepest = 0.0
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
        row = candidate
        active = overlap > 0.0
        if not active and composition & COHESIVE:
            active = cohesive_contact_holds(composition, coefficients, material_index[i], wall_material[w], overlap,
                                            radius, history, row)
        if not active:
            in_use = False
            for column in range(width):
                if history[row, column] != 0.0:
                    in_use = True
            if in_use:
                # The contact opened this step: what it held (booked as elastic) is lost.
                previous_distance = distance - dt * ((velocities[i, 0] - wall_velocities[w, 0]) * nx
                                                     + (velocities[i, 1] - wall_velocities[w, 1]) * ny
                                                     + (velocities[i, 2] - wall_velocities[w, 2]) * nz)
                dissipated_total += released_energy(composition, coefficients, material_index[i], wall_material[w],
                                                    radius - previous_distance, mass[i], radius, history, row)
                clear_history(composition, history, row)
            continue
        if overlap > deepest * radius:
            deepest = overlap / radius
        # Contact point on the plane, `distance` below the centre.
        fx, fy, fz, tx, ty, tz, _, _, _, elastic, dissipated, _, _ = rigid_wall_contact(
            composition, coefficients, material_index[i], wall_material[w], nx, ny, nz, distance,
            wall_velocities[w, 0], wall_velocities[w, 1], wall_velocities[w, 2], velocities[i, 0], velocities[i, 1],
            velocities[i, 2], angular_velocities[i, 0], angular_velocities[i, 1], angular_velocities[i, 2], radius,
            radius, mass[i], inverse_inertia[i], history, row, dt)
        add_particle_loads(forces, torques, i, fx, fy, fz, tx, ty, tz)
        elastic_total += elastic
        dissipated_total += dissipated
        contacts += 1
        wall_forces[w, 0] -= fx
        wall_forces[w, 1] -= fy
        wall_forces[w, 2] -= fz
        if composition & HEAT:
            wall_temperature = wall_temperatures[w]
            if wall_temperature == wall_temperature:  # NaN: an adiabatic wall
                conductance = contact_conductance(composition, coefficients, material_index[i], wall_material[w],
                                                  overlap, mass[i], radius)
                flow = conductance * (wall_temperature - temperatures[i])
                heat_flows[i, 0] += flow
                heat_flows[i, 1] += conductance
                wall_heat[w] += flow * dt
    return elastic_total, dissipated_total, contacts, deepest
