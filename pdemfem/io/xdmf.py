"""XDMF 3 descriptions of HDF5 time series, and the parallel-HDF5 helpers the writers share.

The heavy data lives in HDF5 (written collectively, see particle_output.py and
solid_output.py); the XDMF file is a small XML index that ParaView's Xdmf3 reader
and meshio's ``meshio.xdmf.TimeSeriesReader`` read.  Rank 0 regenerates the whole
index after an output step and installs it with write-to-temp + ``os.replace``,
so a reader (or a run killed at any instant) never sees a half-written index, and
the index only ever names steps whose data was completely written and closed.  The
index grows with the steps, so it is rewritten after a step only when the time since
its last rewrite is INDEX_REWRITE_RATIO times what that rewrite took, and always when
the writer closes (IndexFile): rewritten after every step, 2000 outputs of 27
particles spent 37 of 65 s making and writing it (the cost per output grew with the
outputs written).  A run killed between rewrites leaves an index a few steps behind
its data.

Layout of one index (one ``Grid`` per output step inside a temporal collection)::

    <Xdmf Version="3.0"><Domain>
      <Grid Name="particles" GridType="Collection" CollectionType="Temporal">
        <Grid Name="step_0000000100" GridType="Uniform">
          <Time Value="0.001"/>
          <Topology .../> <Geometry .../> <Attribute .../> ...
"""
from __future__ import annotations

import os
import secrets
import time
from pathlib import Path
from xml.sax.saxutils import quoteattr, escape

import numpy as np
from mpi4py import MPI

# ----------------------------------------------------------------- XML pieces


def number_type(dtype) -> tuple[str, int]:
    """XDMF (NumberType, Precision) of a numpy dtype."""
    dtype = np.dtype(dtype)
    if dtype.kind == "f":
        return "Float", dtype.itemsize
    if dtype.kind == "i":
        return "Int", dtype.itemsize
    if dtype.kind == "u":
        return "UInt", dtype.itemsize
    if dtype.kind == "b":
        return "UChar", 1
    raise TypeError(f"no XDMF number type for {dtype}")


def attribute_type(trailing_shape: tuple) -> str:
    """XDMF AttributeType of per-point/per-cell values with this trailing shape."""
    size = int(np.prod(trailing_shape)) if trailing_shape else 1
    if not trailing_shape or size == 1:
        return "Scalar"
    if size == 3 and len(trailing_shape) == 1:
        return "Vector"
    if size == 6 and len(trailing_shape) == 1:
        return "Tensor6"
    if size == 9:
        return "Tensor"
    return "Matrix"


def data_item(h5_name: str, h5_path: str, shape: tuple, dtype) -> str:
    """A DataItem naming a whole HDF5 dataset (`h5_name` relative to the XDMF file)."""
    kind, precision = number_type(dtype)
    dims = " ".join(str(int(d)) for d in shape)
    return (f'<DataItem Dimensions="{dims}" NumberType="{kind}" Precision="{precision}" '
            f'Format="HDF">{escape(h5_name)}:{escape(h5_path)}</DataItem>')


def hyperslab_item(h5_name: str, h5_path: str, start: int, count: int, full_length: int, dtype) -> str:
    """The rows [start, start+count) of a 1-D dataset of `full_length` rows."""
    return (f'<DataItem ItemType="HyperSlab" Dimensions="{count}" Type="HyperSlab">'
            f'<DataItem Dimensions="3 1" Format="XML">{start} 1 {count}</DataItem>'
            f'{data_item(h5_name, h5_path, (full_length,), dtype)}</DataItem>')


def attribute(name: str, center: str, h5_name: str, h5_path: str, shape: tuple, dtype) -> str:
    """An Attribute (Center "Node" or "Cell") with values in an HDF5 dataset."""
    kind = attribute_type(tuple(shape[1:]))
    if kind == "Tensor" and len(shape) == 3:
        shape = (shape[0], 9)
    return (f'<Attribute Name={quoteattr(name)} AttributeType="{kind}" Center="{center}">'
            f'{data_item(h5_name, h5_path, shape, dtype)}</Attribute>')


def uniform_grid(name: str, time: float, parts: list[str]) -> str:
    return (f'    <Grid Name={quoteattr(name)} GridType="Uniform">\n'
            f'      <Time Value="{float(time)!r}"/>\n'
            + "".join(f"      {part}\n" for part in parts)
            + "    </Grid>\n")


