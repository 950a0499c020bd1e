"""Solid output: the P1 tetrahedral mesh once, nodal and cell fields per step, plus XDMF.

    out = SolidOutput("out", "plate", comm, owned_points, owned_cells, node_offset)
    out.write(time, step, point_data={"displacements": u, "velocities": v, "temperature": T},
              cell_data={"von_mises": s})                                    # collective

Inputs are rank-local: this rank owns the global nodes [node_offset, node_offset + n)
(``owned_points`` are their coordinates, in that order) and the cells ``owned_cells``
(every cell owned by exactly one rank), whose four entries are GLOBAL node numbers
in the same numbering.  Nodal fields hold one row per owned node, cell fields one
row per owned cell, in the order given here.  Cells are stored in rank order at the
offset of an exclusive prefix sum of the owned cell counts; nothing is gathered.

File layout (``<name>.h5``)::

    /mesh/points  (N, 3) float64      /mesh/cells (M, 4) int64   (written once)
    /step_0000000100/   attrs: time, step
        displacements (N, 3)  velocities (N, 3)  temperature (N,)  von_mises (M,)

The XDMF index (``<name>.xdmf``) repeats the Topology (Tetrahedron) and Geometry
references in every step's grid (XML only, the data is stored once), which is the
form both ParaView's Xdmf3 reader and ``meshio.xdmf.TimeSeriesReader`` read.  Use
ParaView's "Warp By Vector" with ``displacements`` to draw the deformed solid.
"""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from pdemfem.io import xdmf
from pdemfem.io.particle_output import step_group

log = logging.getLogger("pdemfem")


