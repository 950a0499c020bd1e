"""Particle output: one HDF5 file written collectively, plus its XDMF index.

    out = ParticleOutput("out", comm, ["positions", "velocities", "radii", "ids", "forces", "temperature"])
    out.write(time, step, {"positions": x[:n_owned], "velocities": v[:n_owned], ...})   # collective
    out.close()

Every rank passes only the rows it owns (no ghosts).  The rows are written straight
from each rank into the shared file with h5py's mpio driver at the offset given by an
exclusive prefix sum of the owned counts, so no rank ever holds more than its own
particles.  Row order in a step is rank order, so it changes with the decomposition:
use the ``ids`` field to follow a particle between steps.

File layout (``particles.h5``)::

    /step_0000000100/          attrs: time, step, count
        positions   (N, 3) float64      velocities (N, 3)    forces (N, 3)
        radii       (N,)   float64      ids        (N,) int64  temperature (N,)
    /step_0000000200/ ...
    /polyvertex               (N_max,) int64 = 0, 1, 2, ...  (shared Polyvertex connectivity)

One group per output step (instead of one extendable dataset per field with a time
axis) because the particle count changes between steps (insertion, outflow): a group
gives every step datasets of exactly its own size with no ragged indexing, the XDMF
points at them directly, and a step is removed on restart by deleting one group.
The Polyvertex connectivity 0..N-1 is the same for every step, so it is stored once
(grown when the count grows) and each step's index takes a HyperSlab of it.

The file is opened and closed around each write, so between writes it is complete
on disk; the XDMF index (``particles.xdmf``) is replaced atomically by rank 0 after
each step and therefore names only fully written steps.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from pdemfem.io import xdmf

# name -> (per-row shape, dtype kind); floats are written in the writer's float dtype.
PARTICLE_FIELDS = {
    "positions": ((3,), "f"),
    "velocities": ((3,), "f"),
    "radii": ((), "f"),
    "ids": ((), "i"),
    "forces": ((3,), "f"),
    "temperature": ((), "f"),
    "angular_velocities": ((3,), "f"),
    "torques": ((3,), "f"),
    "materials": ((), "i"),
}
DEFAULT_FIELDS = ("positions", "velocities", "radii", "ids", "forces", "temperature")
CONNECTIVITY = "/polyvertex"


def step_group(step: int) -> str:
    return f"step_{int(step):010d}"


class ParticleOutput:
    """Collective writer of the particle time series (see the module docstring).

    `resume_step`: None starts a new file (an existing one is replaced); an int keeps
    the steps of an existing file up to and including that step and appends after
    them (restart).  An existing file that cannot be read is moved aside to
    ``particles.h5.unreadable`` and a new one started.
    """

    def __init__(self, directory, comm, fields=DEFAULT_FIELDS, name: str = "particles",
                 resume_step: int | None = None, float_dtype=np.float64):
        self.comm = comm
        self.directory = xdmf.prepare_directory(Path(directory), comm)
        self.name = name
        self.h5_path = self.directory / f"{name}.h5"
        self.xdmf_path = self.directory / f"{name}.xdmf"
        self.float_dtype = np.dtype(float_dtype)
        fields = list(dict.fromkeys(fields))
        if "positions" not in fields:  # the geometry: without it nothing can be drawn
            fields.insert(0, "positions")
        self.fields = fields
        self._entries: list[dict] = []  # rank 0: what the XDMF index lists
        # rank 0: each listed step's grid text, made once: remade at every write, the index cost O(steps) in
        # Python per output (18 s of a 33 s run with 500 outputs of 250 particles).  Valid for one length of
        # the shared connectivity, which every grid's hyperslab names.
        self._grid_texts: dict[int, str] = {}
        self._texts_connectivity = 0
        self._connectivity_length = 0
        if resume_step is None:
            with xdmf.open_parallel(self.h5_path, "w", comm):
                pass
        else:
            self._resume(int(resume_step))
        self._index = xdmf.IndexFile(self.xdmf_path)
        if comm.rank == 0:
            self._index.write(self._document)

    # ------------------------------------------------------------------ write
    def _field_spec(self, name: str, values: np.ndarray) -> tuple[tuple, np.dtype]:
        if name in PARTICLE_FIELDS:
            trailing, kind = PARTICLE_FIELDS[name]
        else:  # an extra per-particle field: shape from the array, dtype by kind
            trailing, kind = tuple(np.shape(values)[1:]), np.asarray(values).dtype.kind
        dtype = np.dtype(np.int64) if kind in "iub" else self.float_dtype
        return tuple(trailing), dtype

    def write(self, time: float, step: int, arrays: dict) -> None:
        """Write one output step (collective).  `arrays` holds this rank's owned rows per field."""
        missing = [name for name in self.fields if name not in arrays]
        if missing:
            raise KeyError(f"particle output: no array for field(s) {missing}")
        rows = {}
        count = None
        for name in self.fields:
            trailing, dtype = self._field_spec(name, arrays[name])
            rows[name] = xdmf.as_rows(name, arrays[name], dtype, trailing)
            if count is None:
                count = len(rows[name])
            elif len(rows[name]) != count:
                raise ValueError(f"particle output: {name} has {len(rows[name])} rows, positions {count}")
        offset, total = xdmf.owned_offset(self.comm, count)
        group_name = step_group(step)
        with xdmf.open_parallel(self.h5_path, "a", self.comm) as handle:
            if group_name in handle:  # the same step written again (e.g. final step after a stop)
                del handle[group_name]
            group = handle.create_group(group_name)
            group.attrs["time"] = float(time)
            group.attrs["step"] = int(step)
            group.attrs["count"] = int(total)
            for name in self.fields:
                dataset = group.create_dataset(name, shape=(total, *rows[name].shape[1:]), dtype=rows[name].dtype)
                xdmf.write_slab(dataset, offset, rows[name])
            self._grow_connectivity(handle, total)
        if self.comm.rank == 0:
            self._entries = [e for e in self._entries if e["step"] != int(step)]
            self._grid_texts.pop(int(step), None)
            self._entries.append({
                "step": int(step), "time": float(time), "count": int(total),
                "fields": {name: (rows[name].shape[1:], rows[name].dtype) for name in self.fields},
            })
            self._entries.sort(key=lambda e: e["step"])
            self._index.update(self._document)

    def _grow_connectivity(self, handle, total: int) -> None:
        length = self._connectivity_length
        if total <= length:
            return
        new_length = max(total, int(length * 1.5))
        if CONNECTIVITY in handle:
            dataset = handle[CONNECTIVITY]
            dataset.resize((new_length,))
        else:
            dataset = handle.create_dataset(CONNECTIVITY, shape=(new_length,), maxshape=(None,),
                                            chunks=(min(1 << 20, max(new_length, 1)),), dtype=np.int64)
        # Each rank fills a piece of the new tail.
        start, stop = length + (new_length - length) * self.comm.rank // self.comm.size, \
            length + (new_length - length) * (self.comm.rank + 1) // self.comm.size
        if stop > start:
            dataset[start:stop] = np.arange(start, stop, dtype=np.int64)
        self._connectivity_length = new_length

    def close(self) -> None:
        """Write the index if steps were written since its last rewrite (rank 0; nothing else stays open)."""
        if self.comm.rank == 0:
            self._index.flush(self._document)

    # ---------------------------------------------------------------- restart
    def _resume(self, resume_step: int) -> None:
        import h5py

        state = None
        if self.comm.rank == 0:
            state = {"entries": [], "connectivity": 0, "fresh": False}
            try:
                if not self.h5_path.exists():
                    raise FileNotFoundError(self.h5_path)
                with h5py.File(self.h5_path, "a") as handle:
                    for key in list(handle.keys()):
                        if not key.startswith("step_"):
                            continue
                        group = handle[key]
                        step = int(group.attrs["step"])
                        if step > resume_step:
                            del handle[key]
                            continue
                        state["entries"].append({
                            "step": step, "time": float(group.attrs["time"]), "count": int(group.attrs["count"]),
                            "fields": {name: (group[name].shape[1:], group[name].dtype) for name in group},
                        })
                    if CONNECTIVITY in handle:
                        state["connectivity"] = int(handle[CONNECTIVITY].shape[0])
            except FileNotFoundError:
                state["fresh"] = True
            except Exception:  # unreadable (e.g. killed mid-write): keep it for inspection, start anew
                self.h5_path.replace(self.h5_path.with_name(self.h5_path.name + ".unreadable"))
                state = {"entries": [], "connectivity": 0, "fresh": True}
            state["entries"].sort(key=lambda e: e["step"])
        state = self.comm.bcast(state, root=0)
        self._connectivity_length = state["connectivity"]
        if self.comm.rank == 0:
            self._entries = state["entries"]
        if state["fresh"]:
            with xdmf.open_parallel(self.h5_path, "w", self.comm):
                pass

    # ------------------------------------------------------------------- XDMF
    def _document(self) -> str:
        if self._texts_connectivity != self._connectivity_length:
            self._grid_texts, self._texts_connectivity = {}, self._connectivity_length
        grids = []
        for entry in self._entries:
            text = self._grid_texts.get(entry["step"])
            if text is None:
                text = self._grid_texts[entry["step"]] = self._grid(entry)
            grids.append(text)
        return xdmf.temporal_collection(self.name, grids)

    def _grid(self, entry: dict) -> str:
        """One step's grid of the index: the points (a polyvertex over the shared connectivity) and their fields."""
        h5_name, count = self.h5_path.name, entry["count"]
        group = "/" + step_group(entry["step"])
        if count == 0:
            # A step without particles (all left, none inserted yet) is a grid with its time alone: ParaView's Xdmf3
            # reader aborts on a zero-size data item, and a step left out of the index showed the last particles
            # frozen until the end of the run.
            return xdmf.uniform_grid(group[1:], entry["time"], [])
        parts = [
            '<Topology TopologyType="Polyvertex" NumberOfElements="%d" NodesPerElement="1">%s</Topology>'
            % (count, xdmf.hyperslab_item(h5_name, CONNECTIVITY, 0, count, self._connectivity_length, np.int64)),
            '<Geometry GeometryType="XYZ">%s</Geometry>'
            % xdmf.data_item(h5_name, f"{group}/positions", (count, 3), entry["fields"]["positions"][1]),
        ]
        for name, (trailing, dtype) in entry["fields"].items():
            if name == "positions":
                continue
            parts.append(xdmf.attribute(name, "Node", h5_name, f"{group}/{name}", (count, *trailing), dtype))
        return xdmf.uniform_grid(group[1:], entry["time"], parts)
