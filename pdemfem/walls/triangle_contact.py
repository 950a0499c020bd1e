"""Sphere-triangle contact: closest point with face/edge/vertex regions, one contact per smooth patch.

Kernels on flat arrays (numba, cache=True); Python never loops over particles.

Geometry.  `closest_point` (Ericson, Real-Time Collision Detection 5.1.5) returns the
point of a triangle nearest a sphere centre, its barycentric weights and the
Voronoi region it lies in: REGION_FACE (interior), an edge, or a vertex.

One contact per smooth patch.  Triangles are grouped into patches (connected sets
of triangles meeting at less than `smooth_angle`, see pdemfem.walls.mesh).  For each
sphere, every candidate triangle closer than the radius proposes a contact for its
patch, and the patch keeps the nearest one.  On a flat patch this is exactly the
analytic plane: in a face region the distance is the plane distance (c - a) . n,
and a triangle whose closest point lies on a shared edge or vertex is never
nearer than the triangle the centre projects into, so the edges between triangles
of a patch are invisible (same force, no bumps; tested against PlaneWalls).

Between patches.  A patch whose nearest point lies in a face region always
contributes (a concave corner: one contact per face).  A patch whose nearest point
lies on an edge or vertex (a *feature* contact) contributes only when no contact
already kept -- face contacts first, then feature contacts from the deepest --
belongs to a patch that also contains that feature: at a convex edge or vertex the
patches meeting there all report the same point and only one contact is kept, and
a sphere resting on a face near a convex edge does not also feel the edge of the
neighbouring face.  An edge or vertex that only one patch owns (the rim of a finite
plate) is a genuine contact.

History.  Each particle has K slots per mesh (patch id, the contact's history row, last overlap) in
ParticleState.fields, so the tangential spring follows the patch, not the
triangle: rolling across triangles of one patch carries it on unchanged.

Blended gap (blended=True: coupled solids with coupling.transfer: blended).  The overlap is a smooth blend
of the patch's facets under the sphere, delta = sum_t k(s_t) (R - d_t) / sum_t k(s_t) over the triangles
closer than R (s_t the point-triangle distance, k = (1 - s^2/R^2)^2, d_t the distance to the triangle's
plane, cut at the patch's boundary edges), so that a flat patch gives the plane exactly and a dimpled one a
gap whose gradient does not jump when the nearest facet changes.  The normal elastic force acts as the exact
gradient of that potential: f |grad_p delta| along n = -grad_p delta / |grad_p delta| on the particle and
-f d delta / d x_k on every node of those triangles (vertex_forces); the dashpot and tangential rest acts at
the nearest point as before (docs/coupling.md, "Blended contact gap").

Force reporting.  Every contact is recorded with its triangle, the barycentric
weights of the contact point and the force on the wall, and (optionally) the
force is spread onto the triangle's vertices by those weights, which preserves
total force and moment exactly (the moment because the contact point is the
weighted vertex sum).  The FE coupling uses this to load the solid's nodes.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from pdemfem.contact.conduction import contact_conductance
from pdemfem.contact.layout import FRICTION, HEAT, NORMAL_MODEL
from pdemfem.contact.registry import history_layout, normal_elastic
from pdemfem.contact.response import (add_particle_loads, history_in_use, pull_off_overlap, released_energy,
                                      rigid_wall_contact)

REGION_FACE = 0
REGION_EDGE_AB = 1
REGION_EDGE_BC = 2
REGION_EDGE_CA = 3
REGION_VERTEX_A = 4
REGION_VERTEX_B = 5
REGION_VERTEX_C = 6

# A per-particle slot holds the contact history (pdemfem.contact.registry.history_layout), then the
# overlap of the last step: slot_history has history width + 1 columns.
# Columns of a contact's dashpot record: c_n, c_t, normal (3), lever, particle contact-point velocity (3),
# surface velocity at the contact point (3), normal stiffness S_n = dF_n/d(overlap) and tangential stiffness S_t
# (0 when sliding): the spring a deformable surface applies to its nodes' own motion over its sub-steps
# (pdemfem.coupling.dampers).
DAMPING_RECORD_COLUMNS = 14


@njit(inline="always", cache=True)
def closest_point(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz):
    """Closest point of triangle abc to p: (qx, qy, qz, wa, wb, wc, region); q = wa a + wb b + wc c."""
    abx = bx - ax
    aby = by - ay
    abz = bz - az
    acx = cx - ax
    acy = cy - ay
    acz = cz - az
    apx = px - ax
    apy = py - ay
    apz = pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return ax, ay, az, 1.0, 0.0, 0.0, REGION_VERTEX_A
    bpx = px - bx
    bpy = py - by
    bpz = pz - bz
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return bx, by, bz, 0.0, 1.0, 0.0, REGION_VERTEX_B
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return ax + v * abx, ay + v * aby, az + v * abz, 1.0 - v, v, 0.0, REGION_EDGE_AB
    cpx = px - cx
    cpy = py - cy
    cpz = pz - cz
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return cx, cy, cz, 0.0, 0.0, 1.0, REGION_VERTEX_C
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return ax + w * acx, ay + w * acy, az + w * acz, 1.0 - w, 0.0, w, REGION_EDGE_CA
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return (bx + w * (cx - bx), by + w * (cy - by), bz + w * (cz - bz), 0.0, 1.0 - w, w, REGION_EDGE_BC)
    denominator = va + vb + vc
    if denominator <= 0.0:
        # Degenerate (zero-area) triangle: fall back to vertex a.
        return ax, ay, az, 1.0, 0.0, 0.0, REGION_VERTEX_A
    v = vb / denominator
    w = vc / denominator
    return (ax + abx * v + acx * w, ay + aby * v + acy * w, az + abz * v + acz * w, 1.0 - v - w, v, w, REGION_FACE)


@njit(cache=True)
def point_triangle_distance_squared(px, py, pz, vertices, triangles, t):
    a = triangles[t, 0]
    b = triangles[t, 1]
    c = triangles[t, 2]
    qx, qy, qz, wa, wb, wc, region = closest_point(
        px, py, pz, vertices[a, 0], vertices[a, 1], vertices[a, 2], vertices[b, 0], vertices[b, 1],
        vertices[b, 2], vertices[c, 0], vertices[c, 1], vertices[c, 2])
    return (px - qx) ** 2 + (py - qy) ** 2 + (pz - qz) ** 2


@njit(inline="always", cache=True)
def _vertex_in_patch(vertex, patch, vertex_patch_offsets, vertex_patches):
    for k in range(vertex_patch_offsets[vertex], vertex_patch_offsets[vertex + 1]):
        if vertex_patches[k] == patch:
            return True
    return False


@njit(cache=True)
def _plane_distance_gradient(p, xa, xb, xc, out_p, out_a, out_b, out_c):
    """d = sigma n.(p - a) >= 0 for the plane of abc, and its gradient with respect to p, a, b, c."""
    e1 = xb - xa
    e2 = xc - xa
    r = p - xa
    N = np.cross(e1, e2)
    length = math.sqrt(N[0] ** 2 + N[1] ** 2 + N[2] ** 2)
    n = N / length
    d = n[0] * r[0] + n[1] * r[1] + n[2] * r[2]
    sigma = 1.0 if d >= 0.0 else -1.0
    d_b = (np.cross(e2, r) - d * np.cross(e2, n)) / length
    d_c = (np.cross(r, e1) - d * np.cross(n, e1)) / length
    for k in range(3):
        out_p[k] = sigma * n[k]
        out_b[k] = sigma * d_b[k]
        out_c[k] = sigma * d_c[k]
        out_a[k] = -(out_p[k] + out_b[k] + out_c[k])
    return sigma * d


@njit(cache=True)
def _clipped_distance_gradient(p, xa, xb, xc, neighbours, out_p, out_a, out_b, out_c):
    """Distance from p to the triangle's plane cut at its patch-boundary edges (edges without a same-patch
    neighbour: columns ab, bc, ca), and its gradient.  Inside the interior edges the plane extends (a flat
    patch stays exact); beyond a rim edge the distance is to that edge's line, or to a rim vertex."""
    d = _plane_distance_gradient(p, xa, xb, xc, out_p, out_a, out_b, out_c)
    corners = (xa, xb, xc)
    n = np.cross(xb - xa, xc - xa)
    n = n / math.sqrt(n[0] ** 2 + n[1] ** 2 + n[2] ** 2)
    foot = p - (n[0] * (p[0] - xa[0]) + n[1] * (p[1] - xa[1]) + n[2] * (p[2] - xa[2])) * n
    outside = np.zeros(3, dtype=np.bool_)
    for e in range(3):
        if neighbours[e] >= 0:
            continue
        u = corners[e]
        v = corners[(e + 1) % 3]
        w = corners[(e + 2) % 3]
        inward = np.cross(n, v - u)
        if (inward[0] * (w[0] - u[0]) + inward[1] * (w[1] - u[1]) + inward[2] * (w[2] - u[2])) < 0.0:
            inward = -inward
        if inward[0] * (foot[0] - u[0]) + inward[1] * (foot[1] - u[1]) + inward[2] * (foot[2] - u[2]) < 0.0:
            outside[e] = True
    if not (outside[0] or outside[1] or outside[2]):
        return d
    # Nearest point of the clipped plane: on a violated rim edge's line, clamped to rim vertices.
    best = 1e300
    best_q = np.zeros(3)
    best_tau = 0.0
    best_edge = -1
    for e in range(3):
        if neighbours[e] >= 0:
            continue
        u = corners[e]
        v = corners[(e + 1) % 3]
        edge = v - u
        tau = ((p[0] - u[0]) * edge[0] + (p[1] - u[1]) * edge[1] + (p[2] - u[2]) * edge[2]) / (
            edge[0] ** 2 + edge[1] ** 2 + edge[2] ** 2)
        # Clamp at an end only where the neighbouring edge there is a rim edge too (a rim corner).
        if tau < 0.0 and neighbours[(e + 2) % 3] < 0:
            tau = 0.0
        elif tau > 1.0 and neighbours[(e + 1) % 3] < 0:
            tau = 1.0
        q = u + tau * edge
        distance = math.sqrt((p[0] - q[0]) ** 2 + (p[1] - q[1]) ** 2 + (p[2] - q[2]) ** 2)
        if outside[e] and distance < best:
            best = distance
            best_q = q
            best_tau = tau
            best_edge = e
    if best_edge < 0 or best == 0.0:
        return d
    r = (p - best_q) / best
    gradients = (out_a, out_b, out_c)
    for k in range(3):
        out_p[k] = r[k]
        out_a[k] = 0.0
        out_b[k] = 0.0
        out_c[k] = 0.0
    first_corner = best_edge
    second_corner = (best_edge + 1) % 3
    for k in range(3):
        gradients[first_corner][k] = -(1.0 - best_tau) * r[k]
        gradients[second_corner][k] = -best_tau * r[k]
    return best


