"""Particle state as structure-of-arrays numpy arrays: owned particles first, then ghosts.

Kernels read and write these arrays directly; nothing here holds scene objects.
Rows [0, owned_count) are the particles this rank integrates; rows after them
are ghost copies of neighbours' particles (read-only inputs to the contact
kernels).  Every per-particle array is a registered *field* (`FieldSpec`); its
flags decide where it goes:

    migrate        travels with an owned particle to the rank that owns it next (rebuilds)
    ghost_rebuild  sent in full to the ghost copies when the ghosts are chosen (rebuilds)
    ghost_step     refreshed on the ghost copies every step between rebuilds (float64 only)
    checkpoint     written to checkpoints (state_dict) and read back (load_state_dict)
    periodic_shift a position: a ghost of a periodic image gets the image's shift added

A field registered between rebuilds reaches the ghosts at the next step (ghost_step) or
the next rebuild (ghost_rebuild only).  Every field is permuted by `reorder` (cell sort)
and kept by `keep`.  The core fields are attributes (`state.positions`, ...); a
module that needs its own per-particle state (e.g. mesh-wall contact history)
registers it with `add_field` and reads it as `state.fields[name]`.  Migration,
the ghost exchanges and the checkpoint take their field lists from the registry,
so a new field needs no change there.
"""
from __future__ import annotations

import math

from dataclasses import asdict, dataclass

import numpy as np
from numba import njit

from pdemfem import state_dict as kinds


@dataclass(frozen=True)
class FieldSpec:
    name: str
    migrate: bool = True
    ghost_rebuild: bool = False
    ghost_step: bool = False
    checkpoint: bool = True
    periodic_shift: bool = False
    # The value of a new particle's row (pdemfem.particles.stream inserts particles mid-run).
    fill: float = 0

    def flags(self) -> dict:
        flags = asdict(self)
        flags.pop("name")
        return flags


# Where in a 4 KiB page each field's buffer starts.  Arrays read and written in one loop (kick_drift: eight
# of them) whose addresses agree in their low 12 bits make the core take a load for a possibly pending store
# ("4K aliasing") and crowd the same L1 sets.  malloc starts every array above 128 kB 16 bytes into a page, and
# later in a run at offsets that collide by chance: the same kick_drift took 54 us on one rank and 87 us on the
# other at 14,000 particles, and 1.17-1.47x the staggered time with every array at one offset.  Field k starts
# at the k-th point of the golden-ratio sequence over the page's 64 cache lines: any first n fields lie apart.
_PAGE_BYTES = 4096
_LINE_BYTES = 64
_GOLDEN_FRACTION = 0.6180339887498949


def page_offset(slot: int) -> int:
    """Byte offset into a 4 KiB page of the buffer of the field registered `slot`-th."""
    lines = _PAGE_BYTES // _LINE_BYTES
    return int((slot * _GOLDEN_FRACTION) % 1.0 * lines) * _LINE_BYTES


def staggered_empty(shape: tuple, dtype, slot: int) -> np.ndarray:
    """np.empty(shape, dtype), C-contiguous, starting `page_offset(slot)` bytes into a 4 KiB page."""
    dtype = np.dtype(dtype)
    size = math.prod(shape) * dtype.itemsize
    raw = np.empty(size + _PAGE_BYTES, dtype=np.uint8)
    start = (page_offset(slot) - raw.ctypes.data) % _PAGE_BYTES
    return raw[start:start + size].view(dtype).reshape(shape)


def _core(name, **flags) -> FieldSpec:
    return FieldSpec(name, **flags)


