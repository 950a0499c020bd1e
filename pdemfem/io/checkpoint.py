"""Checkpoints: one HDF5 file with everything needed to continue, written atomically.

    path = checkpoint_path("out/checkpoints", step)
    write_checkpoint(path, comm, particle_arrays={"ids": ids, "positions": x, ...},   # owned rows
                     global_arrays={"wall_positions": w},                              # same on all ranks
                     slab_arrays={"u": (u_owned, first_row), "u_prev": (...)},        # owned slabs
                     contact_arrays={"pairs": pairs, "shear": xi},                     # owned contacts
                     attributes={"step": 1000, "time": 0.01, "scene_hash": h, "rng_state": json_text},
                     keep=2)
    checkpoint = read_checkpoint("out/checkpoints/latest.h5", comm, expected_hash=h, force=False)
    checkpoint.attributes["step"], checkpoint.particles["positions"], checkpoint.globals, checkpoint.slabs

    write_state(path, comm, {"particles": system.state_dict(), ...}, attributes, keep=2)   # state dicts
    checkpoint, state = read_state(path, comm, expected_hash=h)   # the same nesting, plain values

Writing (collective):
1. particles are sorted by global id across ranks with a parallel sort by regular
   sampling (see `sort_rows_by_key`), so the file is identical for any rank count and
   decomposition; contacts likewise by their (id_i, id_j) ``pairs``;
2. rank 0 creates ``<path>.tmp-<random>`` with HDF5 alone: attributes, groups, the
   global arrays, the checksums (order-independent sums, reduced over the ranks in one
   Allreduce before anything is sorted) and every other dataset with contiguous storage
   allocated at creation (never filled), whose byte offsets it broadcasts;
3. every rank writes its sorted block of each dataset straight into that storage with
   pwrite (at the dataset's offset plus its exclusive-prefix-sum row offset), one array
   after the other (the kernel writes one back while the next is sorted), and fsyncs;
4. rank 0 renames it to ``path`` with os.replace (atomic), fsyncs the directory,
   points ``latest.h5`` at it and deletes all but the newest `keep` of the checkpoints
   this run wrote (never another run's, never the one it restarted from).

A run killed at any instant (SIGKILL, node failure) therefore leaves at worst a stale
``*.tmp-*`` file (removed by the next write) and every named checkpoint whole.

Why not parallel HDF5 (the mpio driver) for the data: through MPI-IO a checkpoint
reached 0.29 (1 rank) and 0.09 (2 ranks) of the bandwidth of plain write() calls; with
the layout made by HDF5 and the data written by pwrite it reaches that bandwidth up to
the cost of sorting the rows by id (docs/performance.md).  The file is an ordinary HDF5
file either way: readers see no difference.

``latest.h5`` is a hard link (replaced atomically through a temporary link), not a
symbolic link or a copy: it can never dangle when checkpoints are pruned or moved by
hand, it costs no extra I/O or disk space (a copy would double the checkpoint's write
time), and tools that do not follow links (rsync without -H, tar, cp) still copy a real
file.  Where the file system has no hard links it falls back to a copy.

Reading (collective): every rank opens the file read-only on its own (no collective
HDF5 calls, so a bad file cannot hang some ranks), checks marker, format version,
scene hash and per-dataset checksums, and takes an even split of the id-sorted rows
(rank r of p gets rows [N r/p, N (r+1)/p)); the Simulation then migrates them to the
ranks that own them spatially.  Hence a restart works on any rank count.  All ranks
agree on any error and raise the same CheckpointError.

File layout::

    /            attrs: pdemfem_checkpoint=1, format_version, step, time, scene_hash, ...
                 (write_state: state_manifest, JSON: each entry's path and kind, the scalars)
    /particles/<field>   (N, ...)  sorted by ids                attrs: sum64
    /contacts/<field>    (K, ...)  sorted by pairs (lexicographic)
    /globals/<name>      arrays identical on all ranks (walls, RNG, insertion)
    /slabs/<name>        (M, ...)  owned slabs at caller-given offsets (FE vectors)

Scaling of the id sort: memory O(N/p) per rank plus p^2 samples; one Alltoallv of the
rows (per array, skipped when every row already is on the rank whose block it belongs to).
Locally, dense ids (span below DENSE_SPAN_FACTOR times their count) are put in order by
their slots in O(n) instead of a comparison sort, and rows are permuted by a scatter
(sequential reads) rather than a gather.  It replaces the simple Allgatherv of all ids (8 N bytes on every rank, which
stops fitting at ~10^8-10^9 particles and costs an O(N log N) sort on every rank).
The MPI counts are in rows (a contiguous datatype per row), so the limit is 2^31 rows
per rank pair, not 2 GB.
"""
from __future__ import annotations

import json
import logging
import os
import secrets
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mpi4py import MPI
from numba import njit

from pdemfem import state_dict as kinds
from pdemfem.errors import CheckpointError
from pdemfem.io import xdmf
from pdemfem.io.output_guard import DIVERGED_SUFFIX, agree_on_error, write_error_text

