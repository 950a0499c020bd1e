"""Numba kernels on flat arrays: element integrals, owned-row assembly, loads, stress, explicit update.

Conventions: coords (n_local, 3), cells (n_cells, nen) local node numbers; rows
with local number < n_owned are owned by this rank and are the only ones a
kernel writes (halo cells supply the rest of an owned row's sum).  Elements
are straight-sided: one Jacobian per cell.  Stress/strain in Voigt order
xx, yy, zz, yz, xz, xy (engineering shear strains).
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def cell_jacobian_inverse(coords, cells, c, jinv):
    """Fill jinv (3,3) = dxi/dx of cell c; return det(dx/dxi) = 6 * volume."""
    n0 = cells[c, 0]
    j = np.empty((3, 3))
    for k in range(3):
        nk = cells[c, k + 1]
        for d in range(3):
            j[d, k] = coords[nk, d] - coords[n0, d]  # column k = x_k - x_0
    det = (
        j[0, 0] * (j[1, 1] * j[2, 2] - j[1, 2] * j[2, 1])
        - j[0, 1] * (j[1, 0] * j[2, 2] - j[1, 2] * j[2, 0])
        + j[0, 2] * (j[1, 0] * j[2, 1] - j[1, 1] * j[2, 0])
    )
    inv = 1.0 / det
    jinv[0, 0] = (j[1, 1] * j[2, 2] - j[1, 2] * j[2, 1]) * inv
    jinv[0, 1] = (j[0, 2] * j[2, 1] - j[0, 1] * j[2, 2]) * inv
    jinv[0, 2] = (j[0, 1] * j[1, 2] - j[0, 2] * j[1, 1]) * inv
    jinv[1, 0] = (j[1, 2] * j[2, 0] - j[1, 0] * j[2, 2]) * inv
    jinv[1, 1] = (j[0, 0] * j[2, 2] - j[0, 2] * j[2, 0]) * inv
    jinv[1, 2] = (j[0, 2] * j[1, 0] - j[0, 0] * j[1, 2]) * inv
    jinv[2, 0] = (j[1, 0] * j[2, 1] - j[1, 1] * j[2, 0]) * inv
    jinv[2, 1] = (j[0, 1] * j[2, 0] - j[0, 0] * j[2, 1]) * inv
    jinv[2, 2] = (j[0, 0] * j[1, 1] - j[0, 1] * j[1, 0]) * inv
    return det


@njit(cache=True)
def physical_gradients(ref_grads_q, jinv, out):
    """out[a, i] = sum_k dN_a/dxi_k * dxi_k/dx_i for one quadrature point."""
    nen = ref_grads_q.shape[0]
    for a in range(nen):
        for i in range(3):
            s = 0.0
            for k in range(3):
                s += ref_grads_q[a, k] * jinv[k, i]
            out[a, i] = s


@njit(cache=True)
def element_stiffness_mass(coords, cells, c, stiff_grads, stiff_weights, mass_values, mass_weights, lam, mu, rho, ke, me):
    """Element stiffness ke (nen,nen,3,3) and scalar consistent mass me (nen,nen) of cell c; returns volume."""
    nen = cells.shape[1]
    jinv = np.empty((3, 3))
    det = cell_jacobian_inverse(coords, cells, c, jinv)
    g = np.empty((nen, 3))
    ke[:] = 0.0
    me[:] = 0.0
    for q in range(stiff_weights.shape[0]):
        physical_gradients(stiff_grads[q], jinv, g)
        wq = stiff_weights[q] * det
        for a in range(nen):
            for b in range(nen):
                dot = g[a, 0] * g[b, 0] + g[a, 1] * g[b, 1] + g[a, 2] * g[b, 2]
                for i in range(3):
                    for j in range(3):
                        ke[a, b, i, j] += wq * (lam * g[a, i] * g[b, j] + mu * g[a, j] * g[b, i])
                    ke[a, b, i, i] += wq * mu * dot
    for q in range(mass_weights.shape[0]):
        wq = mass_weights[q] * det * rho
        for a in range(nen):
            for b in range(nen):
                me[a, b] += wq * mass_values[q, a] * mass_values[q, b]
    return det / 6.0


@njit(cache=True)
def hrz_lumping(me, volume, rho, out):
    """HRZ lumped masses of one element: diagonal of me scaled to the element mass (row sum for P1)."""
    nen = me.shape[0]
    trace = 0.0
    for a in range(nen):
        trace += me[a, a]
    scale = rho * volume / trace
    for a in range(nen):
        out[a] = me[a, a] * scale


@njit(cache=True)
def _find(indices, start, end, value):
    lo, hi = start, end - 1
    while lo <= hi:
        mid = (lo + hi) // 2
        if indices[mid] < value:
            lo = mid + 1
        elif indices[mid] > value:
            hi = mid - 1
        else:
            return mid
    return -1


@njit(cache=True)
def assemble_owned_rows(coords, cells, n_owned, indptr, indices, stiff_grads, stiff_weights, mass_values, mass_weights,
                        lam, mu, rho, k_values, m_values, lumped):
    """Add every local cell's K (blocks 3x3) and consistent M (scalar) into the owned-row CSR; HRZ lumped mass too."""
    nen = cells.shape[1]
    ke = np.empty((nen, nen, 3, 3))
    me = np.empty((nen, nen))
    ml = np.empty(nen)
    for c in range(cells.shape[0]):
        volume = element_stiffness_mass(coords, cells, c, stiff_grads, stiff_weights, mass_values, mass_weights, lam, mu, rho, ke, me)
        hrz_lumping(me, volume, rho, ml)
        for a in range(nen):
            row = cells[c, a]
            if row >= n_owned:
                continue
            lumped[row] += ml[a]
            for b in range(nen):
                pos = _find(indices, indptr[row], indptr[row + 1], cells[c, b])
                m_values[pos] += me[a, b]
                for i in range(3):
                    for j in range(3):
                        k_values[pos, i, j] += ke[a, b, i, j]


