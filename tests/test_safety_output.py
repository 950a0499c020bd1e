"""Nothing lost: an earlier run's results and checkpoints are never overwritten or mixed silently,
unusable output locations and failed writes are one clear exit-2 error, restarts say what is wrong.
"""
from __future__ import annotations

import errno
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from pdemfem import cli
from pdemfem.errors import CheckpointError, OutputError
from pdemfem.io import checkpoint as ckpt
from test_cli import SCENE as CLI_SCENE

# The command-line tests' scene (20 grains on a floor), checkpointing every output step.
SCENE = CLI_SCENE + "checkpoint: {every: 0.001, keep: 2}\n"


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "scene.yaml").write_text(SCENE)
    return tmp_path


def run_main(capsys, *argv):
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def snapshot(folder: Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_second_run_into_the_same_directory_is_refused(workdir, capsys):
    # Before: the second run overwrote history.csv, particles.h5 and the checkpoints, exit 0.
    assert run_main(capsys, "run", "scene.yaml", "--quiet")[0] == 0
    before = snapshot(workdir / "results")
    (workdir / "results" / "checkpoints").rename(workdir / "elsewhere")  # results only: --force applies
    before = snapshot(workdir / "results")
    code, _, err = run_main(capsys, "run", "scene.yaml", "--quiet")
    assert code == 2, err
    assert "holds the results of an earlier run (history.csv" in err and "--force" in err and "--restart" in err
    assert "Traceback" not in err
    assert snapshot(workdir / "results") == before


def test_a_data_file_without_its_index_is_not_overwritten(workdir, capsys):
    """An earlier run's particles.h5 or <solid>.h5 whose .xdmf was moved or deleted is still its results (it was
    replaced silently, exit 0); --force deletes it like the rest."""
    results = workdir / "results"
    results.mkdir()
    (results / "particles.h5").write_bytes(b"an earlier run's particles")
    code, _, err = run_main(capsys, "run", "scene.yaml", "--quiet")
    assert code == 2 and "holds the results of an earlier run (particles.h5)" in err, err
    assert (results / "particles.h5").read_bytes() == b"an earlier run's particles"
    code, _, err = run_main(capsys, "run", "scene.yaml", "--quiet", "--force")
    assert code == 0, err
    assert (results / "particles.h5").read_bytes() != b"an earlier run's particles"


def test_force_starts_afresh_without_mixing(workdir, capsys):
    results = workdir / "results"
    results.mkdir()
    (results / "history.csv").write_text("an earlier run's history\n")
    (results / "beam.xdmf").write_text("<Xdmf/>")       # a solid of the earlier scene, gone from this one
    (results / "beam.h5").write_bytes(b"old")
    (results / "notes.txt").write_text("the user's own file")
    code, _, err = run_main(capsys, "run", "scene.yaml", "--quiet", "--force")
    assert code == 0, err
    assert not (results / "beam.xdmf").exists() and not (results / "beam.h5").exists()
    assert (results / "history.csv").read_text().startswith("time,step,")
    assert (results / "notes.txt").read_text() == "the user's own file"


def test_force_never_deletes_checkpoints_it_did_not_write(workdir, capsys):
    assert run_main(capsys, "run", "scene.yaml", "--quiet")[0] == 0
    checkpoints = snapshot(workdir / "results" / "checkpoints")
    assert any(name.startswith("checkpoint_") for name in checkpoints)
    code, _, err = run_main(capsys, "run", "scene.yaml", "--quiet", "--force")
    assert code == 2, err
    assert "holds checkpoints of an earlier run" in err and "rm -r" in err
    assert snapshot(workdir / "results" / "checkpoints") == checkpoints


def test_restart_may_continue_in_the_directory(workdir, capsys):
    assert run_main(capsys, "run", "scene.yaml", "--quiet")[0] == 0
    (workdir / "longer.yaml").write_text(SCENE.replace("end: 0.002", "end: 0.003"))
    code, _, err = run_main(capsys, "run", "longer.yaml", "-o", "results", "--quiet", "--restart", "results/checkpoints")
    assert code == 0, err


def test_python_api_refuses_unless_force(workdir):
    from pdemfem.simulation import Simulation

    scene = workdir / "scene.yaml"
    Simulation.from_file(scene, output_dir=workdir / "api").run(progress=False)
    first_rows = (workdir / "api" / "history.csv").read_text().count("\n")
    assert first_rows >= 4  # header + t = 0, 1, 2 ms (+ the end's row when 2 ms is not a whole output interval)
    (workdir / "api" / "checkpoints").rename(workdir / "api_checkpoints")
    with pytest.raises(OutputError, match="holds the results of an earlier run"):
        Simulation.from_file(scene, output_dir=workdir / "api").run(progress=False)
    Simulation.from_file(scene, output_dir=workdir / "api", force=True).run(progress=False)
    # Started afresh: the same rows as the first run, none of its rows left over.
    assert (workdir / "api" / "history.csv").read_text().count("\n") == first_rows


def test_pruning_keeps_checkpoints_of_other_runs(tmp_path):
    # Before: keep=2 deleted every other checkpoint_*.h5 in the directory, a foreign one included.
    foreign = ckpt.checkpoint_path(tmp_path, 1)
    foreign.write_bytes(b"another run's checkpoint")
    written = []
    for step in (2, 3, 4):
        ckpt.write_checkpoint(ckpt.checkpoint_path(tmp_path, step), MPI.COMM_WORLD,
                              particle_arrays={"ids": np.arange(3, dtype=np.int64)}, attributes={"step": step},
                              keep=2, written=written)
    names = sorted(p.name for p in tmp_path.glob("checkpoint_*.h5"))
    assert names == [foreign.name, ckpt.checkpoint_path(tmp_path, 3).name, ckpt.checkpoint_path(tmp_path, 4).name]
    assert foreign.read_bytes() == b"another run's checkpoint"


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs /proc (a directory nobody can write, even root)")
@pytest.mark.parametrize("where", ["output", "checkpoint"])
def test_non_writable_directory_is_one_clear_error(workdir, capsys, where):
    # Before: a FileNotFoundError traceback from history.csv, or an h5py traceback from the first
    # checkpoint after the run had computed up to it.
    if where == "output":
        argv = ["run", "scene.yaml", "--quiet", "-o", "/proc/self"]
        expected = "the output directory (output.dir / -o) is not writable"
    else:
        (workdir / "scene.yaml").write_text(SCENE.replace("keep: 2}", "keep: 2, dir: /proc/self/pdemfem}"))
        argv = ["run", "scene.yaml", "--quiet"]
        expected = "the checkpoint directory (checkpoint.dir) is not writable"
    code, _, err = run_main(capsys, *argv)
    assert code == 2, err
    assert expected in err and "Traceback" not in err


def test_disk_full_during_a_checkpoint_keeps_the_older_ones(workdir, capsys, monkeypatch):
    # ENOSPC simulated in the HDF5 writer from the second checkpoint on.  Before: an OSError
    # traceback (exit 1) and a stale temporary file.
    from pdemfem.io import xdmf

    calls = {"checkpoints": 0, "written": []}
    original_write = ckpt._write_file

    def full_disk(temporary, *args, **kwargs):
        calls["checkpoints"] += 1
        calls["written"].append(Path(temporary).name)
        if calls["checkpoints"] >= 2:
            with open(temporary, "wb") as handle:  # a partly written file, as a full disk leaves it
                handle.write(b"partial")
            raise OSError(errno.ENOSPC, "No space left on device", str(temporary))
        return original_write(temporary, *args, **kwargs)

    monkeypatch.setattr(ckpt, "_write_file", full_disk)
    code, _, err = run_main(capsys, "run", "scene.yaml", "--quiet")
    assert code == 2, err
    assert "could not write the checkpoint (No space left on device" in err and "intact" in err
    assert "Traceback" not in err
    directory = workdir / "results" / "checkpoints"
    # The first checkpoint (its step follows from the scene's dt) is the one left, whole.
    first = sorted(p.name for p in directory.iterdir() if p.name.startswith("checkpoint_"))
    assert len(first) == 1 and first[0][:len("checkpoint_000000000000")] in calls["written"][0], (first, calls)
    assert sorted(p.name for p in directory.iterdir()) == [first[0], "latest.h5"]
    step = int(first[0][len("checkpoint_"):-len(".h5")])
    checkpoint = ckpt.read_checkpoint(directory / "latest.h5", MPI.COMM_WORLD)  # whole: checksums verified
    assert checkpoint.attributes["step"] == step
    assert xdmf  # the series writer is untouched


def test_a_checkpoint_that_cannot_fit_is_refused_before_it_is_begun(workdir, capsys, monkeypatch):
    """HDF5 crashed (SIGSEGV, exit 59 under PETSc's handler, a .tmp file left) when a real disk filled while rank 0
    laid the checkpoint out: a checkpoint larger than the free space is refused before its file is created."""
    import os

    real_statvfs = os.statvfs
    checkpoints = workdir / "results" / "checkpoints"

    def nearly_full(path):
        status = real_statvfs(path)
        if Path(path).resolve() == checkpoints.resolve() and any(checkpoints.glob("checkpoint_*.h5")):
            return os.statvfs_result((status.f_bsize, status.f_frsize, status.f_blocks, 10, 10, status.f_files,
                                      status.f_ffree, status.f_favail, status.f_flag, status.f_namemax))
        return status

    monkeypatch.setattr(os, "statvfs", nearly_full)
    code, _, err = run_main(capsys, "run", "scene.yaml", "--quiet")
    assert code == 2 and "could not write the checkpoint (No space left on device: the checkpoint needs" in err, err
    assert "Traceback" not in err
    left = sorted(p.name for p in checkpoints.iterdir())
    assert len(left) == 2 and left[1] == "latest.h5" and not any(".tmp" in name for name in left), left
    ckpt.read_checkpoint(checkpoints / "latest.h5", MPI.COMM_WORLD)  # the first one, whole


@pytest.mark.parametrize("failing_row", [2, 3])
def test_disk_full_during_output_is_a_clean_error(workdir, capsys, monkeypatch, failing_row):
    """Rows at t = 0, 0.001 and 0.002 s, a checkpoint after the row at 0.001 s: the second row fails before any
    checkpoint (the message said "continue from the latest checkpoint" all the same), the third after one."""
    from pdemfem.io.history import HistoryWriter

    rows = {"count": 0}
    original = HistoryWriter.write

    def full_disk(self, values):
        rows["count"] += 1
        if rows["count"] == failing_row:
            raise OSError(errno.ENOSPC, "No space left on device")
        return original(self, values)

    monkeypatch.setattr(HistoryWriter, "write", full_disk)
    code, _, err = run_main(capsys, "run", "scene.yaml", "--quiet")
    assert code == 2, err
    assert "history.csv: cannot write the output (No space left on device) at step" in err
    assert "Traceback" not in err
    if failing_row == 2:
        assert "the run wrote no checkpoint before the failure" in err and "--restart" not in err, err
    else:
        assert "continue from the last checkpoint" in err and "checkpoint_" in err, err


def test_restart_past_time_end_says_so(workdir, capsys):
    # Before: exit 0 without a step run and without a word.
    assert run_main(capsys, "run", "scene.yaml", "--quiet")[0] == 0
    (workdir / "shorter.yaml").write_text(SCENE.replace("end: 0.002", "end: 0.001"))
    code, _, err = run_main(capsys, "run", "shorter.yaml", "-o", "results", "--quiet", "--restart", "results/checkpoints")
    assert code == 2, err
    assert "at or past time.end = 0.001 s" in err and "nothing left to run" in err and "raise time.end" in err


def test_hash_mismatch_names_the_changed_keys(workdir, capsys):
    assert run_main(capsys, "run", "scene.yaml", "--quiet")[0] == 0
    changed = SCENE.replace("poisson_ratio: 0.3", "poisson_ratio: 0.25").replace("end: 0.002", "end: 0.003")
    (workdir / "changed.yaml").write_text(changed)
    code, _, err = run_main(capsys, "run", "changed.yaml", "-o", "results", "--quiet", "--restart", "results/checkpoints")
    assert code == 2, err
    assert "materials.glass.poisson_ratio: 0.3 -> 0.25" in err
    assert "time.end" not in err.split("fix:")[0]  # time.end is not physics: not listed as a change


def test_checkpoint_error_type_for_restart_errors(workdir):
    from pdemfem.simulation import Simulation

    Simulation.from_file(workdir / "scene.yaml").run(progress=False)
    (workdir / "shorter.yaml").write_text(SCENE.replace("end: 0.002", "end: 0.001"))
    with pytest.raises(CheckpointError, match="nothing left to run"):
        Simulation.from_file(workdir / "shorter.yaml", restart=workdir / "results" / "checkpoints")
