"""Stopping a run: SIGTERM writes a final checkpoint and exits 0; SIGKILL at any moment
leaves the newest complete checkpoint usable.  Both through the real `pdemfem run` command."""
from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).parent / "mpi_cases"))

import restart_scenes  # noqa: E402
from pdemfem.runtime import process_environment  # noqa: E402

LONG = 20000  # steps: minutes of work, never reached


def start(folder: Path, steps: int, checkpoint_steps=None, restart=None):
    scene = restart_scenes.pile_scene("out", steps, 25, checkpoint_steps)
    path = folder / "scene.yaml"
    path.write_text(yaml.safe_dump(scene))
    command = [sys.executable, "-m", "pdemfem.cli", "run", str(path), "--quiet"]
    if restart is not None:
        command += ["--restart", str(restart)]
    return subprocess.Popen(command, env=process_environment(), cwd=folder, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def wait_for(condition, process, timeout=60.0):
    deadline = time.monotonic() + timeout
    while not condition():
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.05)


def history_rows(folder: Path) -> int:
    path = folder / "out" / "history.csv"
    return path.read_text().count("\n") - 1 if path.exists() else 0


def continue_briefly(folder: Path, checkpoint: Path) -> None:
    with h5py.File(checkpoint, "r") as handle:
        step = int(handle.attrs["step"])
    process = start(folder, step + 25, restart=checkpoint)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 0, stderr
    history = np.genfromtxt(folder / "out" / "history.csv", delimiter=",", names=True)
    assert history["step"][-1] == step + 25 and np.all(np.diff(history["step"]) > 0)


def test_sigterm_writes_a_final_checkpoint_and_exits_cleanly(tmp_path):
    process = start(tmp_path, LONG)
    wait_for(lambda: history_rows(tmp_path) >= 3, process)
    process.send_signal(signal.SIGTERM)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 0, stderr
    assert "SIGTERM: stopped at step" in stderr and "--restart" in stderr
    latest = tmp_path / "out" / "checkpoints" / "latest.h5"
    with h5py.File(latest, "r") as handle:
        step = int(handle.attrs["step"])
    assert 0 < step < LONG and step % 100 == 0  # stops at a collective stop check
    continue_briefly(tmp_path, latest)


def test_sigkill_leaves_the_previous_checkpoint_usable(tmp_path):
    process = start(tmp_path, LONG, checkpoint_steps=5)  # a checkpoint (~60 kB) every 5 steps
    directory = tmp_path / "out" / "checkpoints"
    wait_for(lambda: len(list(directory.glob("checkpoint_*.h5"))) >= 3, process)
    time.sleep(0.37)
    process.kill()
    process.communicate(timeout=30)
    continue_briefly(tmp_path, directory / "latest.h5")