@njit(cache=True)
def blend_overlap(px, py, pz, radius, patch, first, last_k, candidate_triangles, vertices, triangles, triangle_patch,
                  gradient_p, node_scale, vertex_forces, edge_neighbours, share_vertex, share_value, share_start):
    """The blended overlap (module docstring): delta = sum_t k(s_t) (R - d_t) / sum_t k(s_t) over the patch's
    candidate triangles closer than R (s_t the point-triangle distance, k = (1 - s^2/R^2)^2, d_t the distance to
    the triangle's plane cut at the patch's boundary edges); gradient_p <- d delta / d p; when node_scale != 0,
    vertex_forces[k] += node_scale * d delta / d x_k.  Two passes: the weighted sum, then (with delta known) the
    derivatives, whose weight terms carry (R - d_t - delta).  With share_start >= 0 the second pass also writes, from
    row share_start on, each blended facet's vertices with their share of the contact, (omega_t / sum omega) times
    the barycentric weight of the facet's nearest point (>= 0, summing to 1 over the rows): the contact springs
    over the FE sub-steps spread by them (coupling/dampers.py).  Returns (delta, weight sum, the rows' end)."""
    p = np.array([px, py, pz])
    g_p = np.zeros(3)
    g_a = np.zeros(3)
    g_b = np.zeros(3)
    g_c = np.zeros(3)
    total = 0.0
    weighted = 0.0
    for k in range(first, last_k):
        t = candidate_triangles[k]
        if triangle_patch[t] != patch:
            continue
        a = triangles[t, 0]
        b = triangles[t, 1]
        c = triangles[t, 2]
        qx, qy, qz, wa, wb, wc, region = closest_point(px, py, pz, vertices[a, 0], vertices[a, 1], vertices[a, 2],
                                                        vertices[b, 0], vertices[b, 1], vertices[b, 2],
                                                        vertices[c, 0], vertices[c, 1], vertices[c, 2])
        s = math.sqrt((px - qx) ** 2 + (py - qy) ** 2 + (pz - qz) ** 2)
        if s >= radius:
            continue
        omega = (1.0 - s * s / (radius * radius)) ** 2
        d = _clipped_distance_gradient(p, vertices[a], vertices[b], vertices[c], edge_neighbours[t], g_p, g_a, g_b,
                                       g_c)
        total += omega
        weighted += omega * (radius - d)
    shares = share_start
    if total == 0.0:
        return 0.0, 0.0, shares
    delta = weighted / total
    gradient_p[:] = 0.0
    for k in range(first, last_k):
        t = candidate_triangles[k]
        if triangle_patch[t] != patch:
            continue
        a = triangles[t, 0]
        b = triangles[t, 1]
        c = triangles[t, 2]
        qx, qy, qz, wa, wb, wc, region = closest_point(px, py, pz, vertices[a, 0], vertices[a, 1], vertices[a, 2],
                                                        vertices[b, 0], vertices[b, 1], vertices[b, 2],
                                                        vertices[c, 0], vertices[c, 1], vertices[c, 2])
        s = math.sqrt((px - qx) ** 2 + (py - qy) ** 2 + (pz - qz) ** 2)
        if s >= radius:
            continue
        omega = (1.0 - s * s / (radius * radius)) ** 2
        if shares >= 0:
            share_vertex[shares] = a
            share_value[shares] = omega * wa / total
            share_vertex[shares + 1] = b
            share_value[shares + 1] = omega * wb / total
            share_vertex[shares + 2] = c
            share_value[shares + 2] = omega * wc / total
            shares += 3
        if s == 0.0:
            continue
        domega = -4.0 * s * (1.0 - s * s / (radius * radius)) / (radius * radius)
        d = _clipped_distance_gradient(p, vertices[a], vertices[b], vertices[c], edge_neighbours[t], g_p, g_a, g_b,
                                       g_c)
        h = radius - d
        ux = (px - qx) / s
        uy = (py - qy) / s
        uz = (pz - qz) / s
        factor = (h - delta) * domega / total
        # d s / d p = u ; d s / d x_k = -w_k u
        gradient_p[0] += (-omega * g_p[0]) / total + factor * ux
        gradient_p[1] += (-omega * g_p[1]) / total + factor * uy
        gradient_p[2] += (-omega * g_p[2]) / total + factor * uz
        if node_scale != 0.0:
            for axis in range(3):
                u_axis = ux if axis == 0 else (uy if axis == 1 else uz)
                vertex_forces[a, axis] += node_scale * ((-omega * g_a[axis]) / total - factor * wa * u_axis)
                vertex_forces[b, axis] += node_scale * ((-omega * g_b[axis]) / total - factor * wb * u_axis)
                vertex_forces[c, axis] += node_scale * ((-omega * g_c[axis]) / total - factor * wc * u_axis)
    return delta, total, shares


