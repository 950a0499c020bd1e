"""Recursive coordinate bisection (RCB) of space into one box per rank.

The cut tree is built from the particles' positions weighted by their cost
(1 + contacts): at each level every group of ranks splits its region along the
region's longest axis at the coordinate that divides the group's weight in
proportion to the ranks on each side.  The weighted median is found from
weight histograms along the axis, refined in CUT_ROUNDS rounds (the bin that
holds the median is binned again), with one Allreduce of the histograms per
round, so no particle data is gathered anywhere.  Outer faces extend to
infinity (or to the periodic domain), so every point in space has exactly one
owner.
"""
from __future__ import annotations

import math

import numpy as np
from mpi4py import MPI
from numba import njit

from pdemfem import state_dict as kinds
from pdemfem.neighbors.cells import bounding_box

# The cut search: CUT_ROUNDS histograms of CUT_BINS bins, each over the bin of the round before that holds
# the weighted median, then linear within the last bin: the cut lies within CUT_BINS^-CUT_ROUNDS = 1/65,536 of
# the region's extent of the weighted median (a particle's width in a region of 65,536 particles across).
# Bisection on the coordinate (one Allreduce per halving, 40 of them) made a rebalance cost ~2 ms per rank on
# 2 ranks, waiting included, and rebalances rare; two rounds cost two Allreduces (docs/parallel.md).
CUT_BINS = 256
CUT_ROUNDS = 2
# A region is cut along its longest axis unless another axis's cut scores this much better (_axis_scores: the
# larger side's particles and ghosts over its share): a small gain is not worth flipping the cut at a rebalance
# (every particle between the two cuts migrates).
AXIS_MARGIN = 0.05


class Decomposition:
    """Boxes (ranks, 2, 3) and the cut tree that maps a point to its owner rank.

    Tree arrays: for node k, `node_axis[k]`, `node_cut[k]`, `node_left[k]`,
    `node_right[k]`; a child index < 0 is the leaf of rank -(child + 1).
    """

    def __init__(self, boxes, node_axis, node_cut, node_left, node_right):
        self.boxes = boxes
        self.node_axis = node_axis
        self.node_cut = node_cut
        self.node_left = node_left
        self.node_right = node_right

    @classmethod
    def single(cls, lower, upper):
        boxes = np.array([[lower, upper]], dtype=float)
        leaf = np.array([-1], dtype=np.int64)
        return cls(boxes, np.zeros(1, dtype=np.int64), np.array([np.inf]), leaf, leaf.copy())

    def owners(self, positions: np.ndarray) -> np.ndarray:
        return _owners(positions, self.node_axis, self.node_cut, self.node_left, self.node_right)

    @property
    def rank_count(self) -> int:
        return len(self.boxes)

    # The boxes and the cut tree: the same on every rank (GLOBAL arrays of a checkpoint).
    _STATE = ("boxes", "node_axis", "node_cut", "node_left", "node_right")

    def state_dict(self) -> dict:
        return {name: kinds.global_array(getattr(self, name)) for name in self._STATE}

    @classmethod
    def from_state_dict(cls, state: dict) -> "Decomposition":
        return cls(*(np.asarray(state[name]) for name in cls._STATE))


@njit(cache=True)
def _owners(positions, node_axis, node_cut, node_left, node_right):
    result = np.empty(positions.shape[0], dtype=np.int64)
    for i in range(positions.shape[0]):
        node = 0
        while True:
            if positions[i, node_axis[node]] < node_cut[node]:
                child = node_left[node]
            else:
                child = node_right[node]
            if child < 0:
                result[i] = -(child + 1)
                break
            node = child
    return result


