"""Particle temperatures: the explicit update and the heat content (heat on only).

Every contact kernel adds, for each contact, the heat flow Q = H (T_partner - T_i) [W] and its
conductance H [W/K] to the particle's row of `heat_flows` (pdemfem.contact.conduction).  After the
step's forces, each owned particle's temperature takes a forward-Euler step

    T_i += dt Q_i / (m_i c_i).

With every conductance fixed over the step this is stable, and obeys the maximum principle (no
temperature overshoots its neighbours'), while dt sum_j H_ij / (m_i c_i) <= 1 (every coefficient
of the update is then non-negative); `update_temperatures` returns the largest such ratio so the
run-time guard can refuse a run past it (docs/heat.md).  A pair's two flows are equal and opposite
to the last bit (both ranks of a pair across a cut compute the same H and temperature difference),
so conduction between particles conserves heat to round-off.
"""
from __future__ import annotations

import numpy as np
from numba import njit

# What the kernels get for temperatures and heat flows when heat is off (never read).
NO_TEMPERATURES = np.zeros(0)
NO_HEAT_FLOWS = np.zeros((0, 2))


@njit(cache=True)
def update_temperatures(owned_count, temperatures, heat_flows, mass, material_index, heat_capacity, dt):
    """T += dt Q / (m c) on the owned rows; returns the largest dt sum(H) / (m c) (stable and monotone <= 1)."""
    largest = 0.0
    for i in range(owned_count):
        capacity = mass[i] * heat_capacity[material_index[i]]
        temperatures[i] += dt * heat_flows[i, 0] / capacity
        ratio = dt * heat_flows[i, 1] / capacity
        if ratio > largest:
            largest = ratio
    return largest


@njit(cache=True)
def heat_content(owned_count, temperatures, mass, material_index, heat_capacity):
    """Sum of m c T over the owned rows [J] (relative to 0 K, constant specific heat)."""
    total = 0.0
    for i in range(owned_count):
        total += mass[i] * heat_capacity[material_index[i]] * temperatures[i]
    return total


def material_heat_capacities(scene, material_names) -> np.ndarray:
    """c [J/(kg K)] per contact-table row (0 where a material gives none: it never belongs to a particle)."""
    capacities = np.zeros(len(material_names))
    for row, name in enumerate(material_names):
        material = scene.materials.get(name)
        if material is not None and material.heat_capacity is not None:
            capacities[row] = material.heat_capacity
    return capacities


class HeatLedger:
    """Heat [J] booked per rank and summed over the ranks only when read, one entry per name: what
    bodies (walls, solids' surfaces) gave the particles, or what particles carried in and out
    (CarriedHeat).

    Kernels add flow x dt to `pending` (this rank's contacts, no communication per step);
    `settle` (collective) moves the ranks' pending sums into `total`, the same on every rank.
    Writing a history row and a checkpoint settle first, so a restart continues from the
    same totals (the checkpoint holds `total`)."""

    def __init__(self, names):
        self.names = list(names)
        self.pending = np.zeros(len(self.names))
        self.total = np.zeros(len(self.names))

    def settle(self, comm) -> np.ndarray:
        """Collective: the totals [J] per body, pending sums included."""
        pending = self.pending.copy()
        if comm.size > 1 and len(pending):
            from mpi4py import MPI

            comm.Allreduce(MPI.IN_PLACE, pending, op=MPI.SUM)
        self.total += pending
        self.pending[:] = 0.0
        return self.total.copy()


class CarriedHeat(HeatLedger):
    """Heat content m c T [J] (as thermal_energy counts it) that particles inserted since the start brought
    in ("in": streams) and particles removed since the start took out ("out": outlets, the domain box,
    non-finite positions).  Booked on the rank that inserts or removes them, at list rebuilds; with the
    bodies' heat_<name> these close the particles' heat balance:
    content(t) - content(0) = sum heat_<name> + in - out."""

    IN, OUT = 0, 1

    def __init__(self):
        super().__init__(("in", "out"))

    def book_in(self, heat: float) -> None:
        self.pending[self.IN] += heat

    def book_out(self, heat: float) -> None:
        self.pending[self.OUT] += heat
