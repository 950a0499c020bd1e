"""A solid's prescribed rigid motion: the moving (floating) frame its small elastic deformation lives in.

A solid with a `motion:` key is carried by a rigid motion of constant angular velocity omega about an
axis through `axis_point` (its position at t = 0) and constant translation velocity V.  A material
point with body-frame position p = X + u (X the mesh node, u the elastic displacement the FE solves
for) is at

    x(t) = c(t) + R(t) (p - c0),    c(t) = c0 + V t,    R(t) = rotation by |omega| t about omega,

and moves with v = V + omega x (x - c(t)) + R du/dt.  In the frame the FE equations keep their
small-strain form M u'' + C u' + K u = f plus the frame's inertial (fictitious) forces, exact for a
constant omega and V (no Euler or translational-acceleration term):

* centrifugal   -m omega x (omega x (p - c0))   (m the node's lumped mass; the u part is the spin
  softening, kept: it is the same expression with p = X + u),
* Coriolis      -2 m omega x u'                 (integrated by the implicit midpoint rule per node, a
  Cayley rotation of the velocity: it does no work, as in the equations),
* gravity       R(t)^T m g                      (turns in the frame as the body turns).

Loads constant in the frame (tractions, point forces) are follower loads: they turn with the body.
Contact forces enter rotated by R^T of the time the particles saw the surface at.

Energy.  The elastic motion's kinetic and strain energies are those of the frame (relative to it);
what the frame feeds in is booked as `frame_work`: the work of the centrifugal and gravity loads on
the elastic displacements, and minus the particles' contact forces times the frame's part of the
surface displacement over each FE advance.  The prescribed motion itself (the drive) is not a degree
of freedom: its torque and force are whatever keep the motion, and its work is that frame work.

Free sinkage (carried_mass M).  The axis may instead move freely along z: its height h and rate h' obey
M h'' = F_z + M g_z (F_z the particles' force on the solid, summed over the window of each FE advance),
integrated as the solid advances (kick h' with the window's mean force, then drift h); the frame's
acceleration a = h'' z adds -m a to the elastic body's loads, like gravity.  The axis's energy
1/2 M h'^2 - M g_z h (`axle_energy`) is held energy; the particles' work on it is part of `frame_work`.
The elastic body's own momentum relative to the frame is left out of the axis's equation (small strain).

Limits.  Small strain relative to the frame; the rigid rotation is exact for any angle.  A spin near
the solid's lowest elastic frequency is resonance-like (spin softening makes K - m omega^2
indefinite): the solid's critical step bound is unchanged, the divergence monitor stops such a run.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from pdemfem.fem.kernels import cell_jacobian_inverse


def rotation_matrix(axis_unit, angle: float) -> np.ndarray:
    """Rodrigues: the rotation by `angle` [rad] about the unit vector `axis_unit` (right-handed)."""
    x, y, z = axis_unit
    cosine, sine = math.cos(angle), math.sin(angle)
    one_minus = 1.0 - cosine
    return np.array([
        [cosine + x * x * one_minus, x * y * one_minus - z * sine, x * z * one_minus + y * sine],
        [y * x * one_minus + z * sine, cosine + y * y * one_minus, y * z * one_minus - x * sine],
        [z * x * one_minus - y * sine, z * y * one_minus + x * sine, cosine + z * z * one_minus],
    ])


class MovingFrame:
    """The rigid motion x = c0 + V t + R(t) (p - c0) of a solid's `motion:` entry (see the module docstring)."""

    def __init__(self, axis_point, angular_velocity, velocity, carried_mass=None, start=0.0):
        self.axis_point = np.asarray(axis_point, dtype=float).copy()
        self.angular_velocity = np.asarray(angular_velocity, dtype=float).copy()
        self.velocity = np.asarray(velocity, dtype=float).copy()
        # Free sinkage: the axis's height above its prescribed path (h), its rate (h', replacing velocity[2])
        # and the acceleration of the last kick (the elastic body feels -m a); None: prescribed.
        self.carried_mass = None if carried_mass is None else float(carried_mass)
        self.height = 0.0
        self.height_rate = float(self.velocity[2]) if self.carried_mass is not None else 0.0
        self.acceleration = np.zeros(3)
        if self.carried_mass is not None:
            self.velocity[2] = 0.0
        self.start = float(start)  # before it the frame rests (motion.start)
        self._resting = np.zeros(3)
        self.spin = float(np.linalg.norm(self.angular_velocity))
        self.axis = self.angular_velocity / self.spin if self.spin > 0.0 else np.array([0.0, 0.0, 1.0])

    def moving(self, time: float) -> bool:
        """Has the motion begun (motion.start)?"""
        return time >= self.start

    def elapsed(self, time: float) -> float:
        return max(0.0, time - self.start)

    def rotation(self, time: float) -> np.ndarray:
        return rotation_matrix(self.axis, self.spin * self.elapsed(time))

    def centre(self, time: float) -> np.ndarray:
        """Where the axis point is at `time` (free sinkage: at the height the last advance reached)."""
        return self.axis_point + self.velocity * self.elapsed(time) + np.array([0.0, 0.0, self.height])

    def spin_vector(self, time: float) -> np.ndarray:
        """The angular velocity at `time` (zero before the start)."""
        return self.angular_velocity if self.moving(time) else self._resting

    def translation_velocity(self, time: float) -> np.ndarray:
        if not self.moving(time):
            return self._resting
        return self.velocity + np.array([0.0, 0.0, self.height_rate])

    def chord_velocities(self, body_positions, time: float, interval: float) -> np.ndarray:
        """(x(time + interval) - x(time)) / interval of frame-fixed points p (n, 3): the frame's motion over an
        advance that starts now (a free axis moves with its current rate h' over it)."""
        body = np.asarray(body_positions, float) - self.axis_point
        turned = body @ (self.rotation(time + interval) - self.rotation(time)).T
        # The prescribed part from the centre's path (through a start, too), the free axis's from its rate.
        shift = self.velocity * (self.elapsed(time + interval) - self.elapsed(time))
        if self.moving(time):
            shift = shift + np.array([0.0, 0.0, self.height_rate * interval])
        return (shift + turned) / interval

    def kick(self, vertical_force: float, gravity_z: float, interval: float) -> None:
        """Free sinkage, before an advance of `interval`: h' += interval (F_z / M + g_z)."""
        rate = self.height_rate + interval * (vertical_force / self.carried_mass + gravity_z)
        self.acceleration[2] = (rate - self.height_rate) / interval
        self.height_rate = rate

    def drift(self, interval: float) -> None:
        """Free sinkage, after the advance: h += interval h'."""
        self.height += interval * self.height_rate

    def axle_energy(self, gravity_z: float) -> float:
        """Free sinkage: 1/2 M h'^2 - M g_z h [J] (0 when the axis is prescribed)."""
        if self.carried_mass is None:
            return 0.0
        return 0.5 * self.carried_mass * self.height_rate ** 2 - self.carried_mass * gravity_z * self.height

    def state(self) -> dict:
        return {"height": self.height, "height_rate": self.height_rate, "acceleration": self.acceleration[2]}

    def load_state(self, state: dict) -> None:
        self.height, self.height_rate = float(state["height"]), float(state["height_rate"])
        self.acceleration[2] = float(state["acceleration"])

    def to_world(self, body_positions, time: float) -> np.ndarray:
        """World positions (n, 3) of body-frame positions p = X + u."""
        rotation = self.rotation(time)
        return self.centre(time) + (np.asarray(body_positions, float) - self.axis_point) @ rotation.T

    def world_velocities(self, body_positions, body_velocities, time: float) -> np.ndarray:
        """World velocities V + omega x R (p - c0) + R u' (n, 3)."""
        rotation = self.rotation(time)
        arms = (np.asarray(body_positions, float) - self.axis_point) @ rotation.T
        return (self.translation_velocity(time) + np.cross(self.spin_vector(time), arms)
                + np.asarray(body_velocities, float) @ rotation.T)

    def frame_velocities(self, world_positions, time: float) -> np.ndarray:
        """Velocity (n, 3) of the frame's material at world positions: V + omega x (x - c(t))."""
        return self.translation_velocity(time) + np.cross(self.spin_vector(time),
                                                          np.asarray(world_positions, float) - self.centre(time))

    def vectors_to_body(self, vectors, time: float) -> np.ndarray:
        """R(t)^T v for rows v (n, 3): world components to body-frame components."""
        return np.asarray(vectors, float) @ self.rotation(time)

    def vectors_to_world(self, vectors, time: float) -> np.ndarray:
        return np.asarray(vectors, float) @ self.rotation(time).T

    def symmetric_to_body(self, voigt, time: float) -> np.ndarray:
        """R^T D R of symmetric tensors given as rows (xx, yy, zz, yz, xz, xy)."""
        return _rotate_voigt(np.asarray(voigt, float), self.rotation(time).T)

    def symmetric_to_world(self, voigt, time: float) -> np.ndarray:
        """R S R^T of symmetric tensors (rows xx, yy, zz, yz, xz, xy), e.g. body-frame stresses."""
        return _rotate_voigt(np.asarray(voigt, float), self.rotation(time))