# 7: a solid's Rayleigh damping work.  6: a solid's prescribed groups' work (support_work and its last half step).  5: the rolling spring's history holds the moment the contact applied at the last evaluation too (6 columns, not
# 3).  4: the tangential history holds the force the contact applied at the last evaluation too (6 columns, not 3:
# the contact records of a version-3 file do not fit).  3: the plane walls' contact history is stored among the
# contact records (partner key -1 - wall), no longer as a per-particle field (a version-2 file read now would
# lose it).  2: the simulation's state
# is stored as its components' state dicts (a JSON manifest maps each dataset and scalar to its
# component path and kind); version 1 named the datasets by field.
FORMAT_VERSION = 7
log = logging.getLogger("pdemfem")
MANIFEST = "state_manifest"
MARKER = "pdemfem_checkpoint"
LATEST = "latest.h5"
PREFIX = "checkpoint_"
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def checkpoint_path(directory, step: int) -> Path:
    """The conventional name: <directory>/checkpoint_<step, 12 digits>.h5 (sorts by step)."""
    return Path(directory) / f"{PREFIX}{int(step):012d}.h5"


# ------------------------------------------------------------ parallel sort


def _as_key(keys) -> np.ndarray:
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    return keys.reshape(len(keys), int(np.prod(keys.shape[1:], dtype=np.int64)))  # (0, k) stays (0, k)


def _lex_order(keys: np.ndarray) -> np.ndarray:
    """Stable order of rows of `keys` (n, k), first column most significant."""
    if keys.shape[1] == 1:
        return np.argsort(keys[:, 0], kind="stable")
    return np.lexsort(keys.T[::-1])


# Ids denser than this (span / count) are ordered by placing each at its slot (O(n), ~10x faster
# than a comparison sort of a million ids); sparser ones take the comparison sort.
DENSE_SPAN_FACTOR = 4


def _key_order(keys: np.ndarray):
    """Stable order of the rows of `keys` (n, k); None when they are in order already (the
    checkpoint's common case after a restart or for FE node numbers)."""
    n = len(keys)
    if n < 2:
        return None
    if keys.shape[1] == 1:
        column = keys[:, 0]
        if np.all(column[1:] >= column[:-1]):
            return None
        low, high = int(column.min()), int(column.max())
        if high - low < DENSE_SPAN_FACTOR * n:
            slots = np.full(high - low + 1, -1, dtype=np.int64)
            slots[column - low] = np.arange(n, dtype=np.int64)
            order = slots[slots >= 0]
            if len(order) == n:  # unique keys: the slots are the order (else fall back: ties stay stable)
                return order
    return _lex_order(keys)


PAGE_BYTES = 4096


def _empty_touched(shape, dtype) -> np.ndarray:
    """np.empty with its pages mapped in address order.  A scatter's writes land in random order,
    and each first write to a fresh page faults: faulting a million-row array's pages in random
    order costs ~10x touching them in order first (measured: 125 ms against 16 ms for 24 MB)."""
    array = np.empty(shape, dtype=dtype)
    if array.size:
        array.reshape(-1).view(np.uint8)[::PAGE_BYTES] = 0
    return array


def _destinations(order):
    """The inverse of a gather order: where each row goes (None stays None: rows in place)."""
    if order is None:
        return None
    destination = _empty_touched(len(order), np.int64)
    destination[order] = np.arange(len(order), dtype=np.int64)
    return destination


@njit(cache=True)
def _scatter_rows(source, destination, out):
    # Reads run in memory order and the writes land scattered: a random read stalls on its cache
    # miss, a random write does not (3-4x faster than np.take's gather for a million rows).
    for row in range(destination.shape[0]):
        target = destination[row]
        for column in range(source.shape[1]):
            out[target, column] = source[row, column]


def _permute_rows(values: np.ndarray, destination) -> np.ndarray:
    """Row k of `values` moved to row destination[k] (a new array; `values` itself for None)."""
    if destination is None:
        return values
    values = np.ascontiguousarray(values)
    permuted = _empty_touched(values.shape, values.dtype)
    count = len(values)
    if count == 0 or values.size == 0:
        return permuted
    row_bytes = values.nbytes // count
    word = np.uint64 if row_bytes % 8 == 0 else np.uint8
    as_words = (lambda array: array.reshape(count, -1).view(np.uint8).reshape(count, row_bytes).view(word))
    _scatter_rows(as_words(values), destination, as_words(permuted))
    return permuted


def _count_less(sorted_keys: np.ndarray, splitter: np.ndarray) -> int:
    """Number of rows (already sorted) lexicographically less than `splitter`."""
    if sorted_keys.shape[1] == 1:
        return int(np.searchsorted(sorted_keys[:, 0], splitter[0], side="left"))
    less = np.zeros(len(sorted_keys), dtype=bool)
    equal = np.ones(len(sorted_keys), dtype=bool)
    for column in range(sorted_keys.shape[1]):
        less |= equal & (sorted_keys[:, column] < splitter[column])
        equal &= sorted_keys[:, column] == splitter[column]
    return int(less.sum())


def _row_type(array: np.ndarray):
    row_bytes = array.dtype.itemsize * int(np.prod(array.shape[1:], dtype=np.int64))
    datatype = MPI.BYTE.Create_contiguous(max(row_bytes, 1)).Commit()
    return datatype, row_bytes