# What a ghost carries: everything the contact kernels read of a partner; positions and
# velocities change every step, the rest only at a rebuild.
_GHOST = {"ghost_rebuild": True}
_GHOST_STEP = {"ghost_rebuild": True, "ghost_step": True}
CORE_FIELDS = (
    _core("ids", **_GHOST),
    _core("material_index", **_GHOST),
    _core("radii", **_GHOST),
    _core("mass", **_GHOST),
    _core("inverse_mass", **_GHOST),
    _core("inverse_inertia", **_GHOST),
    _core("positions", periodic_shift=True, **_GHOST_STEP),
    _core("velocities", **_GHOST_STEP),
    _core("angular_velocities", **_GHOST_STEP),
    # The last step's loads: recomputed after every migration, but a checkpoint keeps them
    # (velocity Verlet's first half kick of the next step needs them).
    _core("forces", migrate=False),
    _core("torques", migrate=False),
    _core("positions_at_build", migrate=False, checkpoint=False),
)
# With heat on (pdemfem.particles.heat): the temperature travels, is refreshed on ghosts every step
# (the pair kernel reads the partner's), and is checkpointed; the step's heat flow [W] and the sum of
# the conductances [W/K] of each row's contacts are recomputed every step.  Without heat neither exists.
TEMPERATURE_FIELD = FieldSpec("temperatures", ghost_rebuild=True, ghost_step=True)
HEAT_FLOW_FIELD = FieldSpec("heat_flows", migrate=False, checkpoint=False)
# Each core field's slot in the page-offset sequence (page_offset); fields added later take the next ones.
CORE_FIELD_SLOTS = {spec.name: slot for slot, spec in enumerate(CORE_FIELDS)}
# Fields that define a particle and move with it between ranks.
MIGRATING_FIELDS = tuple(spec.name for spec in CORE_FIELDS if spec.migrate)