@njit(cache=True)
def mesh_contact_forces(first, last, candidate_offsets, candidate_triangles,
                        vertices, vertex_velocities, triangles, triangle_patch,
                        vertex_patch_offsets, vertex_patches, one_sided, wall_material,
                        slot_patch, slot_history, blended, blend_gradient, edge_neighbours,
                        positions, velocities, angular_velocities, radii, mass, inverse_inertia, material_index,
                        coefficients, composition, cohesion_reach, dt,
                        forces, torques, totals, spread_to_vertices, vertex_forces,
                        record_particle, record_triangle, record_weights, record_point, record_force,
                        record_damping, share_contact, share_vertex, share_value, scratch_int, scratch_float,
                        spare_history, transport_velocity, temperatures, heat_flows, vertex_temperatures, vertex_heat):
    """Add the mesh-wall contact forces of particles [first, last).

    With heat on (composition) and vertex temperatures given (an empty array: adiabatic), a contact
    conducts to the surface temperature at its point, interpolated by the barycentric weights, and its
    heat goes to the triangle's vertices by the same weights (vertex_heat += weight x flow x dt [J], when
    vertex_heat is not empty): the particle's heat and the vertices' balance exactly.

    totals[0:3] += force on the wall, totals[3:6] += its moment about the origin
    (sum of q x F_wall minus the rolling couples).  One record per contact
    (particle index, triangle, barycentric weights, contact point, force on the
    wall, and in record_damping the contact's dashpot: c_n, c_t, normal (3), lever (the contact
    point lies lever * normal below the centre), the particle's contact-point velocity (3) and the
    surface velocity there (3), see pdemfem.coupling.dampers).  scratch_int (M, 5) / scratch_float (M, 8) hold the per-patch
    proposals of one particle (M >= the longest candidate list).  A cohesive contact (composition) holds
    beyond touching down to its pull-off overlap: triangles within radius + cohesion_reach propose.
    transport_velocity (3): a conveyor surface's velocity; its part along the contact's tangent plane
    adds to the surface velocity the contact law sees (the geometry does not move).
    A blended contact (blended: the blended gap applied) spreads its normal contact spring over the blended facets'
    vertices instead of its nearest triangle's: rows of share_contact (the contact's record), share_vertex and
    share_value (S_n times the vertex's share, blend_overlap), and its record's S_n is 0 (coupling/dampers.py).
    share_* hold at least 3 rows per candidate triangle.
    Returns (elastic, dissipated, contacts, work done on the particles by the wall, heat [J] it gave them, the
    share rows written, the deepest overlap as a fraction of the particle's radius).
    """
    touching_column = history_layout(composition)[2]
    conducting = (composition & HEAT) != 0 and vertex_temperatures.shape[0] > 0
    heat = 0.0
    overlap_column = slot_history.shape[2] - 1
    elastic_total = 0.0
    dissipated_total = 0.0
    work = 0.0
    contacts = 0
    shares = 0
    deepest = 0.0
    slots = slot_patch.shape[1]
    for i in range(first, last):
        px = positions[i, 0]
        py = positions[i, 1]
        pz = positions[i, 2]
        radius = radii[i]
        reach = radius + cohesion_reach
        radius_squared = reach * reach
        proposals = 0
        # ---- nearest point of each patch among the candidate triangles
        for k in range(candidate_offsets[i], candidate_offsets[i + 1]):
            t = candidate_triangles[k]
            a = triangles[t, 0]
            b = triangles[t, 1]
            c = triangles[t, 2]
            ax = vertices[a, 0]
            ay = vertices[a, 1]
            az = vertices[a, 2]
            bx = vertices[b, 0]
            by = vertices[b, 1]
            bz = vertices[b, 2]
            cx = vertices[c, 0]
            cy = vertices[c, 1]
            cz = vertices[c, 2]
            qx, qy, qz, wa, wb, wc, region = closest_point(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz)
            dx = px - qx
            dy = py - qy
            dz = pz - qz
            distance_squared = dx * dx + dy * dy + dz * dz
            if distance_squared >= radius_squared:
                continue
            # Unit normal of the triangle (right-hand rule a -> b -> c).
            nx = (by - ay) * (cz - az) - (bz - az) * (cy - ay)
            ny = (bz - az) * (cx - ax) - (bx - ax) * (cz - az)
            nz = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
            length = math.sqrt(nx * nx + ny * ny + nz * nz)
            if length == 0.0:
                continue
            nx /= length
            ny /= length
            nz /= length
            signed = (px - ax) * nx + (py - ay) * ny + (pz - az) * nz
            if one_sided and signed < 0.0:
                continue
            if region == REGION_FACE:
                # The plane distance, exactly as an analytic plane computes it.
                distance = abs(signed)
                if signed < 0.0:
                    nx = -nx
                    ny = -ny
                    nz = -nz
            else:
                distance = math.sqrt(distance_squared)
                if distance > 0.0:
                    nx = dx / distance
                    ny = dy / distance
                    nz = dz / distance
            patch = triangle_patch[t]
            slot = -1
            for j in range(proposals):
                if scratch_int[j, 0] == patch:
                    slot = j
                    break
            if slot < 0:
                slot = proposals
                proposals += 1
            elif distance >= scratch_float[slot, 0]:
                continue
            scratch_int[slot, 0] = patch
            scratch_int[slot, 1] = t
            scratch_int[slot, 2] = region
            # The feature the point lies on (vertices), -1 when unused.
            if region == REGION_FACE:
                scratch_int[slot, 3] = -1
                scratch_int[slot, 4] = -1
            elif region == REGION_EDGE_AB:
                scratch_int[slot, 3] = a
                scratch_int[slot, 4] = b
            elif region == REGION_EDGE_BC:
                scratch_int[slot, 3] = b
                scratch_int[slot, 4] = c
            elif region == REGION_EDGE_CA:
                scratch_int[slot, 3] = c
                scratch_int[slot, 4] = a
            elif region == REGION_VERTEX_A:
                scratch_int[slot, 3] = a
                scratch_int[slot, 4] = -1
            elif region == REGION_VERTEX_B:
                scratch_int[slot, 3] = b
                scratch_int[slot, 4] = -1
            else:
                scratch_int[slot, 3] = c
                scratch_int[slot, 4] = -1
            scratch_float[slot, 0] = distance
            scratch_float[slot, 1] = nx
            scratch_float[slot, 2] = ny
            scratch_float[slot, 3] = nz
            scratch_float[slot, 4] = wa
            scratch_float[slot, 5] = wb
            scratch_float[slot, 6] = wc
            # Column 7: 1 kept, 0 undecided, -1 dropped.
            scratch_float[slot, 7] = 1.0 if region == REGION_FACE else 0.0

        # ---- feature contacts, deepest first, unless a kept contact's patch owns the feature
        while True:
            best = -1
            for j in range(proposals):
                if scratch_float[j, 7] == 0.0 and (best < 0 or scratch_float[j, 0] < scratch_float[best, 0]):
                    best = j
            if best < 0:
                break
            f0 = scratch_int[best, 3]
            f1 = scratch_int[best, 4]
            covered = False
            for j in range(proposals):
                if scratch_float[j, 7] == 1.0:
                    patch = scratch_int[j, 0]
                    if _vertex_in_patch(f0, patch, vertex_patch_offsets, vertex_patches) and (
                            f1 < 0 or _vertex_in_patch(f1, patch, vertex_patch_offsets, vertex_patches)):
                        covered = True
                        break
            scratch_float[best, 7] = -1.0 if covered else 1.0

        # ---- a kept proposal that does not touch acts only as a formed cohesive contact above its pull-off
        if cohesion_reach > 0.0:
            for j in range(proposals):
                if scratch_float[j, 7] != 1.0 or scratch_float[j, 0] < radius:
                    continue
                holds = False
                for s in range(slots):
                    if slot_patch[i, s] == scratch_int[j, 0]:
                        holds = slot_history[i, s, touching_column] != 0.0 and radius - scratch_float[j, 0] > (
                            pull_off_overlap(composition, coefficients, material_index[i], wall_material, radius))
                        break
                if not holds:
                    scratch_float[j, 7] = -1.0

        # ---- history slots: match kept patches, release the others, then open new ones
        for s in range(slots):
            patch = slot_patch[i, s]
            if patch < 0:
                continue
            matched = False
            for j in range(proposals):
                if scratch_float[j, 7] == 1.0 and scratch_int[j, 0] == patch:
                    matched = True
                    break
            if not matched:
                history = slot_history[i]
                if history_in_use(composition, history, s):
                    dissipated_total += released_energy(composition, coefficients, material_index[i], wall_material,
                                                        history[s, overlap_column], mass[i], radius, history, s)
                slot_patch[i, s] = -1
                for column in range(overlap_column + 1):
                    slot_history[i, s, column] = 0.0

        for j in range(proposals):
            if scratch_float[j, 7] != 1.0:
                continue
            patch = scratch_int[j, 0]
            t = scratch_int[j, 1]
            distance = scratch_float[j, 0]
            nx = scratch_float[j, 1]
            ny = scratch_float[j, 2]
            nz = scratch_float[j, 3]
            wa = scratch_float[j, 4]
            wb = scratch_float[j, 5]
            wc = scratch_float[j, 6]
            slot = -1
            for s in range(slots):
                if slot_patch[i, s] == patch:
                    slot = s
                    break
            if slot < 0:
                for s in range(slots):
                    if slot_patch[i, s] < 0:
                        slot = s
                        slot_patch[i, s] = patch
                        break
            history = slot_history[i]
            if slot < 0:
                # More simultaneous contacts than slots: this one runs without history.
                history = spare_history
                for column in range(overlap_column + 1):
                    spare_history[0, column] = 0.0
                slot = 0
            a = triangles[t, 0]
            b = triangles[t, 1]
            c = triangles[t, 2]
            # The contact point on the surface (`distance` below the centre), as the weighted vertex sum so
            # that spreading the force by the weights reproduces its moment exactly.
            qx = wa * vertices[a, 0] + wb * vertices[b, 0] + wc * vertices[c, 0]
            qy = wa * vertices[a, 1] + wb * vertices[b, 1] + wc * vertices[c, 1]
            qz = wa * vertices[a, 2] + wb * vertices[b, 2] + wc * vertices[c, 2]
            # Surface velocity at the contact point: barycentric interpolation (exact for rigid motion).
            sx = wa * vertex_velocities[a, 0] + wb * vertex_velocities[b, 0] + wc * vertex_velocities[c, 0]
            sy = wa * vertex_velocities[a, 1] + wb * vertex_velocities[b, 1] + wc * vertex_velocities[c, 1]
            sz = wa * vertex_velocities[a, 2] + wb * vertex_velocities[b, 2] + wc * vertex_velocities[c, 2]
            scale = 1.0
            blend_applied = False
            first_share = shares
            normal_elastic_force = 0.0
            if blended:
                # The blended gap (module docstring): its normal and overlap; scale = |grad_p delta|.
                delta, total, _ = blend_overlap(px, py, pz, radius, patch, candidate_offsets[i],
                                                candidate_offsets[i + 1], candidate_triangles, vertices, triangles,
                                                triangle_patch, blend_gradient, 0.0, vertex_forces, edge_neighbours,
                                                share_vertex, share_value, -1)
                norm = math.sqrt(blend_gradient[0] ** 2 + blend_gradient[1] ** 2 + blend_gradient[2] ** 2)
                if total > 0.0 and norm > 0.0 and delta > 0.0:
                    nx = -blend_gradient[0] / norm
                    ny = -blend_gradient[1] / norm
                    nz = -blend_gradient[2] / norm
                    distance = radius - delta
                    scale = norm
                    blend_applied = True
            # Conveyor: the surface material moves along the surface (the tangential part at this contact).
            along = transport_velocity[0] * nx + transport_velocity[1] * ny + transport_velocity[2] * nz
            sx += transport_velocity[0] - along * nx
            sy += transport_velocity[1] - along * ny
            sz += transport_velocity[2] - along * nz
            fx, fy, fz, tx, ty, tz, mx, my, mz, elastic, dissipated, normal_damping, tangential_damping = (
                rigid_wall_contact(composition, coefficients, material_index[i], wall_material, nx, ny, nz, distance,
                                   sx, sy, sz, velocities[i, 0], velocities[i, 1], velocities[i, 2],
                                   angular_velocities[i, 0], angular_velocities[i, 1], angular_velocities[i, 2],
                                   radius, radius, mass[i], inverse_inertia[i], history, slot, dt))
            add_particle_loads(forces, torques, i, fx, fy, fz, tx, ty, tz)
            if blend_applied:
                # Split the force: the normal elastic part f_el n acts as the blended potential's gradient (on the
                # particle f_el |grad delta| n, on the nodes -f_el d delta/d x_k); the dashpot and tangential
                # rest stays a point force on the nearest triangle (records, dampers.py).  The normal dashpot is
                # -c_n (v - s).n (the contact point's rotation adds nothing along n).
                approach = ((velocities[i, 0] - sx) * nx + (velocities[i, 1] - sy) * ny
                            + (velocities[i, 2] - sz) * nz)
                normal_elastic_force = fx * nx + fy * ny + fz * nz + normal_damping * approach
                extra = (scale - 1.0) * normal_elastic_force
                forces[i, 0] += extra * nx
                forces[i, 1] += extra * ny
                forces[i, 2] += extra * nz
                _, _, shares = blend_overlap(px, py, pz, radius, patch, candidate_offsets[i], candidate_offsets[i + 1],
                                             candidate_triangles, vertices, triangles, triangle_patch, blend_gradient,
                                             -normal_elastic_force, vertex_forces, edge_neighbours, share_vertex,
                                             share_value, shares)
                # The wall's total force (totals, records' sum) is the particle's; the records carry the rest.
                elastic_x = scale * normal_elastic_force * nx
                elastic_y = scale * normal_elastic_force * ny
                elastic_z = scale * normal_elastic_force * nz
                totals[0] -= elastic_x
                totals[1] -= elastic_y
                totals[2] -= elastic_z
                # Its moment taken at the nearest point (the nodal forces' own moment differs by the spread).
                totals[3] -= qy * elastic_z - qz * elastic_y
                totals[4] -= qz * elastic_x - qx * elastic_z
                totals[5] -= qx * elastic_y - qy * elastic_x
                fx -= normal_elastic_force * nx
                fy -= normal_elastic_force * ny
                fz -= normal_elastic_force * nz
            history[slot, overlap_column] = radius - distance  # this step's overlap
            deepest = max(deepest, (radius - distance) / radius)
            if conducting:
                conductance = contact_conductance(composition, coefficients, material_index[i], wall_material,
                                                  radius - distance, mass[i], radius)
                surface_temperature = (wa * vertex_temperatures[a] + wb * vertex_temperatures[b]
                                       + wc * vertex_temperatures[c])
                flow = conductance * (surface_temperature - temperatures[i])
                heat_flows[i, 0] += flow
                heat_flows[i, 1] += conductance
                heat += flow * dt
                if vertex_heat.shape[0] > 0:
                    vertex_heat[a] -= wa * flow * dt
                    vertex_heat[b] -= wb * flow * dt
                    vertex_heat[c] -= wc * flow * dt
            elastic_total += elastic
            dissipated_total += dissipated
            work += (fx * sx + fy * sy + fz * sz) * dt
            # The wall gets -F at q and the opposite rolling couple.
            totals[0] -= fx
            totals[1] -= fy
            totals[2] -= fz
            totals[3] += -(qy * fz - qz * fy) - mx
            totals[4] += -(qz * fx - qx * fz) - my
            totals[5] += -(qx * fy - qy * fx) - mz
            if contacts < record_particle.shape[0]:
                record_particle[contacts] = i
                record_triangle[contacts] = t
                record_weights[contacts, 0] = wa
                record_weights[contacts, 1] = wb
                record_weights[contacts, 2] = wc
                record_point[contacts, 0] = qx
                record_point[contacts, 1] = qy
                record_point[contacts, 2] = qz
                record_force[contacts, 0] = -fx
                record_force[contacts, 1] = -fy
                record_force[contacts, 2] = -fz
                record_damping[contacts, 0] = normal_damping
                record_damping[contacts, 1] = tangential_damping
                record_damping[contacts, 2] = nx
                record_damping[contacts, 3] = ny
                record_damping[contacts, 4] = nz
                record_damping[contacts, 5] = distance
                wx = angular_velocities[i, 0]
                wy = angular_velocities[i, 1]
                wz = angular_velocities[i, 2]
                record_damping[contacts, 6] = velocities[i, 0] - distance * (wy * nz - wz * ny)
                record_damping[contacts, 7] = velocities[i, 1] - distance * (wz * nx - wx * nz)
                record_damping[contacts, 8] = velocities[i, 2] - distance * (wx * ny - wy * nx)
                record_damping[contacts, 9] = sx
                record_damping[contacts, 10] = sy
                record_damping[contacts, 11] = sz
                stiffness = normal_elastic(int(coefficients[material_index[i], wall_material, NORMAL_MODEL]),
                                           composition, radius - distance, coefficients, material_index[i],
                                           wall_material, mass[i], radius)
                record_damping[contacts, 12] = max(stiffness[1], 0.0)
                if blend_applied:
                    # The normal spring goes where the blended gap spread the held normal force: over the blended
                    # facets' vertices (coupling/dampers.py).
                    for row in range(first_share, shares):
                        share_contact[row] = contacts
                        share_value[row] *= record_damping[contacts, 12]
                    record_damping[contacts, 12] = 0.0
                # The tangential spring while the contact sticks (its force below the Coulomb limit): sliding, the
                # force does not follow the displacement.
                # (The blended gap took the normal elastic part out of f above; the Coulomb limit is the whole
                # normal force's.  Without it a blended contact never stuck: no tangential spring, and a sphere
                # resting with friction on a sub-stepped block pumped energy through its held tangential force.)
                normal_part = fx * nx + fy * ny + fz * nz + normal_elastic_force
                tangential_squared = (fx * fx + fy * fy + fz * fz) - normal_part * normal_part
                limit = coefficients[material_index[i], wall_material, FRICTION] * max(normal_part, 0.0)
                sticking = tangential_squared < (1.0 - 1e-9) * limit * limit
                record_damping[contacts, 13] = max(stiffness[2], 0.0) if sticking else 0.0
            if spread_to_vertices:
                vertex_forces[a, 0] -= wa * fx
                vertex_forces[a, 1] -= wa * fy
                vertex_forces[a, 2] -= wa * fz
                vertex_forces[b, 0] -= wb * fx
                vertex_forces[b, 1] -= wb * fy
                vertex_forces[b, 2] -= wb * fz
                vertex_forces[c, 0] -= wc * fx
                vertex_forces[c, 1] -= wc * fy
                vertex_forces[c, 2] -= wc * fz
            contacts += 1
    return elastic_total, dissipated_total, contacts, work, heat, shares, deepest


@njit(cache=True)
def largest_displacement(current, reference, first, last):
    """max |current[k] - reference[k]| over rows [first, last)."""
    largest = 0.0
    for k in range(first, last):
        d = ((current[k, 0] - reference[k, 0]) ** 2 + (current[k, 1] - reference[k, 1]) ** 2
             + (current[k, 2] - reference[k, 2]) ** 2)
        if d > largest:
            largest = d
    return math.sqrt(largest)