def _exchange_rows(comm, array: np.ndarray, send_counts: np.ndarray, recv_counts: np.ndarray) -> np.ndarray:
    """Alltoallv of the rows of `array` (grouped by destination) with row-sized MPI counts."""
    array = np.ascontiguousarray(array)
    received = np.empty((int(recv_counts.sum()), *array.shape[1:]), dtype=array.dtype)
    datatype, row_bytes = _row_type(array)
    try:
        if row_bytes:
            send_displs = np.concatenate([[0], np.cumsum(send_counts)[:-1]]).astype(np.int32)
            recv_displs = np.concatenate([[0], np.cumsum(recv_counts)[:-1]]).astype(np.int32)
            send = array.reshape(-1).view(np.uint8) if array.size else np.empty(0, np.uint8)
            recv = received.reshape(-1).view(np.uint8) if received.size else np.empty(0, np.uint8)
            comm.Alltoallv([send, (send_counts.astype(np.int32), send_displs), datatype],
                           [recv, (recv_counts.astype(np.int32), recv_displs), datatype])
    finally:
        datatype.Free()
    return received


class SortedRows:
    """This rank's block of a table sorted by int64 `keys` across the ranks (collective).

    Parallel sorting by regular sampling: local sort, p samples per rank, p - 1
    splitters from the gathered samples, one Alltoallv of the rows, local sort.
    Rank r's block precedes rank r+1's, so writing the blocks at prefix-sum offsets
    gives the globally sorted table.  Equal keys stay on one rank.

    The keys are sorted (and exchanged) at construction; each array's rows only when
    `rows(name)` asks for them (collective when comm.size > 1), so a writer can put one
    array on disk while sorting the next and never holds two sorted copies of the table.
    """

    def __init__(self, comm, keys, arrays: dict):
        keys = _as_key(keys)
        self.comm = comm
        self.arrays = arrays
        self.local_destination = _destinations(_key_order(keys))
        keys = _permute_rows(keys, self.local_destination)
        self.received_destination = None
        size = comm.size
        if size == 1:
            self.keys = keys
            return
        n, width = keys.shape
        n_samples = min(n, size)
        samples = keys[(np.arange(n_samples) * n) // max(n_samples, 1)] if n_samples else keys[:0]
        counts = np.zeros(size, dtype=np.int64)
        comm.Allgather(np.array([n_samples * width], dtype=np.int64), counts)
        gathered = np.empty(int(counts.sum()), dtype=np.int64)
        comm.Allgatherv(np.ascontiguousarray(samples).reshape(-1),
                        [gathered, (counts.astype(np.int32),
                                    np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int32)), MPI.INT64_T])
        gathered = gathered.reshape(-1, width)
        gathered = gathered[_lex_order(gathered)]
        if len(gathered):
            splitters = gathered[(np.arange(1, size) * len(gathered)) // size]
            bounds = np.array([0] + [_count_less(keys, s) for s in splitters] + [n], dtype=np.int64)
        else:
            bounds = np.array([0] * size + [n], dtype=np.int64)
        self.send_counts = np.diff(bounds)
        self.recv_counts = np.zeros(size, dtype=np.int64)
        comm.Alltoall(self.send_counts, self.recv_counts)
        # Rows already on the rank whose block they belong to (ids written in rank order) skip the
        # exchange: no rank sends to another (known to all from one small reduction).
        leaving = np.array([n - self.send_counts[comm.rank]], dtype=np.int64)
        comm.Allreduce(MPI.IN_PLACE, leaving, op=MPI.MAX)
        self.exchange = bool(leaving[0])
        if not self.exchange:
            self.keys = keys
            return
        keys = _exchange_rows(comm, keys, self.send_counts, self.recv_counts)
        self.received_destination = _destinations(_key_order(keys))
        self.keys = _permute_rows(keys, self.received_destination)

    def rows(self, name: str) -> np.ndarray:
        """This rank's block of `arrays[name]` in key order (collective when comm.size > 1)."""
        values = _permute_rows(np.asarray(self.arrays[name]), self.local_destination)
        if self.comm.size > 1 and self.exchange:
            values = _exchange_rows(self.comm, values, self.send_counts, self.recv_counts)
            values = _permute_rows(values, self.received_destination)
        return values


def sort_rows_by_key(comm, keys, arrays: dict) -> tuple[np.ndarray, dict]:
    """Globally sort rows by int64 `keys` ((n,) or (n, k), lexicographic); return this rank's block
    (the keys (n, k) and every array's rows; see SortedRows)."""
    table = SortedRows(comm, keys, arrays)
    return table.keys, {name: table.rows(name) for name in arrays}


# ---------------------------------------------------------------- checksums


def _sum64(array: np.ndarray) -> int:
    """Order-independent checksum: the sum (mod 2^64) of the data as unsigned words of the largest size
    (8, 4, 2 or 1 bytes) that divides the item size, so that no word straddles two items and the sum is the
    same however the rows are split over ranks.  (Words of 8 bytes over int32 rows, and bytes where a rank's
    part was not a multiple of 8, gave a sum that depended on the split: a checkpoint written on 2 ranks
    with an odd row count per rank was refused as corrupt on 1 or 3.)"""
    data = np.ascontiguousarray(array)
    word = next(size for size in (8, 4, 2, 1) if data.dtype.itemsize % size == 0)
    return int(data.reshape(-1).view(np.dtype(f"u{word}")).sum(dtype=np.uint64))


# -------------------------------------------------------------------- write


def _json_value(value):
    """numpy scalars and arrays in JSON attributes (a state dict's scalars may be numpy values)."""
    if isinstance(value, (np.generic, np.ndarray)):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def _encode_attributes(attributes: dict) -> tuple[dict, list]:
    encoded, as_json = {}, []
    for name, value in attributes.items():
        if isinstance(value, np.generic):
            value = value.item()
        if isinstance(value, (bool, int, float, str)):
            encoded[name] = value
        else:
            encoded[name] = json.dumps(value, default=_json_value)
            as_json.append(name)
    return encoded, as_json


def _link_latest(path: Path) -> None:
    latest = path.with_name(LATEST)
    temporary = path.with_name(f"{LATEST}.tmp-{secrets.token_hex(4)}")
    try:
        os.link(path, temporary)
    except OSError:
        shutil.copyfile(path, temporary)
    os.replace(temporary, latest)


# Checkpoints written by this process (resolved paths, in order), for callers that pass no list.
_WRITTEN_BY_THIS_PROCESS: list = []


def _prune(path: Path, keep: int, written: list) -> None:
    """Keep `path` and the newest keep-1 other checkpoints among `written` (the paths this run
    wrote, oldest first): a run never deletes checkpoints it did not write (another run's in a
    shared checkpoint.dir, or the one it restarted from)."""
    path = path.resolve()
    mine = [p for p in dict.fromkeys(Path(p).resolve() for p in written) if p != path and p.parent == path.parent]
    for old in mine[: max(len(mine) - (keep - 1), 0)]:
        old.unlink(missing_ok=True)
        written[:] = [p for p in written if Path(p).resolve() != old]


def _fsync(path: Path, directory: bool = False) -> None:
    fd = os.open(path, os.O_RDONLY | (os.O_DIRECTORY if directory else 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_checkpoint(path, comm, particle_arrays: dict, global_arrays: dict | None = None,
                     attributes: dict | None = None, slab_arrays: dict | None = None,
                     contact_arrays: dict | None = None, keep: int | None = None,
                     written: list | None = None, particle_key: str = "ids", contact_key: str = "pairs") -> Path:
    """Write one checkpoint atomically (collective); return its path.

    particle_arrays: this rank's owned rows per field, including int64 ids (unique) named
        `particle_key`.
    contact_arrays: this rank's contacts, including `contact_key` (K, 2) int64 (or any int64
        key columns), stored sorted by them.
    global_arrays: identical on every rank; rank 0's copy is written.
    slab_arrays: name -> (owned_rows, first_global_row); the slabs of all ranks must tile
        0..M-1 (e.g. FE vectors in a rank-count independent node numbering).
    attributes: step, time, scene_hash, rng_state (JSON text), insertion progress, ...;
        str/int/float/bool are stored as HDF5 attributes, anything else as JSON.
        format_version defaults to FORMAT_VERSION.
    keep: if given, point latest.h5 at this file and delete all but the newest `keep` of the
        checkpoints this run wrote in the directory (never another run's).
    written: the list of checkpoint paths this run wrote (updated here; rank 0's copy counts);
        default: the checkpoints written by this process.
    A failed write (disk full, I/O error) raises CheckpointError on every rank and removes the
    temporary file; the checkpoints written before stay intact.
    """
    path = Path(path)
    xdmf.prepare_directory(path.parent, comm)
    token = secrets.token_hex(4) if comm.rank == 0 else None
    token = comm.bcast(token, root=0)
    temporary = path.with_name(f"{path.name}.tmp-{token}")
    if comm.rank == 0:  # leftovers of a run killed while writing
        for stale in path.parent.glob(f"{PREFIX}*.h5.tmp-*"):
            stale.unlink(missing_ok=True)
        for stale in path.parent.glob(f"{LATEST}.tmp-*"):
            stale.unlink(missing_ok=True)
    comm.Barrier()
    attributes = dict(attributes or {})
    attributes.setdefault("format_version", FORMAT_VERSION)
    encoded, as_json = _encode_attributes(attributes)
    try:
        # HDF5 crashed (SIGSEGV) instead of failing when the disk filled while rank 0 laid the file out: a file that
        # cannot fit is refused before it is begun.
        failure = _space_shortage(path.parent, comm, as_json, particle_arrays, global_arrays, slab_arrays,
                                  contact_arrays)
        if failure is None:
            _write_file(temporary, comm, encoded, as_json, particle_arrays, global_arrays, slab_arrays,
                        contact_arrays, particle_key, contact_key)
    except (OSError, RuntimeError) as exc:  # disk full, quota, I/O error (h5py: OSError, some RuntimeError)
        failure = str(exc) if isinstance(exc, _WriteFailed) else write_error_text(exc)
    failure = agree_on_error(comm, failure)
    if failure is not None:
        earlier = None
        if comm.rank == 0:
            temporary.unlink(missing_ok=True)
            earlier = any(path.parent.glob(f"{PREFIX}*.h5"))
        if comm.bcast(earlier, root=0):
            raise CheckpointError(str(path), f"could not write the checkpoint ({failure}); the earlier checkpoints "
                                             f"in {path.parent} are intact",
                                  "free disk space (or choose another checkpoint.dir / -o), then continue from the "
                                  "latest intact checkpoint with --restart")
        raise CheckpointError(str(path), f"could not write the checkpoint ({failure}); it was the run's first, so "
                                         f"there is none to continue from",
                              "free disk space (or choose another checkpoint.dir / -o), then run again")
    error = None
    if comm.rank == 0:
        try:
            _fsync(temporary)
            os.replace(temporary, path)
            _fsync(path.parent, directory=True)
            if keep is not None:
                written = _WRITTEN_BY_THIS_PROCESS if written is None else written
                written.append(path)
                _link_latest(path)
                _prune(path, int(keep), written)
        except OSError as exc:
            error = str(exc)
    error = comm.bcast(error, root=0)
    if error is not None:
        raise CheckpointError(str(path), f"could not install the checkpoint ({error})",
                              "check free space and permissions of checkpoint.dir")
    return path


def _space_shortage(folder: Path, comm, as_json, particle_arrays, global_arrays, slab_arrays,
                    contact_arrays) -> str | None:
    """Collective: None when the checkpoint's data (every rank's arrays, rank 0's global arrays and attributes,
    plus 5 % and 1 MiB for HDF5's own structures) fits in the free space of `folder`, else the reason."""
    local = sum(np.asarray(value).nbytes for value in (particle_arrays or {}).values())
    local += sum(np.asarray(value).nbytes for value in (contact_arrays or {}).values())
    local += sum(np.asarray(rows).nbytes for rows, _ in (slab_arrays or {}).values())
    if comm.rank == 0:
        local += sum(np.asarray(value).nbytes for value in (global_arrays or {}).values()) + len(str(as_json))
    needed = comm.allreduce(int(local)) * 1.05 + (1 << 20)
    free = None
    if comm.rank == 0:
        try:
            status = os.statvfs(folder)
            free = status.f_bavail * status.f_frsize
        except OSError:
            free = None  # unknown: the write itself reports what fails
    free = comm.bcast(free, root=0)
    if free is None or free >= needed:
        return None
    return (f"No space left on device: the checkpoint needs ~{needed / 2**20:.1f} MiB, {free / 2**20:.1f} MiB are "
            f"free in {folder}")


# Largest single pwrite (Linux moves at most 2 GiB - 4 KiB per call).
WRITE_BLOCK_BYTES = 1 << 30


@dataclass
class _Dataset:
    """One dataset of the file: where it goes, and this rank's rows of it."""
    group: str
    name: str
    shape: tuple
    dtype: np.dtype
    first_row: int                   # this rank's first row
    rows: object                     # callable giving this rank's rows (in file order), or None: rank 0 writes
    local_sum: int = 0               # this rank's part of the checksum
    summed: bool = True              # checksum summed over the ranks (False: global arrays, rank 0's)


def _plan_table(comm, group: str, arrays: dict, key_name: str) -> list:
    """The datasets of a particle or contact table: rows sorted by key across the ranks (the keys now,
    each array when it is written)."""
    if not arrays:
        return []
    if key_name not in arrays:
        raise KeyError(f"checkpoint {group}: the arrays must include {key_name!r}")
    table = SortedRows(comm, arrays[key_name], arrays)
    offset, total = xdmf.owned_offset(comm, len(table.keys))
    plan = []
    for name in sorted(arrays):
        values = np.asarray(arrays[name])
        rows = lambda name=name: table.rows(name)  # noqa: E731
        if name == key_name and values.ndim == 1 and values.dtype == np.int64:
            rows = lambda: table.keys.reshape(-1)  # noqa: E731  (the sorted keys are these rows)
        # The checksum is a sum over the rows: the unsorted rows give it as well.
        plan.append(_Dataset(group, name, (total, *values.shape[1:]), values.dtype, offset, rows, _sum64(values)))
    return plan


def _create_layout(temporary, encoded, as_json, ranks, plan, table_counts, global_arrays) -> dict:
    """Rank 0: the file with its attributes, groups, global arrays and every dataset allocated at
    a fixed place (contiguous, allocated at creation, never filled); returns {(group, name): byte
    offset of the dataset's data}, which the ranks then write directly."""
    import h5py

    creation = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
    creation.set_alloc_time(h5py.h5d.ALLOC_TIME_EARLY)
    creation.set_fill_time(h5py.h5d.FILL_TIME_NEVER)
    offsets = {}
    with h5py.File(temporary, "w") as handle:
        handle.attrs[MARKER] = 1
        for name, value in encoded.items():
            handle.attrs[name] = value
        handle.attrs["json_attributes"] = json.dumps(as_json)
        handle.attrs["ranks_at_write"] = ranks
        for group in ("particles", "contacts", "globals", "slabs"):
            handle.create_group(group)
        for group, count in table_counts.items():
            handle[group].attrs["count"] = count
        for entry in plan:
            dataset = handle[entry.group].create_dataset(entry.name, shape=entry.shape, dtype=entry.dtype,
                                                         dcpl=creation)
            dataset.attrs["sum64"] = np.uint64(entry.local_sum)
            if entry.rows is None:
                values = np.ascontiguousarray(global_arrays[entry.name])
                if values.size:
                    dataset[...] = values
            elif int(np.prod(entry.shape)):
                offsets[(entry.group, entry.name)] = int(dataset.id.get_offset())
    return offsets


def _write_at(descriptor: int, offset: int, values: np.ndarray) -> None:
    data = memoryview(np.ascontiguousarray(values)).cast("B")
    done = 0
    while done < len(data):
        done += os.pwrite(descriptor, data[done:done + WRITE_BLOCK_BYTES], offset + done)


def _write_file(temporary, comm, encoded, as_json, particle_arrays, global_arrays, slab_arrays, contact_arrays,
                particle_key, contact_key):
    """Rank 0 lays the file out with HDF5 (metadata, attributes, checksums, global arrays; each
    dataset's storage allocated contiguously at a known offset); then every rank writes its rows of
    every dataset straight into that storage with pwrite and fsyncs them.  The data thus goes to
    the file at the speed of plain writes, without MPI-IO or HDF5 in the data path, and one array
    is sorted while the kernel writes the previous one back."""
    plan = _plan_table(comm, "particles", dict(particle_arrays), particle_key)
    plan += _plan_table(comm, "contacts", dict(contact_arrays or {}), contact_key)
    table_counts = {}
    for entry in plan:
        table_counts[entry.group] = entry.shape[0]
    for name, values in sorted((global_arrays or {}).items()):
        values = np.asarray(values)
        plan.append(_Dataset("globals", name, values.shape, values.dtype, 0, None, _sum64(values), summed=False))
    for name, (values, first) in sorted((slab_arrays or {}).items()):
        values = np.ascontiguousarray(values)
        _, total = xdmf.owned_offset(comm, len(values))
        plan.append(_Dataset("slabs", name, (total, *values.shape[1:]), values.dtype, int(first),
                             lambda values=values: values, _sum64(values)))
    # Every checksum in one reduction (unsigned addition wraps modulo 2^64 alike on every rank).
    sums = np.array([entry.local_sum if entry.summed else 0 for entry in plan], dtype=np.uint64)
    if comm.size > 1 and len(sums):
        comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
    for entry, total in zip(plan, sums):
        if entry.summed:
            entry.local_sum = int(total)
    layout = None
    if comm.rank == 0:
        try:
            layout = _create_layout(temporary, encoded, as_json, comm.size, plan, table_counts, global_arrays or {})
        except Exception as exc:  # any failure on rank 0 alone must reach the ranks waiting in bcast
            layout = write_error_text(exc)
    if comm.size > 1:
        layout = comm.bcast(layout, root=0)
    if isinstance(layout, str):
        raise _WriteFailed(layout)
    failure = None
    try:
        descriptor = os.open(temporary, os.O_WRONLY)
    except OSError as exc:
        descriptor, failure = None, write_error_text(exc)
    for entry in plan:
        if entry.rows is None:
            continue
        # Collective for particle and contact tables on several ranks: a rank whose write failed
        # still takes part (the caller agrees on the failure after).
        values = entry.rows()
        if failure is None and len(values) and (entry.group, entry.name) in layout:
            row_bytes = values.dtype.itemsize * int(np.prod(values.shape[1:], dtype=np.int64))
            try:
                _write_at(descriptor, layout[(entry.group, entry.name)] + entry.first_row * row_bytes, values)
            except OSError as exc:
                failure = write_error_text(exc)
    if descriptor is not None:
        try:
            if failure is None:
                os.fsync(descriptor)  # this rank's rows on disk before rank 0 renames the file
        except OSError as exc:
            failure = write_error_text(exc)
        finally:
            os.close(descriptor)
    if failure is not None:
        raise _WriteFailed(failure)


class _WriteFailed(RuntimeError):
    """A failed checkpoint write, its text already in write_error_text's form."""


# --------------------------------------------------------------------- read


@dataclass
class Checkpoint:
    path: Path
    attributes: dict
    particles: dict = field(default_factory=dict)   # this rank's share of the id-sorted rows
    contacts: dict = field(default_factory=dict)    # this rank's share of the pair-sorted contacts
    globals: dict = field(default_factory=dict)
    slabs: dict = field(default_factory=dict)
    particle_count: int = 0                         # global
    particle_rows: tuple = (0, 0)                   # [first, stop) of this rank's share


def _decode(value):
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.generic):
        return value.item()
    return value


def _even_share(total: int, rank: int, size: int) -> tuple[int, int]:
    return total * rank // size, total * (rank + 1) // size


class _Bad(Exception):
    def __init__(self, problem: str, fix: str):
        super().__init__(problem)
        self.problem, self.fix = problem, fix


OLDER_FIX = "restart from an older checkpoint in the same directory (checkpoint_<step>.h5), or start anew"


def physics_refusal(attrs: dict, expected_hash, force: bool, expected_physics=None):
    """(problem, fix) when the checkpoint's scene hash is not `expected_hash` and not `force`, else None."""
    if expected_hash is None or attrs.get("scene_hash") == expected_hash or force:
        return None
    return (_changed_physics_problem(attrs, expected_hash, expected_physics),
            "restart with the scene that wrote it; if the change is deliberate add --force "
            "(Python: force=True); time.end, output.* and checkpoint.* may change freely")


def _changed_physics_problem(attrs: dict, expected_hash: str, expected_physics) -> str:
    """What changed in the scene (key: old -> new) when the checkpoint stored its scene's physics."""
    from pdemfem.scene.loader import physics_changes

    stored = attrs.get("scene_physics")
    if isinstance(stored, dict) and isinstance(expected_physics, dict):
        changes = physics_changes(stored, expected_physics)
        if changes:
            return ("the scene's physics changed since the checkpoint was written (scene hash mismatch):\n"
                    + "\n".join(f"    {change}" for change in changes))
    return (f"the scene's physics changed since the checkpoint was written (scene hash {attrs.get('scene_hash')}, "
            f"this scene {expected_hash}; the checkpoint does not record which keys)")


def _read_local(path: Path, comm, expected_hash, force: bool, expected_version: int, slab_ranges: dict,
                expected_physics=None):
    import h5py

    if not path.exists():
        raise _Bad("checkpoint file not found",
                   "give the path of an existing checkpoint, e.g. out/checkpoints/latest.h5 "
                   "(checkpoints are written to checkpoint.dir)")
    with open(path, "rb") as handle:
        head = handle.read(8)
    if head != HDF5_SIGNATURE:
        raise _Bad("not an HDF5 file (corrupt, or not a checkpoint)", OLDER_FIX)
    try:
        handle = h5py.File(path, "r")
    except OSError as exc:
        text = str(exc)
        problem = "file is truncated" if "truncated" in text else f"file is corrupt ({text})"
        raise _Bad(problem, OLDER_FIX) from None
    with handle:
        attrs = {name: _decode(value) for name, value in handle.attrs.items()}
        if MARKER not in attrs:
            raise _Bad("an HDF5 file, but not a pdemfem checkpoint", "give a checkpoint_<step>.h5 or latest.h5")
        version = attrs.get("format_version")
        if isinstance(version, int) and version < expected_version:
            raise _Bad(f"written by an older pdemfem (checkpoint format version {version}, this pdemfem reads "
                       f"version {expected_version})",
                       "continue it with the pdemfem version that wrote it, or start the run anew")
        if version != expected_version:
            raise _Bad(f"checkpoint format version {version}, this pdemfem reads version {expected_version}",
                       "restart with the pdemfem version that wrote it, or start the run anew")
        for name in json.loads(attrs.pop("json_attributes", "[]")):
            attrs[name] = json.loads(attrs[name])
        refusal = physics_refusal(attrs, expected_hash, force, expected_physics)
        if refusal is not None:
            raise _Bad(*refusal)
        attrs.pop(MARKER, None)
        result = Checkpoint(path=path, attributes=attrs)
        checks = []  # (dataset path, stored sum, local sum, summed over ranks?)
        for group_name, target in (("particles", result.particles), ("contacts", result.contacts)):
            group = handle[group_name]
            total = int(group.attrs.get("count", 0))
            first, stop = _even_share(total, comm.rank, comm.size)
            if group_name == "particles":
                result.particle_count, result.particle_rows = total, (first, stop)
            for name in sorted(group):
                dataset = group[name]
                target[name] = dataset[first:stop]
                checks.append((dataset.name, int(dataset.attrs["sum64"]), _sum64(target[name]), True))
        for name, dataset in handle["globals"].items():
            result.globals[name] = dataset[()]
            checks.append((dataset.name, int(dataset.attrs["sum64"]), _sum64(result.globals[name]), False))
        for name, dataset in handle["slabs"].items():
            if name in slab_ranges:
                first, stop = slab_ranges[name]
                result.slabs[name] = dataset[first:stop]
            else:
                result.slabs[name] = dataset[()]
                checks.append((dataset.name, int(dataset.attrs["sum64"]), _sum64(result.slabs[name]), False))
    return result, checks


def read_checkpoint(path, comm, expected_hash: str | None = None, force: bool = False,
                    expected_version: int = FORMAT_VERSION, slab_ranges: dict | None = None,
                    expected_physics: dict | None = None) -> Checkpoint:
    """Read a checkpoint for a restart on any number of ranks (collective).

    `path` may be a checkpoint file or its directory (then latest.h5 in it).  Returns the
    attributes, this rank's even share of the id-sorted particles and pair-sorted contacts,
    the global arrays, and the slabs (whole, or rows [first, stop) per name in slab_ranges).
    Raises CheckpointError, on every rank alike, for a missing, truncated, corrupt or
    foreign file, another format version, or a scene hash mismatch (unless force; the message
    lists the changed keys when the file holds its scene's physics and `expected_physics` is given).
    """
    path = Path(path)
    if path.is_dir():
        path = path / LATEST
    slab_ranges = dict(slab_ranges or {})
    result, checks, failure = None, [], None
    try:
        result, checks = _read_local(path, comm, expected_hash, force, expected_version, slab_ranges,
                                     expected_physics)
    except _Bad as bad:
        failure = (bad.problem, bad.fix)
    except OSError as exc:  # HDF5's own errors on reading data: damaged inside
        failure = (f"file is corrupt (HDF5: {exc})", OLDER_FIX)
    except Exception as exc:  # a damaged layout met by h5py or our reader (a missing attribute reads as None)
        log.debug("checkpoint %s: %s", path, exc, exc_info=True)
        failure = ("file is corrupt (its layout is damaged: an attribute or dataset the checkpoint must have "
                   "could not be read)", OLDER_FIX)
    failures = comm.allgather(failure)
    failure = next((f for f in failures if f is not None), None)
    if failure is None:
        # Checksums: the particle/contact shares add up over ranks (uint64 sums wrap alike).
        local = np.array([c[2] if c[3] else 0 for c in checks], dtype=np.uint64)
        comm.Allreduce(MPI.IN_PLACE, local, op=MPI.SUM)
        bad = [c[0] for c, summed in zip(checks, local)
               if (int(summed) if c[3] else c[2]) != c[1]]
        bad_everywhere = comm.allgather(bad)
        bad = sorted({name for names in bad_everywhere for name in names})
        if bad:
            failure = (f"file is corrupt (checksum mismatch in {', '.join(bad)})", OLDER_FIX)
    if failure is not None:
        raise CheckpointError(str(path), failure[0], failure[1])
    return result


# ------------------------------------------------------------ state dicts

_GROUP_OF_KIND = {kinds.PARTICLE_ROWS: "particles", kinds.PARTICLE_IDS: "particles", kinds.CONTACT_ROWS: "contacts",
                  kinds.CONTACT_KEYS: "contacts", kinds.GLOBAL: "globals", kinds.SLAB: "slabs"}
_PATH_SEPARATOR = "|"


def write_state(path, comm, state: dict, attributes: dict | None = None, keep: int | None = None,
                written: list | None = None) -> Path:
    """Write a nested state dict of Entry leaves (pdemfem.state_dict) as one checkpoint (collective).

    Each array entry goes to the group its kind names (particle rows sorted by the PARTICLE_IDS
    entry, contact rows by the CONTACT_KEYS entry, global arrays, slabs) under the name of its
    path; scalars and the path and kind of every entry go to the JSON attribute `state_manifest`,
    so read_state gives the same nesting back without knowing the components."""
    tables = {group: {} for group in ("particles", "contacts", "globals", "slabs")}
    keys = {kinds.PARTICLE_IDS: None, kinds.CONTACT_KEYS: None}
    manifest = []
    for entry_path, entry in kinds.flatten(state):
        name = _PATH_SEPARATOR.join(entry_path)
        record = {"path": list(entry_path), "kind": entry.kind}
        if entry.kind == kinds.SCALAR:
            record["value"] = entry.value
        else:
            group = _GROUP_OF_KIND[entry.kind]
            if name in tables[group]:
                raise ValueError(f"checkpoint state: two entries are named {name!r}")
            tables[group][name] = (_slab_rows(comm, name, entry) if entry.kind == kinds.SLAB
                                   else np.ascontiguousarray(entry.value))
            if entry.kind in keys:
                if keys[entry.kind] is not None:
                    raise ValueError(f"checkpoint state: more than one {entry.kind} entry "
                                     f"({keys[entry.kind]!r}, {name!r})")
                keys[entry.kind] = name
        manifest.append(record)
    for key_kind, group in ((kinds.PARTICLE_IDS, "particles"), (kinds.CONTACT_KEYS, "contacts")):
        if tables[group] and keys[key_kind] is None:
            raise ValueError(f"checkpoint state: {group} rows without a {key_kind} entry to sort them by")
    attributes = dict(attributes or {})
    attributes[MANIFEST] = manifest
    return write_checkpoint(path, comm, particle_arrays=tables["particles"], global_arrays=tables["globals"],
                            attributes=attributes, slab_arrays=tables["slabs"], contact_arrays=tables["contacts"],
                            keep=keep, written=written, particle_key=keys[kinds.PARTICLE_IDS] or "ids",
                            contact_key=keys[kinds.CONTACT_KEYS] or "pairs")


def _slab_rows(comm, name: str, entry) -> tuple:
    """(rows, first row) of a SLAB entry: rows given with their global row numbers are sorted by them
    across ranks first (collective), so each rank writes one contiguous block."""
    if entry.keys is None:
        return np.ascontiguousarray(entry.value), int(entry.first)
    keys, rows = sort_rows_by_key(comm, entry.keys, {"rows": entry.value})
    keys = keys[:, 0]
    first = int(keys[0]) if len(keys) else 0
    if len(keys) and int(keys[-1]) - first + 1 != len(keys):
        raise ValueError(f"checkpoint state {name!r}: the global row numbers are not contiguous")
    return rows["rows"], first


def read_state(path, comm, expected_hash: str | None = None, force: bool = False,
               expected_physics: dict | None = None) -> tuple[Checkpoint, dict]:
    """Read a checkpoint written by write_state (collective): (Checkpoint, nested state of plain values).

    Particle and contact entries hold this rank's even share of the sorted rows, global arrays,
    slabs and scalars the whole value (read_checkpoint's errors apply)."""
    checkpoint = read_checkpoint(path, comm, expected_hash=expected_hash, force=force,
                                 expected_physics=expected_physics)
    manifest = checkpoint.attributes.pop(MANIFEST, None)
    if not isinstance(manifest, list):
        raise CheckpointError(str(checkpoint.path), "holds no simulation state (no state manifest): written by "
                                                    "write_checkpoint directly, not by a simulation",
                              "give a checkpoint a simulation wrote (checkpoint.dir, default <output>/checkpoints)")
    sources = {"particles": checkpoint.particles, "contacts": checkpoint.contacts, "globals": checkpoint.globals,
               "slabs": checkpoint.slabs}
    leaves = []
    for record in manifest:
        entry_path = tuple(record["path"])
        if record["kind"] == kinds.SCALAR:
            leaves.append((entry_path, record["value"]))
            continue
        group = sources[_GROUP_OF_KIND[record["kind"]]]
        name = _PATH_SEPARATOR.join(entry_path)
        if name not in group:
            raise CheckpointError(str(checkpoint.path), f"file is corrupt (the state manifest names {name!r}, the "
                                                        f"file lacks it)", OLDER_FIX)
        leaves.append((entry_path, group[name]))
    return checkpoint, kinds.nest(leaves)