@njit(cache=True)
def element_matrices(coords, cells, cell_ids, stiff_grads, stiff_weights, mass_values, mass_weights, lam, mu, rho, k_out, m_out, lumped_out):
    """Dense element matrices of the given cells: k_out (m, 3nen, 3nen), m_out (m, nen, nen), lumped_out (m, nen)."""
    nen = cells.shape[1]
    ke = np.empty((nen, nen, 3, 3))
    me = np.empty((nen, nen))
    ml = np.empty(nen)
    for e in range(cell_ids.shape[0]):
        volume = element_stiffness_mass(coords, cells, cell_ids[e], stiff_grads, stiff_weights, mass_values, mass_weights, lam, mu, rho, ke, me)
        hrz_lumping(me, volume, rho, ml)
        for a in range(nen):
            lumped_out[e, a] = ml[a]
            for b in range(nen):
                m_out[e, a, b] = me[a, b]
                for i in range(3):
                    for j in range(3):
                        k_out[e, 3 * a + i, 3 * b + j] = ke[a, b, i, j]


@njit(cache=True)
def body_force_load(coords, cells, n_owned, mass_values, mass_weights, force_density, out):
    """out[a] += int N_a * force_density dV over local cells, owned rows only (force_density = rho g)."""
    nen = cells.shape[1]
    jinv = np.empty((3, 3))
    for c in range(cells.shape[0]):
        det = cell_jacobian_inverse(coords, cells, c, jinv)
        for a in range(nen):
            row = cells[c, a]
            if row >= n_owned:
                continue
            s = 0.0
            for q in range(mass_weights.shape[0]):
                s += mass_weights[q] * mass_values[q, a]
            for d in range(3):
                out[row, d] += s * det * force_density[d]