def recursive_bisection(comm, positions, weights, lower, upper, ghost_cutoff: float = 0.0) -> Decomposition:
    """RCB of the region [lower, upper] over comm.size ranks (collective).

    `positions`/`weights` are this rank's particles; `lower`/`upper` bound the
    region whose outer faces the boxes inherit (may be infinite); `ghost_cutoff`
    is how far from a cut the other side's particles are ghosts (the axis choice
    counts them, _axis_scores).
    """
    size = comm.size
    if size == 1:
        return Decomposition.single(lower, upper)
    weights = np.ascontiguousarray(weights, dtype=float)
    # Finite extents for choosing axes and cut ranges: the particles' global bounding box (one MIN: -max).
    # (bounding_box: one pass, where numpy's strided axis-0 min and max took 0.4 ms at 14,000 particles)
    data_lower, data_upper = bounding_box(positions)
    extents = np.concatenate([data_lower, -data_upper])
    comm.Allreduce(MPI.IN_PLACE, extents, op=MPI.MIN)
    data_low, data_high = extents[:3], -extents[3:]
    data_low = np.where(np.isfinite(data_low), data_low, 0.0)
    data_high = np.where(np.isfinite(data_high), data_high, 1.0)

    boxes = np.empty((size, 2, 3))
    node_axis, node_cut, node_left, node_right = [], [], [], []
    # Work list of regions: (first rank, rank count, box lower, box upper, finite lower, finite upper, node slot)
    regions = [(0, size, np.array(lower, float), np.array(upper, float), data_low.copy(), data_high.copy(), None)]
    membership = np.zeros(len(positions), dtype=np.int64)  # index into `regions` of each particle
    while regions:
        splitting = [k for k, region in enumerate(regions) if region[1] > 1]
        for k, region in enumerate(regions):
            if region[1] == 1:
                boxes[region[0], 0] = region[2]
                boxes[region[0], 1] = region[3]
                _link(node_left, node_right, region[6], -(region[0] + 1))
        if not splitting:
            break
        count = len(splitting)
        finite_lows = np.array([regions[k][4] for k in splitting])
        finite_highs = np.array([regions[k][5] for k in splitting])
        fractions = np.array([(regions[k][1] // 2) / regions[k][1] for k in splitting])
        slot_of_region = -np.ones(len(regions), dtype=np.int64)
        slot_of_region[splitting] = np.arange(count)
        # Particles of regions already finished (single-rank leaves) have membership -1.
        particle_slot = np.where(membership >= 0, slot_of_region[np.maximum(membership, 0)], -1)
        axes, cuts, coordinate = _axes_and_cuts(comm, particle_slot, positions, weights, finite_lows, finite_highs,
                                                fractions, float(ghost_cutoff))
        new_regions = []
        new_index_of = {}
        for n, k in enumerate(splitting):
            first, ranks, box_low, box_high, finite_low, finite_high, parent_slot = regions[k]
            node = len(node_axis)
            node_axis.append(axes[n])
            node_cut.append(cuts[n])
            node_left.append(0)
            node_right.append(0)
            _link(node_left, node_right, parent_slot, node)
            left_ranks = ranks // 2
            left_high, right_low = box_high.copy(), box_low.copy()
            left_high[axes[n]] = cuts[n]
            right_low[axes[n]] = cuts[n]
            finite_left_high, finite_right_low = finite_high.copy(), finite_low.copy()
            finite_left_high[axes[n]] = cuts[n]
            finite_right_low[axes[n]] = cuts[n]
            new_index_of[(k, 0)] = len(new_regions)
            new_regions.append((first, left_ranks, box_low, left_high, finite_low, finite_left_high, (node, 0)))
            new_index_of[(k, 1)] = len(new_regions)
            new_regions.append((first + left_ranks, ranks - left_ranks, right_low, box_high, finite_right_low,
                                finite_high, (node, 1)))
        new_membership = np.full_like(membership, -1)
        for n, k in enumerate(splitting):
            mine = particle_slot == n
            goes_right = coordinate[mine] >= cuts[n]
            new_membership[mine] = np.where(goes_right, new_index_of[(k, 1)], new_index_of[(k, 0)])
        membership = new_membership
        regions = new_regions
    if not node_axis:  # cannot happen for size > 1, kept for clarity
        return Decomposition.single(lower, upper)
    return Decomposition(boxes, np.array(node_axis, dtype=np.int64), np.array(node_cut, dtype=float),
                         np.array(node_left, dtype=np.int64), np.array(node_right, dtype=np.int64))


def _axes_and_cuts(comm, particle_slot, positions, weights, finite_lows, finite_highs, fractions, ghost_cutoff):
    """Per region being split (slot): the axis to cut and the cut (collective: CUT_ROUNDS Allreduces).

    The first round bins the weight and the particle count along all three axes at once; each axis's cut
    there is scored by _axis_scores and the axis chosen (the longest unless another scores AXIS_MARGIN
    better); each later round bins the weight along the chosen axis over the bin of the round before that holds
    the median, and the cut goes linearly through the last round's median bin.  The same particles give the same
    cuts on any rank count up to the Allreduce's summation order.  Returns (axes, cuts, each particle's
    coordinate along its region's axis)."""
    count = len(fractions)
    bins = CUT_BINS if count <= 64 else CUT_BINS // 4  # many regions at once (many ranks): a smaller message
    window_low = np.ascontiguousarray(finite_lows, dtype=float)
    window_high = np.ascontiguousarray(finite_highs, dtype=float)
    histogram = _axis_histograms(particle_slot, positions, weights, window_low, window_high, bins, count)
    comm.Allreduce(MPI.IN_PLACE, histogram, op=MPI.SUM)
    cuts_by_axis = np.empty((3, count))
    low_by_axis = np.empty((3, count))
    high_by_axis = np.empty((3, count))
    scores = np.empty((3, count))
    for axis in range(3):
        low_by_axis[axis] = window_low[:, axis]
        high_by_axis[axis] = window_high[:, axis]
        # (narrows low/high_by_axis to the median bins, where the later rounds go on)
        _median_bins(np.ascontiguousarray(histogram[:, axis, 0]), fractions, low_by_axis[axis], high_by_axis[axis],
                     cuts_by_axis[axis])
        scores[axis] = _axis_scores(np.ascontiguousarray(histogram[:, axis, 1]), np.ascontiguousarray(window_low[:, axis]),
                                    np.ascontiguousarray(window_high[:, axis]), cuts_by_axis[axis], ghost_cutoff,
                                    fractions)
    longest = np.argmax(window_high - window_low, axis=1)
    best = np.argmin(scores, axis=0)
    slots = np.arange(count)
    axes = np.where(scores[best, slots] < scores[longest, slots] - AXIS_MARGIN, best, longest)
    cuts = cuts_by_axis[axes, slots]
    low = low_by_axis[axes, slots]
    high = high_by_axis[axes, slots]
    coordinate = positions[np.arange(len(positions)), axes[np.maximum(particle_slot, 0)]]
    for _ in range(CUT_ROUNDS - 1):
        histogram = _cut_histogram(particle_slot, coordinate, weights, low, high, CUT_BINS, count)
        comm.Allreduce(MPI.IN_PLACE, histogram, op=MPI.SUM)
        _median_bins(histogram, fractions, low, high, cuts)
    return axes, cuts, coordinate


@njit(cache=True)
def _axis_histograms(particle_slot, positions, weights, window_low, window_high, bins, count):
    """Per (slot, axis): the weight ([.., 0, ..]) and the particle count ([.., 1, ..]) in the columns of _bin_of,
    over the slot's window along each axis."""
    histogram = np.zeros((count, 3, 2, bins + 2))
    for i in range(particle_slot.shape[0]):
        slot = particle_slot[i]
        if slot < 0:
            continue
        for axis in range(3):
            column = _bin_of(positions[i, axis], window_low[slot, axis], window_high[slot, axis], bins)
            histogram[slot, axis, 0, column] += weights[i]
            histogram[slot, axis, 1, column] += 1.0
    return histogram


@njit(cache=True)
def _axis_scores(counts, window_low, window_high, cuts, ghost_cutoff, fractions):
    """Per slot: max over the two sides of (owned particles + ghosts) / the side's fair share of the particles,
    for a cut at `cuts` with the count histogram `counts` (as _cut_histogram bins).  1 is the best: both sides
    hold their share and no particle is near the cut.

    The cut balances the cost model's weight; the particle count is what the rest of the work goes with (the
    list build of a rebuild step, the integration, the ghosts), and where the two sides hold alike parts of the
    scene the model's errors cancel.  A settling bed cut across gravity gave the upper rank 1.4-1.5x the
    particles (it balanced the lower rank's contacts with them), so its rebuild steps took 1.5-2 ms more; cut
    upright, both halves were alike, at twice the ghosts (docs/parallel.md)."""
    count, columns = counts.shape
    bins = columns - 2
    scores = np.empty(count)
    for slot in range(count):
        lower = window_low[slot]
        width = (window_high[slot] - lower) / bins
        cut = cuts[slot]
        below = counts[slot, 0]
        above = counts[slot, bins + 1]
        band_below = 0.0
        band_above = 0.0
        for column in range(1, bins + 1):
            bin_low = lower + (column - 1) * width
            bin_high = bin_low + width
            value = counts[slot, column]
            if width > 0.0:
                below_part = min(max((cut - bin_low) / width, 0.0), 1.0)
            else:
                below_part = 1.0 if bin_low < cut else 0.0
            below += value * below_part
            above += value * (1.0 - below_part)
            if width > 0.0 and value > 0.0:
                # the part of the bin within the ghost cutoff of the cut, on either side
                near_low = max(bin_low, cut - ghost_cutoff)
                near_high = min(bin_high, cut)
                if near_high > near_low:
                    band_below += value * (near_high - near_low) / width
                near_low = max(bin_low, cut)
                near_high = min(bin_high, cut + ghost_cutoff)
                if near_high > near_low:
                    band_above += value * (near_high - near_low) / width
        total = below + above
        if total <= 0.0:
            scores[slot] = 1.0
            continue
        fraction = fractions[slot]
        scores[slot] = max((below + band_above) / (fraction * total),
                           (above + band_below) / ((1.0 - fraction) * total))
    return scores


@njit(cache=True)
def _cut_histogram(particle_slot, coordinate, weights, window_low, window_high, bins, count):
    """Weight per (slot, bin): bin 0 below the slot's window, 1 .. bins across it, bins + 1 at or above
    its upper end; particles of finished regions (slot -1) are left out."""
    histogram = np.zeros((count, bins + 2))
    for i in range(particle_slot.shape[0]):
        slot = particle_slot[i]
        if slot < 0:
            continue
        histogram[slot, _bin_of(coordinate[i], window_low[slot], window_high[slot], bins)] += weights[i]
    return histogram


@njit(inline="always", cache=True)
def _bin_of(value, lower, upper, bins):
    """The histogram column of `value`: 0 below [lower, upper), 1 .. bins across it, bins + 1 at or above upper."""
    if value < lower:
        return 0
    if value >= upper:
        return bins + 1
    return 1 + min(bins - 1, int((value - lower) / (upper - lower) * bins))


@njit(cache=True)
def _median_bins(histogram, fractions, window_low, window_high, cuts):
    """Narrow each slot's window to the bin where the cumulative weight passes fractions x the total (in
    place), and put the cut in it linearly by weight.  No weight at all: the cut halves the window; the
    target beyond the window's last bin (weight at its upper end): the cut is the window's upper end."""
    count, columns = histogram.shape
    bins = columns - 2
    for slot in range(count):
        total = 0.0
        for column in range(columns):
            total += histogram[slot, column]
        lower = window_low[slot]
        width = (window_high[slot] - lower) / bins
        if total <= 0.0:
            cuts[slot] = lower + 0.5 * bins * width
            window_low[slot] = cuts[slot]
            window_high[slot] = cuts[slot]
            continue
        target = fractions[slot] * total
        below = histogram[slot, 0]
        found = -1
        for column in range(1, bins + 1):
            if below + histogram[slot, column] > target:
                found = column - 1
                break
            below += histogram[slot, column]
        if found < 0:
            if histogram[slot, 0] > target:  # the median lies below the window (cannot happen after round 1)
                cuts[slot] = lower
            else:
                cuts[slot] = window_high[slot]
            window_low[slot] = cuts[slot]
            window_high[slot] = cuts[slot]
            continue
        bin_low = lower + found * width
        share = (target - below) / histogram[slot, found + 1]
        cuts[slot] = bin_low + share * width
        window_low[slot] = bin_low
        window_high[slot] = bin_low + width if found < bins - 1 else window_high[slot]


def _link(node_left, node_right, parent_slot, child):
    if parent_slot is None:
        return
    parent, side = parent_slot
    (node_left if side == 0 else node_right)[parent] = child


def box_distance(points: np.ndarray, box_lower: np.ndarray, box_upper: np.ndarray) -> np.ndarray:
    """Euclidean distance of each point to an axis-aligned box (0 inside)."""
    below = np.maximum(box_lower - points, 0.0)
    above = np.maximum(points - box_upper, 0.0)
    gap = np.where(np.isfinite(below), below, 0.0) + np.where(np.isfinite(above), above, 0.0)
    return np.sqrt(np.sum(gap * gap, axis=-1))


@njit(cache=True)
def rows_near_box(points, shift, box_lower, box_upper, cutoff):
    """The rows of the points that, moved by `shift`, lie closer than `cutoff` to the box: box_distance's
    arithmetic (the same decisions, bit for bit) in one pass, where numpy's took several temporaries and 30 ns
    per point (the ghost selection of every rebuild on every rank)."""
    count = points.shape[0]
    rows = np.empty(count, dtype=np.int64)
    found = 0
    for i in range(count):
        total = 0.0
        for axis in range(3):
            point = points[i, axis] + shift[axis]
            below = box_lower[axis] - point
            above = point - box_upper[axis]
            # np.maximum(., 0) keeps NaN, which the finite test then drops, as it drops inf
            below = below if below > 0.0 or below != below else 0.0
            above = above if above > 0.0 or above != above else 0.0
            gap = (below if np.isfinite(below) else 0.0) + (above if np.isfinite(above) else 0.0)
            total += gap * gap
        rows[found] = i
        found += math.sqrt(total) < cutoff
    return rows[:found]


@njit(inline="always", cache=True)
def _touching(positions, radii, i, j):
    """Whether particles i and j overlap (their centres closer than the sum of their radii)."""
    dx = positions[i, 0] - positions[j, 0]
    dy = positions[i, 1] - positions[j, 1]
    dz = positions[i, 2] - positions[j, 2]
    gap = radii[i] + radii[j]
    return dx * dx + dy * dy + dz * dz < gap * gap


@njit(cache=True)
def add_pair_costs(row_particles, offsets, partners, positions, radii, contact_cost, costs):
    """The bisection's particle weights from the neighbour list (ParticleSystem._particle_costs): costs[i] and
    costs[j] += 1 + contact_cost x touching, for every listed pair (i, j), in one pass (numpy's version
    materialised six pair-length arrays at every rebuild on several ranks)."""
    for r in range(row_particles.shape[0]):
        i = row_particles[r]
        for row in range(offsets[r], offsets[r + 1]):
            j = partners[row]
            weight = 1.0 + contact_cost if _touching(positions, radii, i, j) else 1.0
            costs[i] += weight
            costs[j] += weight


@njit(cache=True)
def touching_pair_ends(row_particles, offsets, partners, positions, radii, owned_count):
    """How many ends of the listed pairs that touch are owned particles (two for a pair of owned particles, one for a
    pair with a ghost): the touching test of add_pair_costs, counted."""
    ends = 0
    for r in range(row_particles.shape[0]):
        i = row_particles[r]
        for row in range(offsets[r], offsets[r + 1]):
            j = partners[row]
            if _touching(positions, radii, i, j):
                ends += (i < owned_count) + (j < owned_count)
    return ends
