"""One contact's force, torque and energies, composed from the scene's sub-models.

`contact_response` is inlined into every contact kernel (pairs, planes, cylinders, triangle
meshes).  Sign conventions: n points from the partner (j or wall) to the first body i,
`overlap` is positive in compression, v is i's contact-point velocity minus the partner's and w
their relative angular velocity; every returned force/moment acts on i (the partner gets the
opposite).  The Verlet velocities are half-step values (v^{n+1/2}), so v dt is exactly the
relative displacement of the step, which is what the springs need.

`composition` (the scene's sub-models, pdemfem.contact.layout) gates every sub-model: the branches
of unused ones are never taken (docs/contact_models.md measures what each costs).
"""
from __future__ import annotations

from numba import njit

from pdemfem.contact.damping_viscous import dashpot
from pdemfem.contact import tangential_mindlin
from pdemfem.contact.layout import COHESIVE, DAMPING, FRICTION, NORMAL_MODEL, ROLLING_ANY, ROLLING_MODEL
from pdemfem.contact.registry import (history_layout, normal_elastic, normal_friction_offset,
                                      normal_pull_off_overlap, rolling_torque, spring_energy_column)


@njit(inline="always", cache=True)
def pull_off_overlap(composition, coefficients, a, b, effective_radius):
    """The overlap (<= 0) down to which a formed contact holds; 0 without cohesive models."""
    if composition & COHESIVE:
        return normal_pull_off_overlap(int(coefficients[a, b, NORMAL_MODEL]), composition, coefficients, a, b,
                                       effective_radius)
    return 0.0


@njit(inline="always", cache=True)
def history_in_use(composition, history, row):
    """Whether the contact's history holds anything (a spring or the touching flag)."""
    width = history_layout(composition)[3]
    for column in range(width):
        if history[row, column] != 0.0:
            return True
    return False


@njit(cache=True)
def released_energy(composition, coefficients, a, b, previous_overlap, effective_mass, effective_radius,
                    history, row):
    """Energy a contact held at the previous step's overlap and loses when it opens: its springs'
    energy, and a cohesive contact's elastic energy (the adhesion hysteresis)."""
    released = 0.0
    energy_column = spring_energy_column(composition)
    if energy_column >= 0:
        released += history[row, energy_column]
    # A cohesive contact breaks holding energy (the adhesion hysteresis): its elastic energy at the last
    # overlap it held; a repulsive one opens at zero overlap, its elastic energy already returned to the motion.
    touching_column = history_layout(composition)[2]
    if touching_column >= 0 and history[row, touching_column] != 0.0 and pull_off_overlap(
            composition, coefficients, a, b, effective_radius) < 0.0:
        released += normal_elastic(int(coefficients[a, b, NORMAL_MODEL]), composition, previous_overlap, coefficients,
                                   a, b, effective_mass, effective_radius)[3]
    return released


@njit(inline="always", cache=True)
def clear_history(composition, history, row):
    width = history_layout(composition)[3]
    for column in range(width):
        history[row, column] = 0.0


@njit(inline="always", cache=True)
def dashpot_onset(overlap, approach_rate, elastic_force, normal_stiffness, dt):
    """The factor on the dashpots at a contact's first evaluation: the mean dashpot force of the continuous
    contact over the time the step's force stands for, over the dashpot now.

    A dashpot's force jumps at first touch, so a step that applies it for a whole step misses the continuous
    contact's impulse by up to half a step of it, by where in the step the contact began: the restitution of
    single impacts at dt auto scattered by -3.0..+1.4 % (linear law, e = 0.5, 33 steps per contact; -1.1..+0.4 %
    Hertz), first order in dt.  The bodies close at a constant rate over the step (the drift), so the contact
    began tau = overlap / approach before this evaluation (tau <= dt: the last one saw none); velocity Verlet's
    force here stands for [t - dt/2, t + dt/2] and the one before, which saw no contact, for the window before,
    so the continuous dashpot's impulse over both, with c ~ overlap^p (p = 0 linear, 1/4 Hertz: c ~ sqrt(S_n)),
    is c(overlap) approach (tau + dt/2)^(p+1) / ((p + 1) tau^p).  p comes from the elastic law itself:
    S_n overlap / F = 1 + 2p for F ~ overlap^(1 + 2p).  Later evaluations (tau > dt), receding contacts
    and contacts whose elastic force is not yet repulsive (a JKR contact's first touch) get 1.  The clamped force law ends with a force that falls to zero continuously: no
    factor is needed there."""
    if approach_rate <= 0.0 or overlap <= 0.0 or elastic_force <= 0.0 or overlap >= approach_rate * dt:
        return 1.0
    exponent = 0.5 * (normal_stiffness * overlap / elastic_force - 1.0)
    if exponent < 0.0:
        exponent = 0.0
    elif exponent > 0.25:
        exponent = 0.25
    began = overlap / approach_rate
    window = began + 0.5 * dt
    if exponent == 0.0:
        return window / dt
    return window * (window / began) ** exponent / ((1.0 + exponent) * dt)