@njit(cache=True)
def thermal_load(coords, cells, n_owned, n_owned_cells, mass_values, mass_grads, mass_weights, delta_t, load_coefficient,
                 energy_coefficient, out):
    """out[a] += int load_coefficient * dT * grad N_a dV (owned rows); returns int energy_coefficient dT^2 dV (owned cells)."""
    nen = cells.shape[1]
    jinv = np.empty((3, 3))
    g = np.empty((nen, 3))
    energy = 0.0
    for c in range(cells.shape[0]):
        det = cell_jacobian_inverse(coords, cells, c, jinv)
        for q in range(mass_weights.shape[0]):
            t = 0.0
            for a in range(nen):
                t += mass_values[q, a] * delta_t[cells[c, a]]
            wq = mass_weights[q] * det
            if c < n_owned_cells:
                energy += wq * energy_coefficient * t * t
            if t == 0.0:
                continue
            physical_gradients(mass_grads[q], jinv, g)
            for a in range(nen):
                row = cells[c, a]
                if row < n_owned:
                    for d in range(3):
                        out[row, d] += wq * load_coefficient * t * g[a, d]
    return energy


@njit(cache=True)
def face_node_areas(coords, faces, n_owned, out):
    """out[a] += int_face N_a dA over the faces, owned rows only: A/3 per corner of a 3-node face, A/3 per
    midside (0 per corner) of a 6-node face (exact for straight-sided faces).  A uniform traction's
    consistent load is these shares times the traction; a uniform heat flux's, times the flux."""
    for f in range(faces.shape[0]):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        e1 = coords[b] - coords[a]
        e2 = coords[c] - coords[a]
        nx = e1[1] * e2[2] - e1[2] * e2[1]
        ny = e1[2] * e2[0] - e1[0] * e2[2]
        nz = e1[0] * e2[1] - e1[1] * e2[0]
        share = 0.5 * np.sqrt(nx * nx + ny * ny + nz * nz) / 3.0
        first = 0 if faces.shape[1] == 3 else 3
        for k in range(first, first + 3):
            row = faces[f, k]
            if row < n_owned:
                out[row] += share


@njit(cache=True)
def cell_stresses(coords, cells, n_cells, displacement, delta_t, centroid_grads, centroid_values, lam, mu, thermal_coefficient, out):
    """Voigt stress at each owned cell's centroid: lam tr(eps) I + 2 mu eps - 3 K alpha dT I."""
    nen = cells.shape[1]
    jinv = np.empty((3, 3))
    g = np.empty((nen, 3))
    for c in range(n_cells):
        cell_jacobian_inverse(coords, cells, c, jinv)
        physical_gradients(centroid_grads, jinv, g)
        grad_u = np.zeros((3, 3))
        t = 0.0
        for a in range(nen):
            node = cells[c, a]
            t += centroid_values[a] * delta_t[node]
            for i in range(3):
                for j in range(3):
                    grad_u[i, j] += displacement[node, i] * g[a, j]
        trace = grad_u[0, 0] + grad_u[1, 1] + grad_u[2, 2]
        p = lam * trace - thermal_coefficient * t
        out[c, 0] = p + 2.0 * mu * grad_u[0, 0]
        out[c, 1] = p + 2.0 * mu * grad_u[1, 1]
        out[c, 2] = p + 2.0 * mu * grad_u[2, 2]
        out[c, 3] = mu * (grad_u[1, 2] + grad_u[2, 1])
        out[c, 4] = mu * (grad_u[0, 2] + grad_u[2, 0])
        out[c, 5] = mu * (grad_u[0, 1] + grad_u[1, 0])


