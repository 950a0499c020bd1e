"""What every contributor wall shares: the totals on the wall, its per-particle history fields,
its checkpointed state, and the rotation helper of moving walls.

A contributor wall (mesh, cylinder, a solid's contact surface) plugs into the particle
system (see pdemfem.particles.system) and owns its state: `state_dict()` returns the
totals and the work (and a subclass adds its kinematics), `load_state_dict()` takes
them back, `canonicalize()` rebuilds what is derived from them.  The checkpoint code
only sees the dicts, so a new wall kind needs no change there.
"""
from __future__ import annotations

import math

import numpy as np

from pdemfem import state_dict as kinds
from pdemfem.particles.heat import NO_HEAT_FLOWS, NO_TEMPERATURES


def rotation_matrix(rotation_vector) -> np.ndarray:
    """Rodrigues: the rotation by |phi| about phi / |phi|."""
    phi = np.asarray(rotation_vector, dtype=float)
    angle = float(np.linalg.norm(phi))
    if angle == 0.0:
        return np.eye(3)
    k = phi / angle
    cross = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * cross + (1.0 - math.cos(angle)) * cross @ cross


class ContributorWall(kinds.StateComponent):
    """Totals every contributor wall keeps: force and moment on the wall, work done on the particles."""

    def __init__(self, name: str):
        self.name = name
        # force (3) and moment about the origin (3) on the wall, this step, summed over ranks after reduce.
        self.totals = np.zeros(6)
        self.work = 0.0
        self._step_work = 0.0
        # The step work (power x dt) of the last force evaluation, summed over the ranks: the next step books
        # the trapezoid of it and its own (_book_step_work); None before the first evaluation.
        self._previous_step_work = None
        # With heat on: the wall's fixed temperature [K] (NaN: adiabatic), and the heat [J] it gave this
        # rank's particles in the last add_forces (the particle system books it).
        self.temperature = math.nan
        self.step_heat = 0.0

    @property
    def force(self) -> np.ndarray:
        """Total contact force the particles exert on the wall (N)."""
        return self.totals[:3].copy()

    def torque(self, about=(0.0, 0.0, 0.0)) -> np.ndarray:
        """Moment of the particles' contact forces on the wall about the point `about` (N m)."""
        about = np.asarray(about, dtype=float)
        return self.totals[3:] - np.cross(about, self.totals[:3])

    def local_totals(self) -> np.ndarray:
        """This rank's part of what the step sums over the ranks: force, moment and this step's work."""
        return np.append(self.totals, self._step_work)

    def take_summed_totals(self, summed: np.ndarray) -> None:
        """The local_totals() summed over the ranks (the particle system's one SUM per step)."""
        self.totals[:] = summed[:6]
        self._book_step_work(float(summed[6]))

    def _book_step_work(self, step_work: float) -> None:
        """Book the wall's work on the particles over the step just taken: the trapezoid of the step works
        (power x dt) at the force evaluations before and after the wall's move, the rule velocity Verlet's
        kinetic energy follows (the evaluation alone books the work a step early: a first-order error
        wherever the force jumps).  On one rank add_forces calls it with the rank's (= the total) work;
        on several, take_summed_totals with the total."""
        if self._previous_step_work is not None:
            self.work += 0.5 * (self._previous_step_work + step_work)
        self._previous_step_work = step_work

    def set_temperature(self, temperature: float) -> None:
        """Hold the wall at `temperature` [K] (with heat on, touching particles exchange heat with it)."""
        self.temperature = float(temperature)

    @staticmethod
    def _heat_arrays(state):
        """(temperatures, heat_flows) for a kernel: the state's with heat on, empty arrays otherwise."""
        if state.temperatures is None:
            return NO_TEMPERATURES, NO_HEAT_FLOWS
        return state.temperatures, state.heat_flows

    @staticmethod
    def _field(state, name: str, tail_shape, dtype, fill):
        """The wall's per-particle contact history: migrates with the particles and is checkpointed
        (ParticleState's field registry), never sent to ghosts (only owned particles touch walls)."""
        if name not in state.fields:
            state.add_field(name, tail_shape, dtype, fill)
        return state.fields[name]

    # ------------------------------------------------------------ checkpoints
    def state_dict(self) -> dict:
        state = {"work": kinds.scalar(float(self.work)), "totals": kinds.global_array(self.totals)}
        if self._previous_step_work is not None:
            state["previous_step_work"] = kinds.scalar(float(self._previous_step_work))
        return state

    def load_state_dict(self, state: dict) -> None:
        self.work = float(state["work"])
        if "previous_step_work" in state:
            self._previous_step_work = float(state["previous_step_work"])
        self.totals = np.array(state["totals"], dtype=float)