class ParticleState(kinds.StateComponent):
    """Spheres: identity, material, size, kinematics, loads and contact history."""

    def __init__(self, ids, material_index, radii, densities, positions, velocities, angular_velocities,
                 temperatures=None):
        count = len(ids)
        self.ids = np.ascontiguousarray(ids, dtype=np.int64)
        self.material_index = np.ascontiguousarray(material_index, dtype=np.int32)
        self.radii = np.ascontiguousarray(radii, dtype=np.float64)
        self.mass = 4.0 / 3.0 * np.pi * self.radii**3 * np.asarray(densities, dtype=np.float64)
        self.inverse_mass = 1.0 / self.mass
        # Solid sphere: I = 2/5 m r^2.
        self.inverse_inertia = 1.0 / (0.4 * self.mass * self.radii**2)
        self.positions = np.ascontiguousarray(positions, dtype=np.float64).reshape(count, 3)
        self.velocities = np.ascontiguousarray(velocities, dtype=np.float64).reshape(count, 3)
        self.angular_velocities = np.ascontiguousarray(angular_velocities, dtype=np.float64).reshape(count, 3)
        self.forces = np.zeros((count, 3))
        self.torques = np.zeros((count, 3))
        self.positions_at_build = self.positions.copy()
        self.registry = {spec.name: spec for spec in CORE_FIELDS}
        self._slots = dict(CORE_FIELD_SLOTS)  # page_offset's slot of every field ever registered, never reused
        self.registry_version = 0  # bumped when a field is added or removed (the ghost scatter re-plans)
        self._scratch_bytes = None  # reorder's gather target, kept from reorder to reorder
        self.fields = {}  # the arrays of the fields registered with add_field
        # name -> the buffer an array is the leading rows of, with spare rows for the next append
        # (`_append_to`): the ghosts appended at every rebuild then copy nothing but themselves.
        self._buffers = {}
        self.owned_count = count
        for name in self.registry:
            self._rehouse(name, count)
        if temperatures is not None:
            self.add_field(TEMPERATURE_FIELD.name, **TEMPERATURE_FIELD.flags())[:] = temperatures
            self.add_field(HEAT_FLOW_FIELD.name, (2,), **HEAT_FLOW_FIELD.flags())

    @property
    def temperatures(self):
        """Temperature [K] per row (owned, then ghosts); None when heat is off."""
        return self.fields.get(TEMPERATURE_FIELD.name)

    @property
    def heat_flows(self):
        """Per row, this step: heat flowing in [W] (column 0) and the sum of its contacts' conductances [W/K]
        (column 1, the thermal step check); None when heat is off."""
        return self.fields.get(HEAT_FLOW_FIELD.name)

    # ------------------------------------------------------------ fields
    def add_field(self, name: str, tail_shape: tuple = (), dtype=np.float64, fill=0, *, migrate: bool = True,
                  ghost_rebuild: bool = False, ghost_step: bool = False, checkpoint: bool = True,
                  periodic_shift: bool = False) -> np.ndarray:
        """Register an extra per-particle array of shape (count, *tail_shape) (flags: module docstring)."""
        if name in self.registry:
            raise ValueError(f"per-particle field '{name}' registered twice")
        self._register(FieldSpec(name, migrate=migrate, ghost_rebuild=ghost_rebuild, ghost_step=ghost_step,
                                 checkpoint=checkpoint, periodic_shift=periodic_shift,
                                 fill=fill.item() if hasattr(fill, "item") else fill), np.dtype(dtype))
        self.fields[name] = staggered_empty((self.count, *tail_shape), dtype, self._slots[name])
        self.fields[name][...] = fill
        return self.fields[name]

    def _register(self, spec: FieldSpec, dtype) -> None:
        if (spec.ghost_step or spec.periodic_shift) and not spec.ghost_rebuild:
            raise ValueError(f"per-particle field '{spec.name}': a field refreshed on ghosts every step (or "
                             f"shifted for periodic images) must also be sent at rebuilds (ghost_rebuild)")
        if spec.ghost_step and dtype != np.float64:
            raise ValueError(f"per-particle field '{spec.name}': ghost_step fields must be float64 (the ghost "
                             f"update packs them all in one float64 kernel call), got {dtype}")
        self.registry[spec.name] = spec
        self._slots[spec.name] = max(self._slots.values()) + 1
        self.registry_version += 1

    def remove_field(self, name: str) -> np.ndarray:
        """Unregister a field added with add_field; returns its array."""
        if name not in self.fields:
            raise KeyError(f"no per-particle field '{name}' added with add_field")
        del self.registry[name]
        self.registry_version += 1
        self._buffers.pop(name, None)
        return self.fields.pop(name)

    def _new_buffer(self, name: str, rows: int, like: np.ndarray) -> np.ndarray:
        """A buffer for the field's first `rows` rows and spare ones after them, at the field's page offset."""
        return staggered_empty((_spare_rows(rows), *like.shape[1:]), like.dtype, self._slots[name])

    def _rehouse(self, name: str, rows: int) -> None:
        """Move the field's array into a buffer of its own (page offset, spare rows)."""
        values = self.array(name)
        buffer = self._new_buffer(name, rows, values)
        buffer[:rows] = values
        self._buffers[name] = buffer
        self._set(name, buffer[:rows])

    def record_build_positions(self) -> None:
        """positions_at_build := positions, every row (a list build): copied into the field's own buffer."""
        rows = self.count
        buffer = self._buffers.get("positions_at_build")
        if buffer is None or len(buffer) < rows:
            buffer = self._buffers["positions_at_build"] = self._new_buffer("positions_at_build", rows, self.positions)
        buffer[:rows] = self.positions
        self.positions_at_build = buffer[:rows]

    def array(self, name: str) -> np.ndarray:
        return self.fields[name] if name in self.fields else getattr(self, name)

    def _set(self, name, values):
        if name in self.fields:
            self.fields[name] = values
        else:
            setattr(self, name, values)

    def field_names(self, flag: str) -> list:
        """Names of the registered fields with the given flag set (registration order)."""
        return [name for name, spec in self.registry.items() if getattr(spec, flag)]

    def _all_arrays(self):
        for name in self.registry:
            yield name, self.array(name)

    @property
    def count(self) -> int:
        """Rows held: owned particles plus ghosts."""
        return len(self.ids)

    @property
    def ghost_count(self) -> int:
        return self.count - self.owned_count

    # ------------------------------------------------------------ reshaping
    def reorder(self, permutation: np.ndarray) -> None:
        """Permute the owned rows (ghosts must have been dropped first)."""
        assert self.ghost_count == 0, "reorder owned particles only"
        count = len(permutation)
        for name, values in self._all_arrays():
            # Gathered into one scratch buffer kept for every field and copied back: each array stays in its
            # buffer (page offset, spare rows for the ghosts appended next).  A fresh buffer per field and
            # reorder is mapped afresh by malloc above its threshold (pdemfem.runtime.fix_malloc) and
            # page-faulted (at 28,000 particles each 3-vector field is 672 KB, 164 pages); with this and the
            # list build's kept sorted positions, steps 500-2000 of the settle scene page-faulted 4,200 times
            # instead of 9,800.
            scratch = self._scratch(values.shape, values.dtype)
            np.take(values, permutation, axis=0, out=scratch)
            values[...] = scratch

    def _scratch(self, shape, dtype) -> np.ndarray:
        """A view of the scratch bytes kept for reorder, as an array of `shape` and `dtype`."""
        size = math.prod(shape) * np.dtype(dtype).itemsize
        if self._scratch_bytes is None or len(self._scratch_bytes) < size:
            self._scratch_bytes = np.empty(int(1.25 * size) + 4096, dtype=np.uint8)
        return self._scratch_bytes[:size].view(dtype).reshape(shape)

    def keep(self, rows: np.ndarray) -> None:
        """Keep only the given rows (owned), in place: the kept rows move to the front of each array, which
        stays a view of its buffer, so the particles that arrive next (migration) fill its spare rows instead
        of a copy of every array (a rebuild that migrates copied each array twice).  Drops ghosts."""
        count = len(rows)
        for name, values in self._all_arrays():
            values[:count] = values[rows]  # numpy gathers into a temporary first: any order of rows is safe
            self._set(name, values[:count])
        self.owned_count = count

    def remove(self, rows: np.ndarray) -> None:
        """Remove the given owned rows (sorted, unique), in place: the last kept rows move into the holes, so the
        cost goes with the rows removed, not with all rows (keep's order-preserving gather copied every row of
        every array: 0.6 ms per migration at 20,000 particles, most of the migration).  The rows' order
        changes; the cell sort restores locality when it has broken enough (ParticleSystem._sort_owned).
        Drops ghosts."""
        count = self.owned_count - len(rows)
        holes = rows[rows < count]
        # The tail's rows that stay: a mask over the tail (np.isin sorted both: 0.2 ms per migration).
        staying = np.ones(len(rows), dtype=bool)
        staying[rows[rows >= count] - count] = False
        staying_tail = np.flatnonzero(staying) + count
        for name, values in self._all_arrays():
            if len(holes):
                values[holes] = values[staying_tail]
            self._set(name, values[:count])
        self.owned_count = count

    def drop_ghosts(self) -> None:
        # The owned rows lead every array: a slice of them is a contiguous view, no copy (the next append
        # writes into the rows after it, _append_to).
        if self.ghost_count:
            for name, values in self._all_arrays():
                self._set(name, values[:self.owned_count])

    def layout(self, flag: str):
        """([(name, first column, columns, tail shape, dtype)], width) of the fields with `flag`
        packed side by side into float64 rows."""
        layout, width = [], 0
        for name in self.field_names(flag):
            values = self.array(name)
            columns = math.prod(values.shape[1:])  # numpy's prod cost 5 us a field: 100 us per migration
            layout.append((name, width, columns, values.shape[1:], values.dtype))
            width += columns
        return layout, width

    def migrating_layout(self):
        return self.layout("migrate")

    def ghost_layout(self):
        return self.layout("ghost_rebuild")

    def pack_rows(self, rows: np.ndarray, layout, width) -> np.ndarray:
        """Rows of the named fields as one float64 matrix (ids and ints are exact below 2^53)."""
        packed = np.empty((len(rows), width))
        rows = np.ascontiguousarray(rows, dtype=np.int64)
        for name, start, columns, _, dtype in layout:
            values = self.array(name)
            if dtype in _KERNEL_DTYPES:
                # One compiled gather per field: numpy's fancy index and strided copy cost 25 us a field for
                # the 1,500 ghosts of a rebuild (0.25 of its 0.8 ms ghost planning).
                _gather_rows(values.reshape(len(values), columns), rows, packed, start)
            else:
                packed[:, start:start + columns] = values[rows].reshape(len(rows), columns)
        return packed

    def _grow(self, name: str, count: int) -> np.ndarray:
        """Make room for `count` more rows of the field; returns the new rows (uninitialised).  They go into
        the spare rows of the array's buffer when it has them: the array becomes a longer view of the same
        buffer and no existing row is copied."""
        values = self.array(name)
        held = len(values)
        buffer = self._buffers.get(name)
        # (values are the buffer's leading rows when they start where it starts: it is alive, so nothing else is)
        if not (buffer is not None and held + count <= len(buffer)
                and values.__array_interface__["data"][0] == buffer.__array_interface__["data"][0]):
            buffer = self._new_buffer(name, held + count, values)
            buffer[:held] = values
            self._buffers[name] = buffer
        self._set(name, buffer[:held + count])
        return buffer[held:held + count]

    def _append_to(self, name: str, count: int, rows) -> None:
        """Append `count` rows to the field: `rows` (cast to the field's dtype) or one value for all of them."""
        self._grow(name, count)[...] = rows

    def append_rows(self, packed: np.ndarray, layout, as_ghosts: bool) -> None:
        """Append unpacked rows; fields not in the layout get zeros."""
        count = len(packed)
        if count == 0:
            return  # nothing arrived: keep the arrays as they are
        given = {name for name, *_ in layout}
        for name, start, columns, tail, dtype in layout:
            new_rows = self._grow(name, count)
            if dtype in _KERNEL_DTYPES:
                _scatter_columns(packed, start, new_rows.reshape(count, columns), dtype != np.float64)
            else:
                new = packed[:, start:start + columns].reshape((count, *tail))
                new_rows[...] = np.rint(new) if np.issubdtype(dtype, np.integer) else new
        for name in self.registry:
            if name not in given:
                self._append_to(name, count, 0)
        if not as_ghosts:
            self.owned_count += count

    def append_particles(self, new: "ParticleState") -> None:
        """Append the particles of `new` (built by the constructor, so its core fields are complete) as
        owned rows (ghosts must have been dropped first); every field added with add_field gets its fill."""
        assert self.ghost_count == 0, "append owned particles only"
        for name in self.registry:
            self._append_to(name, new.count, new.array(name) if name in new.registry else self.registry[name].fill)
        self.owned_count += new.count

    def nbytes(self) -> int:
        return sum(values.nbytes for _, values in self._all_arrays())

    # ------------------------------------------------------------ checkpoints
    def state_dict(self) -> dict:
        """The owned rows of every checkpointed field (PARTICLE_ROWS, keyed by ids), and the flags of
        the fields added with add_field (so a restart registers them before their owner asks)."""
        owned = self.owned_count
        rows = {"ids": kinds.Entry(kinds.PARTICLE_IDS, self.ids[:owned])}
        for name in self.field_names("checkpoint"):
            if name != "ids":
                rows[name] = kinds.particle_rows(self.array(name)[:owned])
        return {"rows": rows, "added_fields": kinds.scalar({name: self.registry[name].flags() for name in self.fields
                                                            if self.registry[name].checkpoint})}

    def load_state_dict(self, state: dict) -> None:
        """This rank's share of the stored particles replaces every row (ghosts included); fields the
        file holds that are not registered yet are registered with their stored flags."""
        rows = state["rows"]
        for name, flags in state["added_fields"].items():
            if name not in self.registry and name in rows:
                self._register(FieldSpec(name, **flags), np.asarray(rows[name]).dtype)
                self.fields[name] = np.asarray(rows[name])
        missing = sorted(name for name in self.field_names("checkpoint") if name not in rows)
        if missing:
            raise kinds.StateMismatch(f"lacks the per-particle state {missing} this scene needs")
        count = len(rows["ids"])
        self._buffers.clear()
        for name, values in self._all_arrays():
            if self.registry[name].checkpoint:
                self._set(name, np.ascontiguousarray(rows[name], dtype=values.dtype))
            else:
                self._set(name, np.zeros((count, *values.shape[1:]), dtype=values.dtype))
            self._rehouse(name, count)
        self.record_build_positions()
        self.owned_count = count


# The dtypes pack_rows and append_rows move with compiled loops (others go through numpy).
_KERNEL_DTYPES = (np.dtype(np.float64), np.dtype(np.int64), np.dtype(np.int32))


@njit(cache=True)
def _gather_rows(values, rows, packed, start):
    """packed[k, start + c] = values[rows[k], c]: one field's (count, columns) view into the packed matrix."""
    for k in range(rows.shape[0]):
        row = rows[k]
        for column in range(values.shape[1]):
            packed[k, start + column] = values[row, column]


@njit(cache=True)
def _scatter_columns(packed, start, destination, integer):
    """destination[k, c] = packed[k, start + c], rounded to the nearest integer for an `integer` field (ids
    and indices travel exactly as float64 below 2^53)."""
    for k in range(destination.shape[0]):
        for column in range(destination.shape[1]):
            value = packed[k, start + column]
            destination[k, column] = np.rint(value) if integer else value


def _spare_rows(rows: int) -> int:
    """A buffer's length for `rows` rows: a fifth more, so that the ghosts of the next rebuilds (their count
    drifts) fit without a copy."""
    return rows + rows // 5 + 16