@njit(inline="always", cache=True)
def contact_response(composition, coefficients, a, b, nx, ny, nz, overlap, vx, vy, vz, previous_vx, previous_vy,
                     previous_vz, wx, wy, wz, effective_mass, effective_radius, effective_inertia, rolling_inertia, history, row,
                     dt, may_be_first):
    """Force and rolling moment on i for one contact; updates history[row].

    may_be_first: whether this evaluation may be the contact's first (dashpot_onset); False where the caller
    has set first evaluations apart (the pair loop: with the onset's code inlined for every contact, the
    settled bed's loop took 13-16 % longer, though 12 of its 65,400 contacts were first evaluations).

    previous_v is the contact point's relative velocity of this step as the previous evaluation's geometry
    (normal, levers) sees it: what the tangential force applied then worked on (used with friction only).

    Returns (fx, fy, fz, mx, my, mz, elastic energy, dissipated energy this step, c_n, c_t): the
    dashpots' force on i is -(c_n n n^T + c_t (I - n n^T)) v; c_n is 0 when the dashpot was
    clamped, and a sliding contact's c_t is the dashpot's share of the Coulomb-capped force (the cap's
    factor times c_t: pdemfem.contact.tangential_mindlin).  A deformable surface applies the dashpot to its
    own nodes at its own rate (pdemfem.coupling.dampers).
    """
    tangential_column, rolling_column, touching_column, width = history_layout(composition)
    model = int(coefficients[a, b, NORMAL_MODEL])
    elastic_force, normal_stiffness, tangential_stiffness, elastic_energy = normal_elastic(
        model, composition, overlap, coefficients, a, b, effective_mass, effective_radius)
    if touching_column >= 0:
        history[row, touching_column] = 1.0

    # Normal: spring + dashpot; the dashpot never pulls (the force is never below min(elastic, 0)).
    normal_speed = vx * nx + vy * ny + vz * nz
    approach_rate = -normal_speed
    gamma = coefficients[a, b, DAMPING]
    onset = 1.0
    if may_be_first:
        onset = dashpot_onset(overlap, approach_rate, elastic_force, normal_stiffness, dt)
    normal_damping = onset * dashpot(gamma, effective_mass, normal_stiffness)
    normal_force = elastic_force + normal_damping * approach_rate
    floor = min(elastic_force, 0.0)
    if normal_force < floor:
        normal_force = floor
        normal_damping = 0.0
    # Velocity Verlet gives the force of this evaluation the mean of the half-step velocities before and
    # after it; this contact alone changes the approach rate by dt F_n / m* over the step, so the dashpot's
    # work is booked at approach - dt F_n / (2 m*) (exact for an isolated contact; with the half-step rate
    # alone, strong damping (e = 1e-4) booked 5-36 % more than the energy lost).
    dissipated = (normal_force - elastic_force) * (approach_rate - 0.5 * dt * normal_force / effective_mass) * dt
    fx = normal_force * nx
    fy = normal_force * ny
    fz = normal_force * nz
    tangential_damping = 0.0

    # The springs below book their work on the relative motion; their energy change is booked here against
    # the energy they were booked with last time (kept in the history: nothing is recomputed).
    energy_column = spring_energy_column(composition)
    spring_energy_after = 0.0

    if tangential_column >= 0:
        friction = coefficients[a, b, FRICTION]
        if friction > 0.0:
            load = normal_force
            if composition & COHESIVE:
                load += normal_friction_offset(model, composition, coefficients, a, b, effective_radius)
            tangential_damping = onset * dashpot(gamma, effective_mass, tangential_stiffness)
            tx, ty, tz, tangential_damping, spring_energy, tangential_dissipated = tangential_mindlin.force(
                nx, ny, nz, vx, vy, vz, normal_speed, previous_vx, previous_vy, previous_vz, tangential_stiffness,
                tangential_damping, friction * max(load, 0.0), history, row, tangential_column, dt)
            fx += tx
            fy += ty
            fz += tz
            spring_energy_after += spring_energy
            dissipated += tangential_dissipated

    mx = 0.0
    my = 0.0
    mz = 0.0
    if composition & ROLLING_ANY:
        mx, my, mz, rolling_energy, rolling_dissipated = rolling_torque(
            int(coefficients[a, b, ROLLING_MODEL]), composition, coefficients, a, b, nx, ny, nz, wx, wy, wz,
            normal_force, normal_stiffness, effective_radius, effective_inertia, rolling_inertia, history,
            row, rolling_column, dt)
        spring_energy_after += rolling_energy
        dissipated += rolling_dissipated
    if energy_column >= 0:
        # The sub-models booked their work minus their energy now; the energy they held before is released.
        dissipated += history[row, energy_column]
        history[row, energy_column] = spring_energy_after
        elastic_energy += spring_energy_after
    return fx, fy, fz, mx, my, mz, elastic_energy, dissipated, normal_damping, tangential_damping


