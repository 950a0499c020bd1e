"""Checkpoints: round trip on any rank count, atomic install, clear errors, stop signals.

MPI cases: tests/mpi_cases/io_checkpoint.py (write/read/loop) and io_stop.py (signals).
Error cases run in this process on MPI.COMM_SELF.
"""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from mpi_harness import CASES, run_under_mpi
from pdemfem.errors import CheckpointError
from pdemfem.io.checkpoint import (FORMAT_VERSION, LATEST, checkpoint_path, read_checkpoint,
                                   sort_rows_by_key, write_checkpoint)
from pdemfem.io.signals import StopRequest
from pdemfem.runtime import mpiexec_command, process_environment

N = 1000


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """Checkpoints of steps 5, 10, 15 (keep=2) written on 1, 2 and 3 ranks."""
    root = tmp_path_factory.mktemp("checkpoints")
    for ranks in (1, 2, 3):
        run_under_mpi(ranks, "io_checkpoint.py", "write", root / f"w{ranks}", N, 5, 10, 15)
    return root


@pytest.mark.mpi
@pytest.mark.parametrize("write_ranks,read_ranks", [(3, 1), (3, 2), (3, 3), (1, 3), (2, 2)])
def test_round_trip_on_any_rank_count(written, write_ranks, read_ranks):
    completed = run_under_mpi(read_ranks, "io_checkpoint.py", "read", written / f"w{write_ranks}" / LATEST, N, 15)
    assert f"OK {read_ranks}" in completed.stdout


@pytest.mark.mpi
def test_particle_tables_identical_for_any_writer_rank_count(written):
    tables = []
    for ranks in (1, 2, 3):
        with h5py.File(written / f"w{ranks}" / LATEST, "r") as handle:
            tables.append({f"{g}/{n}": handle[g][n][()] for g in ("particles", "contacts", "slabs", "globals")
                           for n in handle[g]})
    for other in tables[1:]:
        assert other.keys() == tables[0].keys()
        for name in tables[0]:
            assert np.array_equal(other[name], tables[0][name]), name
    assert np.array_equal(tables[0]["particles/ids"], np.arange(N))


@pytest.mark.mpi
def test_keep_and_latest(written):
    directory = written / "w2"
    names = sorted(p.name for p in directory.iterdir())
    assert names == ["checkpoint_000000000010.h5", "checkpoint_000000000015.h5", LATEST]
    assert os.path.samefile(directory / LATEST, checkpoint_path(directory, 15))
    # a directory stands for its latest.h5
    assert read_checkpoint(directory, MPI.COMM_SELF).attributes["step"] == 15


# ------------------------------------------------------------------ errors
def small_checkpoint(path: Path, **attributes) -> Path:
    attrs = {"step": 3, "time": 0.5, "scene_hash": "good"}
    attrs.update(attributes)
    rng = np.random.default_rng(0)
    return write_checkpoint(path, MPI.COMM_SELF, {"ids": rng.permutation(200), "positions": rng.random((200, 3))},
                            global_arrays={"walls": np.arange(6.0)}, attributes=attrs)


def problem_of(path, **keywords) -> CheckpointError:
    with pytest.raises(CheckpointError) as info:
        read_checkpoint(path, MPI.COMM_SELF, **keywords)
    assert info.value.where == str(path)
    assert info.value.fix
    return info.value


def test_serial_round_trip_sorts_by_id(tmp_path):
    path = small_checkpoint(tmp_path / "c.h5")
    checkpoint = read_checkpoint(path, MPI.COMM_SELF, expected_hash="good")
    assert np.array_equal(checkpoint.particles["ids"], np.arange(200))
    rng = np.random.default_rng(0)
    ids, positions = rng.permutation(200), rng.random((200, 3))
    assert np.array_equal(checkpoint.particles["positions"], positions[np.argsort(ids)])
    assert checkpoint.attributes["format_version"] == FORMAT_VERSION and checkpoint.attributes["time"] == 0.5
    assert np.array_equal(checkpoint.globals["walls"], np.arange(6.0))


def test_missing_file(tmp_path):
    assert "not found" in problem_of(tmp_path / "nope.h5").problem


def test_garbage_file(tmp_path):
    path = tmp_path / "garbage.h5"
    path.write_bytes(os.urandom(4096))
    assert "not an HDF5 file" in problem_of(path).problem