class SolidOutput:
    """Collective writer of one solid's time series (see the module docstring).

    `resume_step`: None writes a new file; an int reopens the existing file, keeps
    steps up to and including it (the mesh must have the same node and cell counts)
    and appends after them.
    """

    def __init__(self, directory, name: str, comm, owned_points, owned_cells, node_offset: int,
                 resume_step: int | None = None, float_dtype=np.float64):
        self.comm = comm
        self.name = name
        self.directory = xdmf.prepare_directory(Path(directory), comm)
        self.h5_path = self.directory / f"{name}.h5"
        self.xdmf_path = self.directory / f"{name}.xdmf"
        self.float_dtype = np.dtype(float_dtype)
        points = xdmf.as_rows("owned_points", owned_points, np.float64, (3,))
        cells = xdmf.as_rows("owned_cells", owned_cells, np.int64, (4,))
        self.n_nodes = len(points)
        self.n_cells = len(cells)
        self.node_offset = int(node_offset)
        first_node, self.total_nodes = xdmf.owned_offset(comm, self.n_nodes)
        self.cell_offset, self.total_cells = xdmf.owned_offset(comm, self.n_cells)
        # The caller's node offset must tile 0..N-1 without gaps or overlaps.
        bounds = np.array([self.node_offset, self.node_offset + self.n_nodes], dtype=np.int64)
        all_bounds = np.zeros((comm.size, 2), dtype=np.int64)
        comm.Allgather(bounds, all_bounds)
        order = np.argsort(all_bounds[:, 0], kind="stable")
        tiles = all_bounds[order]
        tiles = tiles[tiles[:, 1] > tiles[:, 0]]
        if len(tiles) and (tiles[0, 0] != 0 or tiles[-1, 1] != self.total_nodes
                           or np.any(tiles[1:, 0] != tiles[:-1, 1])):
            raise ValueError(f"solid output {name}: owned node ranges {all_bounds.tolist()} do not tile "
                             f"0..{self.total_nodes}")
        if len(cells) and (cells.min() < 0 or cells.max() >= self.total_nodes):
            raise ValueError(f"solid output {name}: cell node numbers outside 0..{self.total_nodes - 1}")
        self._entries: list[dict] = []
        self._grid_texts: dict[int, str] = {}  # rank 0: each listed step's grid text, made once
        # A restart resumes the file; one killed mid-write (unreadable) is moved aside and started anew, as
        # particles.h5 is: the run goes on from its checkpoint and the lost output steps are named in the log.
        if resume_step is None or not self.h5_path.exists() or not self._resume(int(resume_step)):
            with xdmf.open_parallel(self.h5_path, "w", comm) as handle:
                mesh = handle.create_group("mesh")
                xdmf.write_slab(mesh.create_dataset("points", (self.total_nodes, 3), np.float64),
                                self.node_offset, points)
                xdmf.write_slab(mesh.create_dataset("cells", (self.total_cells, 4), np.int64),
                                self.cell_offset, cells)
        self._index = xdmf.IndexFile(self.xdmf_path)
        if comm.rank == 0:
            self._index.write(self._document)

    def _rows(self, name, values, count):
        array = np.asarray(values)
        dtype = np.int64 if array.dtype.kind in "iub" else self.float_dtype
        array = np.ascontiguousarray(array, dtype=dtype)
        if len(array) != count:
            raise ValueError(f"solid output {self.name}: {name} has {len(array)} rows, expected {count}")
        return array

    def write(self, time: float, step: int, point_data: dict | None = None, cell_data: dict | None = None) -> None:
        """Write one output step (collective): owned-node rows and owned-cell rows per field."""
        point_data = {k: self._rows(k, v, self.n_nodes) for k, v in (point_data or {}).items()}
        cell_data = {k: self._rows(k, v, self.n_cells) for k, v in (cell_data or {}).items()}
        group_name = step_group(step)
        with xdmf.open_parallel(self.h5_path, "a", self.comm) as handle:
            if group_name in handle:
                del handle[group_name]
            group = handle.create_group(group_name)
            group.attrs["time"] = float(time)
            group.attrs["step"] = int(step)
            for data, total, offset, center in ((point_data, self.total_nodes, self.node_offset, "Node"),
                                                (cell_data, self.total_cells, self.cell_offset, "Cell")):
                for name in sorted(data):
                    dataset = group.create_dataset(name, (total, *data[name].shape[1:]), data[name].dtype)
                    dataset.attrs["center"] = center
                    xdmf.write_slab(dataset, offset, data[name])
        if self.comm.rank == 0:
            fields = {name: ("Node", a.shape[1:], a.dtype) for name, a in sorted(point_data.items())}
            fields.update({name: ("Cell", a.shape[1:], a.dtype) for name, a in sorted(cell_data.items())})
            self._entries = [e for e in self._entries if e["step"] != int(step)]
            self._grid_texts.pop(int(step), None)
            self._entries.append({"step": int(step), "time": float(time), "fields": fields})
            self._entries.sort(key=lambda e: e["step"])
            self._index.update(self._document)

    def close(self) -> None:
        """Write the index if steps were written since its last rewrite (rank 0; nothing else stays open)."""
        if self.comm.rank == 0:
            self._index.flush(self._document)

    def _resume(self, resume_step: int) -> bool:
        """Collective: keep the file's steps up to resume_step; False when it was unreadable (moved aside to
        <name>.h5.unreadable: the caller starts a new one).  A readable file of another mesh is an error."""
        import h5py

        state = None
        if self.comm.rank == 0:
            try:
                entries = []
                with h5py.File(self.h5_path, "a") as handle:
                    shape = (handle["mesh/points"].shape[0], handle["mesh/cells"].shape[0])
                    for key in list(handle.keys()):
                        if not key.startswith("step_"):
                            continue
                        group = handle[key]
                        if int(group.attrs["step"]) > resume_step:
                            del handle[key]
                            continue
                        entries.append({"step": int(group.attrs["step"]), "time": float(group.attrs["time"]),
                                        "fields": {name: (group[name].attrs["center"], group[name].shape[1:],
                                                          group[name].dtype) for name in group}})
                state = {"ok": shape == (self.total_nodes, self.total_cells),
                         "entries": sorted(entries, key=lambda e: e["step"])}
            except Exception:  # unreadable (e.g. killed mid-write): keep it for inspection, start anew
                self.h5_path.replace(self.h5_path.with_name(self.h5_path.name + ".unreadable"))
                log.warning("solid output %s: %s was unreadable (a run killed while writing it?); moved to "
                            "%s.unreadable and started anew from the restart step", self.name, self.h5_path,
                            self.h5_path.name)
                state = {"ok": True, "unreadable": True, "entries": []}
            if not state["ok"]:  # a different mesh: keep the old file aside
                self.h5_path.replace(self.h5_path.with_name(self.h5_path.name + ".previous"))
        state = self.comm.bcast(state, root=0)
        if not state["ok"]:
            raise ValueError(f"solid output {self.name}: {self.h5_path} does not hold this mesh; "
                             "it was moved to .previous, start without resume")
        if self.comm.rank == 0:
            self._entries = state["entries"]
        return not state.get("unreadable", False)

    def _document(self) -> str:
        h5_name = self.h5_path.name
        topology = ('<Topology TopologyType="Tetrahedron" NumberOfElements="%d" NodesPerElement="4">%s</Topology>'
                    % (self.total_cells, xdmf.data_item(h5_name, "/mesh/cells", (self.total_cells, 4), np.int64)))
        geometry = ('<Geometry GeometryType="XYZ">%s</Geometry>'
                    % xdmf.data_item(h5_name, "/mesh/points", (self.total_nodes, 3), np.float64))
        grids = []
        for entry in self._entries:
            text = self._grid_texts.get(entry["step"])
            if text is None:  # each step's grid is made once (see ParticleOutput._grid_texts)
                group = "/" + step_group(entry["step"])
                parts = [topology, geometry]
                for name, (center, trailing, dtype) in entry["fields"].items():
                    total = self.total_nodes if center == "Node" else self.total_cells
                    parts.append(xdmf.attribute(name, center, h5_name, f"{group}/{name}", (total, *trailing), dtype))
                text = self._grid_texts[entry["step"]] = xdmf.uniform_grid(group[1:], entry["time"], parts)
            grids.append(text)
        return xdmf.temporal_collection(self.name, grids)