def _rotate_voigt(voigt: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """Q S Q^T for each row S in Voigt order (xx, yy, zz, yz, xz, xy)."""
    if not len(voigt):
        return voigt.copy()
    full = np.empty((len(voigt), 3, 3))
    full[:, 0, 0], full[:, 1, 1], full[:, 2, 2] = voigt[:, 0], voigt[:, 1], voigt[:, 2]
    full[:, 1, 2] = full[:, 2, 1] = voigt[:, 3]
    full[:, 0, 2] = full[:, 2, 0] = voigt[:, 4]
    full[:, 0, 1] = full[:, 1, 0] = voigt[:, 5]
    turned = np.einsum("ij,njk,lk->nil", rotation, full, rotation)
    return np.column_stack([turned[:, 0, 0], turned[:, 1, 1], turned[:, 2, 2],
                            turned[:, 1, 2], turned[:, 0, 2], turned[:, 0, 1]])


@njit(cache=True)
def centrifugal_reference_load(coords, cells, n_owned, mass_values, mass_weights, density, omega, axis_point, out):
    """out[a] += int N_a rho (|omega|^2 r - omega (omega . r)) dV, r = X - c0: the centrifugal load of the
    undeformed body with the consistent weights (exact: r is linear over a straight-sided cell and the mass
    quadrature integrates N_a N_b exactly), owned rows only (flat dofs)."""
    nen = cells.shape[1]
    jinv = np.empty((3, 3))
    spin2 = omega[0] * omega[0] + omega[1] * omega[1] + omega[2] * omega[2]
    r = np.empty(3)
    for c in range(cells.shape[0]):
        det = cell_jacobian_inverse(coords, cells, c, jinv)
        for q in range(mass_weights.shape[0]):
            for d in range(3):
                r[d] = -axis_point[d]
                for b in range(nen):
                    r[d] += mass_values[q, b] * coords[cells[c, b], d]
            along = omega[0] * r[0] + omega[1] * r[1] + omega[2] * r[2]
            for a in range(nen):
                row = cells[c, a]
                if row >= n_owned:
                    continue
                weight = mass_weights[q] * mass_values[q, a] * det * density
                for d in range(3):
                    out[3 * row + d] += weight * (spin2 * r[d] - omega[d] * along)


@njit(cache=True)
def frame_load(u, lumped_mass, centrifugal_reference, gravity_loads, body_gravity, omega, load):
    """load (flat dofs) = gravity turned into the frame + centrifugal force.

    gravity_loads (3, dofs): the nodal loads of a unit body force density rho e_d; body_gravity the
    gravity vector's components in the frame.  Centrifugal: the undeformed body's (consistent,
    centrifugal_reference_load) plus the spin softening of the displacement with the lumped mass,
    -m omega x (omega x u), the same mass the inertia uses."""
    nodes = u.shape[0] // 3
    spin2 = omega[0] * omega[0] + omega[1] * omega[1] + omega[2] * omega[2]
    for node in range(nodes):
        ux = u[3 * node]
        uy = u[3 * node + 1]
        uz = u[3 * node + 2]
        along = omega[0] * ux + omega[1] * uy + omega[2] * uz
        for axis in range(3):
            dof = 3 * node + axis
            g = (gravity_loads[0, dof] * body_gravity[0] + gravity_loads[1, dof] * body_gravity[1]
                 + gravity_loads[2, dof] * body_gravity[2])
            softening = spin2 * u[dof] - omega[axis] * along
            load[dof] = g + centrifugal_reference[dof] + lumped_mass[dof] * softening


@njit(cache=True)
def coriolis_correction(u, v, v_before, constrained, omega, dt):
    """Add the Coriolis force -2 m omega x u' to a central-difference step already taken without it.

    v holds the step's velocity v* (all other forces), v_before the velocity before the step.  Free
    nodes take the implicit midpoint rule v = v* - dt omega x (v + v_before), i.e.
    (I + S) v = v* - S v_before with S = [dt omega x], solved in closed form
    (I + S)^-1 b = (b + (s.b) s - s x b) / (1 + |s|^2), s = dt omega: a Cayley rotation, so the term does
    no work.  A node with a constrained dof keeps its prescribed components and takes the force explicitly
    (with v_before) on its free ones.  u moves by dt (v - v*) more.  Returns nothing."""
    sx = dt * omega[0]
    sy = dt * omega[1]
    sz = dt * omega[2]
    s2 = sx * sx + sy * sy + sz * sz
    nodes = u.shape[0] // 3
    for node in range(nodes):
        i = 3 * node
        ax, ay, az = v_before[i], v_before[i + 1], v_before[i + 2]
        if constrained[i] or constrained[i + 1] or constrained[i + 2]:
            # explicit: -2 dt omega x v_before on the free components
            fx = -2.0 * (sy * az - sz * ay)
            fy = -2.0 * (sz * ax - sx * az)
            fz = -2.0 * (sx * ay - sy * ax)
            if not constrained[i]:
                v[i] += fx
                u[i] += dt * fx
            if not constrained[i + 1]:
                v[i + 1] += fy
                u[i + 1] += dt * fy
            if not constrained[i + 2]:
                v[i + 2] += fz
                u[i + 2] += dt * fz
            continue
        # b = v* - s x v_before
        bx = v[i] - (sy * az - sz * ay)
        by = v[i + 1] - (sz * ax - sx * az)
        bz = v[i + 2] - (sx * ay - sy * ax)
        sb = sx * bx + sy * by + sz * bz
        nx = (bx + sb * sx - (sy * bz - sz * by)) / (1.0 + s2)
        ny = (by + sb * sy - (sz * bx - sx * bz)) / (1.0 + s2)
        nz = (bz + sb * sz - (sx * by - sy * bx)) / (1.0 + s2)
        u[i] += dt * (nx - v[i])
        u[i + 1] += dt * (ny - v[i + 1])
        u[i + 2] += dt * (nz - v[i + 2])
        v[i] = nx
        v[i + 1] = ny
        v[i + 2] = nz


@njit(cache=True)
def load_work(load, v_before, v, constrained, dt):
    """Work of a load held over one step on the free dofs: load . dt (v_before + v) / 2 (the kernels' rule)."""
    work = 0.0
    for i in range(load.shape[0]):
        if not constrained[i]:
            work += load[i] * 0.5 * dt * (v_before[i] + v[i])
    return work