@njit(cache=True)
def central_difference_update(u, v, acceleration, internal, base_load, nodal_load, load, inverse_mass, constrained,
                              prescribed_velocity, dt, decay, gain, lumped, clear_nodal, mass_damping, lumped_mass,
                              stiffness_damping_force):
    """One explicit step on owned dofs (flat arrays); returns this rank's increments of the external work, of the
    supports' work alone and of the work the Rayleigh damping took, and the supports' work over the second half
    of this step.

    load = base_load + nodal_load (nodal_load then cleared when asked); M a = load - internal at free dofs (a = (load - internal) * inverse_mass when lumped, else
    `acceleration` holds the solve's result); v+ = decay * v + gain * dt * a; constrained dofs take
    their prescribed velocity; u += dt * v+.  Work uses the midpoint displacement increment
    dt (v- + v+)/2 with the applied load at free dofs and the support force (= internal, a = 0) at
    constrained ones.  The supports' own work is their reaction (internal - load, a = 0) on the same increment:
    zero where they hold a node still, the energy a prescribed velocity feeds in otherwise.  That increment is
    centred on u^n while the strain energy is read at u^{n+1}: the reaction's work over the half step
    dt v+ / 2 closes the gap (without it the books lag by the current reaction's work over half a step, which
    grows with the reaction).

    The damping's forces at free dofs, on the same increment: alpha M (v- + v+) / 2 (the decay and gain
    factors; mass_damping = alpha with lumped mass, 0 with consistent mass, whose term the caller books with
    the consistent M) and beta K v- (stiffness_damping_force, inside `internal`; empty without beta).  With
    them booked, central difference's modified energy plus the damping's work is conserved to round-off.
    """
    work = 0.0
    support_work = 0.0
    support_half_step = 0.0
    damping_work = 0.0
    stiffness_damping = stiffness_damping_force.shape[0] > 0
    for i in range(u.shape[0]):
        f = base_load[i] + nodal_load[i]
        load[i] = f  # kept for reactions
        if clear_nodal:
            nodal_load[i] = 0.0
        if constrained[i]:
            a = 0.0
            v_new = prescribed_velocity[i]
            force = internal[i]
            support_work += (internal[i] - f) * 0.5 * dt * (v[i] + v_new)
            support_half_step += (internal[i] - f) * 0.5 * dt * v_new
        else:
            if lumped:
                a = (f - internal[i]) * inverse_mass[i]
            else:
                a = acceleration[i]
            v_new = decay * v[i] + gain * dt * a
            force = f
            damping_force = mass_damping * lumped_mass[i] * 0.5 * (v[i] + v_new)
            if stiffness_damping:
                damping_force += stiffness_damping_force[i]
            damping_work += damping_force * 0.5 * dt * (v[i] + v_new)
        acceleration[i] = a
        work += force * 0.5 * dt * (v[i] + v_new)
        v[i] = v_new
        u[i] += dt * v_new
    return work, support_work, support_half_step, damping_work


@njit(cache=True)
def contact_spring_forces(u, damped_nodes, dampers, spring_rows, start, integral, dt, nodal_load):
    """The contact springs' forces -S (u - u0) at the current displacement (flat dof arrays), added to nodal_load
    and returned per spring (len(spring_rows), 3); integral += dt (u - u0), the time integral over the sub-steps
    (the particles' balancing impulse, coupling/dampers.py).  dampers[row, 9:15] = S (xx, yy, zz, yz, xz, xy)."""
    forces = np.empty((spring_rows.shape[0], 3))
    for k in range(spring_rows.shape[0]):
        row = spring_rows[k]
        node = damped_nodes[row]
        s = dampers[row]
        dx = u[3 * node] - start[k, 0]
        dy = u[3 * node + 1] - start[k, 1]
        dz = u[3 * node + 2] - start[k, 2]
        integral[k, 0] += dt * dx
        integral[k, 1] += dt * dy
        integral[k, 2] += dt * dz
        fx = -(s[9] * dx + s[14] * dy + s[13] * dz)
        fy = -(s[14] * dx + s[10] * dy + s[12] * dz)
        fz = -(s[13] * dx + s[12] * dy + s[11] * dz)
        forces[k, 0] = fx
        forces[k, 1] = fy
        forces[k, 2] = fz
        nodal_load[3 * node] += fx
        nodal_load[3 * node + 1] += fy
        nodal_load[3 * node + 2] += fz
    return forces