def temporal_collection(name: str, grids: list[str]) -> str:
    """The whole XDMF document for a list of `uniform_grid` strings (in time order)."""
    return ('<?xml version="1.0" encoding="utf-8"?>\n'
            '<Xdmf xmlns:xi="http://www.w3.org/2001/XInclude" Version="3.0">\n'
            '  <Domain>\n'
            f'   <Grid Name={quoteattr(name)} GridType="Collection" CollectionType="Temporal">\n'
            + "".join(grids)
            + '   </Grid>\n  </Domain>\n</Xdmf>\n')


def write_atomic(path: Path, text: str) -> None:
    """Replace `path` by `text` so that readers see either the old or the new file, whole.

    Written to a temporary name in the same directory, flushed and fsync'ed, then
    renamed over the target (rename is atomic within a POSIX file system).
    """
    path = Path(path)
    temporary = path.with_name(f"{path.name}.tmp-{secrets.token_hex(4)}")
    try:
        with open(temporary, "w", encoding="utf-8") as handle:
            handle.write(text)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(temporary, path)
    finally:
        if temporary.exists():
            temporary.unlink()


# The index is rewritten when the time since its last rewrite is at least this many times what that rewrite took:
# at most about 1 / (1 + ratio) of a run's time goes to it, however many steps it lists.
INDEX_REWRITE_RATIO = 10.0


class IndexFile:
    """Rank 0's XDMF index file (see the module docstring): `update` after each output step, `flush` when the
    writer closes.  `document` is a callable that makes the whole index text (called only to write it)."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self._pending = False
        self._last_end = -float("inf")
        self._last_duration = 0.0

    def update(self, document) -> None:
        if time.perf_counter() - self._last_end >= INDEX_REWRITE_RATIO * self._last_duration:
            self.write(document)
        else:
            self._pending = True

    def flush(self, document) -> None:
        if self._pending:
            self.write(document)

    def write(self, document) -> None:
        start = time.perf_counter()
        write_atomic(self.path, document())
        self._last_end = time.perf_counter()
        self._last_duration = self._last_end - start
        self._pending = False


# ------------------------------------------------- parallel HDF5 helpers


def owned_offset(comm, count: int) -> tuple[int, int]:
    """(first global row of this rank's slab, global row count) for `count` owned rows.

    One Allgather of one int64 per rank: the offset is the exclusive prefix sum in
    rank order, so the file holds rank 0's rows, then rank 1's, ...
    """
    counts = np.zeros(comm.size, dtype=np.int64)
    comm.Allgather(np.array([count], dtype=np.int64), counts)
    return int(counts[: comm.rank].sum()), int(counts.sum())


def prepare_directory(directory: Path, comm) -> Path:
    """Create `directory` on rank 0 and make every rank wait until it exists."""
    directory = Path(directory)
    error = None
    if comm.rank == 0:
        try:
            directory.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            error = str(exc)
    error = comm.bcast(error, root=0)
    if error is not None:
        from pdemfem.errors import PdemfemError

        raise PdemfemError(str(directory), f"cannot create the output directory ({error})",
                           "choose a writable output.dir")
    return directory


def write_slab(dataset, offset: int, values: np.ndarray) -> None:
    """Write this rank's rows at `offset` (independent I/O; nothing to do for no rows)."""
    if len(values):
        dataset[offset: offset + len(values)] = values


def open_parallel(path: Path, mode: str, comm):
    """h5py.File with the mpio driver (collective open; every rank must call it)."""
    import h5py

    return h5py.File(path, mode, driver="mpio", comm=comm)


def as_rows(name: str, values, dtype, trailing: tuple | None = None) -> np.ndarray:
    """`values` as a C-contiguous array of `dtype` (checking the per-row shape if given)."""
    array = np.ascontiguousarray(values, dtype=dtype)
    if trailing is not None and array.shape[1:] != tuple(trailing):
        if array.size == 0:
            return array.reshape((0, *trailing))
        raise ValueError(f"{name}: expected rows of shape {tuple(trailing)}, got {array.shape}")
    return array


__all__ = [
    "number_type", "attribute_type", "data_item", "hyperslab_item", "attribute", "uniform_grid",
    "temporal_collection", "write_atomic", "owned_offset", "prepare_directory", "write_slab",
    "open_parallel", "as_rows", "MPI",
]