@njit(inline="always", cache=True)
def rigid_wall_contact(composition, coefficients, material, wall_row, nx, ny, nz, distance, surface_vx, surface_vy,
                       surface_vz, vx, vy, vz, wx, wy, wz, radius, contact_radius, mass, inverse_inertia, history, slot,
                       dt):
    """Contact of a particle (velocity v, spin w, radius, mass, inverse inertia; scalars) with a rigid wall
    (R = inf, m = inf): plane, cylinder or triangle.

    n is the wall's normal at the contact point, which lies `distance` below the centre along -n and moves
    with the surface velocity.  contact_radius: the contact's R* (the particle's radius on flat and concave
    walls; r R / (r + R) outside a cylinder of radius R).  Returns (fx, fy, fz, tx, ty, tz, mx, my, mz, elastic, dissipated, c_n, c_t):
    the force on the particle (the wall gets the opposite), its torque about the particle's centre (the
    force's moment and the rolling couple), the rolling couple alone, the contact's energies and its dashpot
    coefficients.  The caller adds force and torque to the particle's rows (add_particle_loads): with the
    particle's ten arrays passed in instead, the plane-wall kernel took twice as long.
    """
    lever = distance
    relative_x = vx - surface_vx - lever * (wy * nz - wz * ny)
    relative_y = vy - surface_vy - lever * (wz * nx - wx * nz)
    relative_z = vz - surface_vz - lever * (wx * ny - wy * nx)
    effective_inertia = 0.0  # only rolling models use them
    rolling_inertia = 0.0
    if composition & ROLLING_ANY:
        effective_inertia = 1.0 / inverse_inertia
        rolling_inertia = effective_inertia + mass * radius * radius  # about the contact point
    # The same velocity with the previous evaluation's lever, the distance a step earlier (exact for a plane
    # or a facet; on a curved surface the normal's turn over the step is left out).
    receded = dt * (relative_x * nx + relative_y * ny + relative_z * nz)
    previous_x = relative_x + receded * (wy * nz - wz * ny)
    previous_y = relative_y + receded * (wz * nx - wx * nz)
    previous_z = relative_z + receded * (wx * ny - wy * nx)
    fx, fy, fz, mx, my, mz, elastic, dissipated, normal_damping, tangential_damping = contact_response(
        composition, coefficients, material, wall_row, nx, ny, nz, radius - distance, relative_x, relative_y,
        relative_z, previous_x, previous_y, previous_z, wx, wy, wz, mass, contact_radius, effective_inertia, rolling_inertia,
        history, slot, dt, True)
    tx = -lever * (ny * fz - nz * fy) + mx
    ty = -lever * (nz * fx - nx * fz) + my
    tz = -lever * (nx * fy - ny * fx) + mz
    return fx, fy, fz, tx, ty, tz, mx, my, mz, elastic, dissipated, normal_damping, tangential_damping


@njit(inline="always", cache=True)
def add_particle_loads(forces, torques, i, fx, fy, fz, tx, ty, tz):
    """Add a contact's force and torque to particle i's rows (what rigid_wall_contact returns).  Taking
    the two load arrays costs nothing measurable; the ten particle arrays the wall helper once took did."""
    forces[i, 0] += fx
    forces[i, 1] += fy
    forces[i, 2] += fz
    torques[i, 0] += tx
    torques[i, 1] += ty
    torques[i, 2] += tz


@njit(cache=True)
def cohesive_contact_holds(composition, coefficients, a, b, overlap, effective_radius, history, row):
    """Whether a contact that does not touch (overlap <= 0) still acts: formed and above its pull-off overlap.

    Called only off the hot path (composition has COHESIVE and the bodies do not touch): an inlined
    helper taking arrays costs reference counting on every candidate of every step."""
    touching_column = history_layout(composition)[2]
    if touching_column < 0 or history[row, touching_column] == 0.0:
        return False
    return overlap > pull_off_overlap(composition, coefficients, a, b, effective_radius)