@njit(cache=True)
def remove_nodal_forces(nodes, forces, nodal_load):
    """nodal_load at `nodes` -= forces (a sub-step's spring forces taken out of the held loads again)."""
    for k in range(nodes.shape[0]):
        node = nodes[k]
        nodal_load[3 * node] -= forces[k, 0]
        nodal_load[3 * node + 1] -= forces[k, 1]
        nodal_load[3 * node + 2] -= forces[k, 2]


@njit(cache=True)
def apply_contact_dampers(u, v, acceleration, lumped_mass, constrained, damped_nodes, dampers, dt, decay, gain):
    """Implicit nodal dashpots of particle contacts, after a central-difference step (flat dof arrays).

    dampers[k] = (D_xx, D_yy, D_zz, D_yz, D_xz, D_xy, g_x, g_y, g_z) for owned node damped_nodes[k]: the
    dashpot force on the node is g - D v.  The step's undamped velocity v* is replaced by the solution of
    (m I + dt D) v = m v* + dt g (backward Euler in the dashpot: dissipative for any dt, unlike the
    dashpot held constant over the interval), and u moves by dt (v - v*) more.  Constrained dofs keep
    their prescribed velocity.  m is the lumped (row-sum) mass, also with consistent mass (an operator
    split that conserves momentum, since the consistent mass rows sum to the lumped one).
    Returns the dashpots' work on the nodes (this rank's), booked as the external work of the step is:
    the impulse m (v - v*) times the midpoint dt (v- + v)/2 of the step's displacement increments, v- the
    velocity before the step (v* = decay v- + gain dt a).  (Booking 1/2 m (v^2 - v*^2), the kinetic energy
    the split removes, would miss the strain energy the extra displacement dt (v - v*) exchanges.)
    """
    work = 0.0
    matrix = np.empty((3, 3))
    tensor = np.empty((3, 3))
    rhs = np.empty(3)
    for k in range(damped_nodes.shape[0]):
        node = damped_nodes[k]
        d = dampers[k]
        idle = True  # a node with a contact spring only: (m v) / m would round v
        for column in range(9):
            if d[column] != 0.0:
                idle = False
        if idle:
            continue
        tensor[0, 0] = d[0]
        tensor[1, 1] = d[1]
        tensor[2, 2] = d[2]
        tensor[1, 2] = tensor[2, 1] = d[3]
        tensor[0, 2] = tensor[2, 0] = d[4]
        tensor[0, 1] = tensor[1, 0] = d[5]
        for r in range(3):
            dof = 3 * node + r
            if constrained[dof]:
                for c in range(3):
                    matrix[r, c] = 0.0
                matrix[r, r] = 1.0
                rhs[r] = v[dof]
            else:
                mass = lumped_mass[dof]
                for c in range(3):
                    matrix[r, c] = dt * tensor[r, c]
                matrix[r, r] += mass
                rhs[r] = mass * v[dof] + dt * d[6 + r]
        # Gaussian elimination without pivoting: the matrix is symmetric positive definite on free rows
        # (m > 0, D positive semi-definite) and the identity on constrained ones.
        for p in range(3):
            for r in range(p + 1, 3):
                factor = matrix[r, p] / matrix[p, p]
                for c in range(p, 3):
                    matrix[r, c] -= factor * matrix[p, c]
                rhs[r] -= factor * rhs[p]
        for p in range(2, -1, -1):
            total = rhs[p]
            for c in range(p + 1, 3):
                total -= matrix[p, c] * rhs[c]
            rhs[p] = total / matrix[p, p]
        for r in range(3):
            dof = 3 * node + r
            if constrained[dof]:
                continue
            change = rhs[r] - v[dof]
            before = (v[dof] - gain * dt * acceleration[dof]) / decay
            work += lumped_mass[dof] * change * 0.5 * (before + rhs[r])
            u[dof] += dt * change
            acceleration[dof] += change / (gain * dt)
            v[dof] = rhs[r]
    return work