def test_truncated_file(tmp_path):
    path = small_checkpoint(tmp_path / "c.h5")
    size = path.stat().st_size
    with open(path, "r+b") as handle:
        handle.truncate(size // 2)
    assert "truncated" in problem_of(path).problem


def test_flipped_data_byte_fails_checksum(tmp_path):
    path = small_checkpoint(tmp_path / "c.h5")
    with h5py.File(path, "r") as handle:
        offset = handle["particles/positions"].id.get_offset()
    with open(path, "r+b") as handle:
        handle.seek(offset + 100)
        byte = handle.read(1)
        handle.seek(offset + 100)
        handle.write(bytes([byte[0] ^ 0x10]))
    problem = problem_of(path).problem
    assert "checksum" in problem and "/particles/positions" in problem


@pytest.mark.parametrize("dtype", [np.int32, np.int16, np.uint8, np.float64, np.complex128])
def test_checksum_does_not_depend_on_the_split_of_the_rows(dtype):
    """The ranks' checksums of their rows add up (mod 2^64) to the checksum of all rows for any split: the
    reader's ranks split the rows otherwise than the writer's.  Exact integer arithmetic, no tolerance."""
    from pdemfem.io.checkpoint import _sum64

    values = (np.arange(3 * 751) * 2654435761 % 65521).reshape(751, 3).astype(dtype)
    whole = _sum64(values)
    for cuts in ([375], [1, 250, 501], [3, 7, 749]):
        parts = np.split(values, cuts)
        assert sum(_sum64(part) for part in parts) % 2**64 == whole, cuts


def test_not_a_checkpoint(tmp_path):
    path = tmp_path / "other.h5"
    with h5py.File(path, "w") as handle:
        handle["x"] = np.arange(3)
    assert "not a pdemfem checkpoint" in problem_of(path).problem


def test_other_format_version(tmp_path):
    path = small_checkpoint(tmp_path / "c.h5", format_version=FORMAT_VERSION + 1)
    assert "format version" in problem_of(path).problem


def test_scene_hash_mismatch_and_force(tmp_path):
    path = small_checkpoint(tmp_path / "c.h5")
    error = problem_of(path, expected_hash="changed")
    assert "scene" in error.problem and "--force" in error.fix
    assert read_checkpoint(path, MPI.COMM_SELF, expected_hash="changed", force=True).attributes["step"] == 3


def test_sort_rows_serial_lexicographic():
    keys = np.array([[2, 1], [1, 5], [2, 0], [1, 2]])
    sorted_keys, rows = sort_rows_by_key(MPI.COMM_SELF, keys, {"v": np.arange(4)})
    assert sorted_keys.tolist() == [[1, 2], [1, 5], [2, 0], [2, 1]]
    assert rows["v"].tolist() == [3, 1, 2, 0]


# ---------------------------------------------------------- killed writes
def test_sigkill_during_write_leaves_previous_checkpoint(tmp_path):
    """A writer killed (SIGKILL) in the middle of a large checkpoint: the previous ones stay valid."""
    count = 600_000  # ~45 MB per checkpoint: a write takes long enough to be caught mid-way
    process = subprocess.Popen([sys.executable, str(CASES / "io_checkpoint.py"), "loop", str(tmp_path), str(count)],
                               env=process_environment(), stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120.0
        killed_mid_write = False
        while time.monotonic() < deadline and process.poll() is None:
            installed = list(tmp_path.glob("checkpoint_*.h5"))
            partial = [p for p in tmp_path.glob("checkpoint_*.h5.tmp-*") if p.exists() and p.stat().st_size > 1 << 20]
            if installed and partial:
                os.kill(process.pid, signal.SIGKILL)
                killed_mid_write = True
                break
            time.sleep(0.005)
        assert killed_mid_write, process.communicate(timeout=5) if process.poll() is not None else "no write seen"
        process.wait(timeout=10)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert list(tmp_path.glob("*.tmp-*")), "expected the killed write's temporary file"
    latest = read_checkpoint(tmp_path / LATEST, MPI.COMM_SELF, expected_hash="abc123")
    step = latest.attributes["step"]
    assert latest.particle_count == count
    assert np.array_equal(latest.particles["ids"], np.arange(count))
    assert latest.globals["insertion_counts"].tolist() == [step, 2 * step]
    for path in tmp_path.glob("checkpoint_*.h5"):
        read_checkpoint(path, MPI.COMM_SELF, expected_hash="abc123")
    # the next write clears the stale temporary file
    small_checkpoint(checkpoint_path(tmp_path, step + 1))
    assert not list(tmp_path.glob("*.tmp-*"))


# ----------------------------------------------------------------- signals
def test_stop_request_flag_in_process():
    previous = signal.getsignal(signal.SIGUSR1)
    stop = StopRequest(signals=(signal.SIGUSR1,))
    try:
        assert not stop.should_stop(MPI.COMM_SELF)
        os.kill(os.getpid(), signal.SIGUSR1)
        time.sleep(0.01)
        assert stop.should_stop(MPI.COMM_SELF) and stop.signal_name == "SIGUSR1"
    finally:
        stop.restore()
    assert signal.getsignal(signal.SIGUSR1) == (previous if previous is not None else signal.SIG_DFL)


def run_stop_case(tmp_path, ranks: int, deliver):
    command = mpiexec_command(ranks, [sys.executable, str(CASES / "io_stop.py"), str(tmp_path)])
    process = subprocess.Popen(command, env=process_environment(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    try:
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline and len(list(tmp_path.glob("pid.[0-9]"))) < ranks:
            time.sleep(0.05)
        pids = [int((tmp_path / f"pid.{r}").read_text()) for r in range(ranks)]
        time.sleep(0.2)
        deliver(process, pids)
        stdout, stderr = process.communicate(timeout=90)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == 0, stderr
    stopped = [(tmp_path / f"stopped.{r}").read_text().split() for r in range(ranks)]
    steps = {int(s[0]) for s in stopped}
    assert len(steps) == 1, f"ranks stopped at different steps: {stopped}"
    step = steps.pop()
    assert read_checkpoint(tmp_path / LATEST, MPI.COMM_SELF).attributes["step"] == step
    return stopped


@pytest.mark.mpi
def test_sigterm_to_one_rank_stops_all_ranks_together(tmp_path):
    stopped = run_stop_case(tmp_path, 3, lambda process, pids: os.kill(pids[1], signal.SIGTERM))
    assert [s[1] for s in stopped] == ["-", "SIGTERM", "-"]


@pytest.mark.mpi
def test_sigusr1_to_mpiexec_is_forwarded(tmp_path):
    if shutil.which("mpiexec") is None:
        pytest.skip("no mpiexec")
    stopped = run_stop_case(tmp_path, 2, lambda process, pids: os.kill(process.pid, signal.SIGUSR1))
    assert all(s[1] == "SIGUSR1" for s in stopped)


@pytest.mark.mpi
@pytest.mark.parametrize("where", ["layout", "rows"])
def test_a_write_failing_on_one_rank_fails_on_every_rank(tmp_path, where):
    """Rank 0 alone lays the file out, and each rank writes its own rows: a failure there (disk
    full) must reach the ranks still waiting for the layout or still sorting (else they hang), and
    leave the previous checkpoint intact and no temporary file."""
    completed = run_under_mpi(2, "io_checkpoint_failure.py", tmp_path, where, timeout=120)
    lines = completed.stdout.splitlines()
    for rank in (0, 1):
        assert any(line.startswith(f"rank {rank}: could not write the checkpoint (No space left on device")
                   for line in lines), completed.stdout
    assert f"files: {checkpoint_path(tmp_path, 1).name}" in lines, completed.stdout
    assert "previous checkpoint readable: 200 particles" in lines, completed.stdout


def test_a_damaged_layout_is_named_without_python_internals(tmp_path):
    """A checkpoint whose structure lost a piece (here a dataset's checksum attribute; a tester's flipped bytes
    near the end of a file met an attribute read as None) was 'file is corrupt (TypeError: 'NoneType' object
    is not subscriptable)': the right outcome, with Python's words for it."""
    path = small_checkpoint(tmp_path / "c.h5")
    with h5py.File(path, "r+") as handle:
        del handle["particles/positions"].attrs["sum64"]
    error = problem_of(path)
    assert "file is corrupt" in error.problem, error.problem
    assert "Error" not in error.problem and "NoneType" not in error.problem, error.problem
