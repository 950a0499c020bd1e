"""The run monitor's diagnosis of a divergence (pdemfem.monitor.likely_causes) names the limit `check` warned
about, also when the diverged run's own speeds are no longer finite."""
from __future__ import annotations

import math

from pdemfem.monitor import likely_causes
from pdemfem.scene.loader import load_scene


def _grains_dict(heated=False, capacity=1e-15, **changes):
    scene = {"time": {"end": 0.05, "dt": "auto"}, "gravity": [0, 0, -9.81],
             "materials": {"glass": {"density": 2500, "youngs_modulus": 5.0e6, "poisson_ratio": 0.3}},
             "interactions": {"default": {"model": "hertz_mindlin", "restitution": 0.5, "friction": 0.5}},
             "particles": [{"name": "grains", "material": "glass", "radius": 0.001,
                            "insert": {"kind": "lattice", "region": {"box": [[0, 0, 0.001], [0.02, 0.02, 0.02]]},
                                       "count": 200}}],
             "walls": [{"name": "floor", "kind": "plane", "point": [0, 0, 0], "normal": [0, 0, 1],
                        "material": "glass"}]}
    if heated:
        scene["materials"]["glass"].update(conductivity=1.0, heat_capacity=capacity)
        scene["walls"][0]["temperature"] = 500.0
    scene.update(changes)
    return scene


def _grains(heated=False, **changes):
    return load_scene(_grains_dict(heated, **changes))[0]


def test_overlaps_at_the_expected_speed_are_named_when_the_run_has_no_finite_speed():
    """Gravity 1e4 g: check warns that the spheres meet at 59 m/s and pass through each other; the run that
    diverges on it named "none of the known limits" (its measured speeds were NaN)."""
    scene = _grains(gravity=[0, 0, -9.81e4])
    causes = likely_causes(scene, 1e-6, math.nan, 0.001, [])
    assert any(text.startswith("contacts glass-glass at") and "overlap" in text for text in causes), causes
    assert not any(text.startswith("none of the known limits") for text in causes)


def test_a_step_above_the_thermal_limit_is_named():
    """heat_capacity 1e-15: check warns that dt is far above the thermal step limit; the run's stop on the
    non-finite temperatures named "none of the known limits"."""
    causes = likely_causes(_grains(heated=True), 9e-6, math.nan, 0.001, [])
    assert any("thermal step limit" in text and "heat_capacity" in text for text in causes), causes


def test_a_temperature_blow_up_is_named_as_the_thermal_limit(tmp_path):
    """The temperatures turned non-finite before the run's check, which then reported
    "non-finite energies" with "none of the known limits"; the unstable temperature update is named first."""
    import pytest

    from pdemfem import Simulation
    from pdemfem.errors import SolverError

    # So small a capacity that the temperatures overflow within a few steps of the first contact with the hot
    # floor, before the run's next check (every 100 steps).
    scene = _grains_dict(heated=True, capacity=1e-30)
    scene["time"]["end"] = 0.02
    sim = Simulation.from_dict(scene, output_dir=tmp_path)
    with pytest.raises(SolverError) as stopped:
        sim.run(progress=False)
    assert "the temperature update is unstable" in str(stopped.value)


def test_a_restart_that_stops_at_once_writes_no_second_row(tmp_path):
    """A restart from the checkpoint a diverged run left stops again at its first check: it wrote the
    checkpoint's row (and field step) a second time."""
    import pytest

    from pdemfem import Simulation
    from pdemfem.errors import SolverError
    from pdemfem.plot import read_history

    scene = _grains_dict(heated=True, capacity=1e-30)
    scene["time"]["end"] = 0.02
    scene["checkpoint"] = {"every": 0.01}
    with pytest.raises(SolverError):
        Simulation.from_dict(scene, output_dir=tmp_path).run(progress=False)
    (stopped,) = (tmp_path / "checkpoints").glob("checkpoint_*_diverged.h5")
    with pytest.raises(SolverError):
        Simulation.from_dict(scene, output_dir=tmp_path, restart=stopped).run(progress=False)
    steps = read_history(tmp_path / "history.csv")["step"]
    assert len(set(steps)) == len(steps), steps


def test_the_stopped_state_does_not_become_latest_nor_push_out_the_good_checkpoints(tmp_path):
    """A diverged run's state was written as the newest checkpoint: latest.h5 pointed at the broken state and,
    with checkpoint.keep, pruning deleted the good checkpoints before it.  It is kept apart now
    (checkpoint_<step>_diverged.h5), and the message names the last good checkpoint."""
    import os

    import pytest

    from pdemfem import Simulation
    from pdemfem.errors import SolverError

    scene = _grains_dict(heated=True, capacity=1e-30)
    scene["time"]["end"] = 0.02
    scene["checkpoint"] = {"every": 0.0005, "keep": 2}  # ~55 steps: several checkpoints before the blow-up
    with pytest.raises(SolverError) as stopped:
        Simulation.from_dict(scene, output_dir=tmp_path).run(progress=False)
    folder = tmp_path / "checkpoints"
    good = sorted(folder.glob("checkpoint_????????????.h5"))
    (diverged,) = folder.glob("checkpoint_*_diverged.h5")
    assert len(good) == 2, good  # keep 2: the stopped state pushed out none of them
    assert int(diverged.name[len("checkpoint_"):][:12]) > int(good[-1].stem[len("checkpoint_"):])
    assert os.path.samefile(folder / "latest.h5", good[-1])
    assert str(diverged) in str(stopped.value) and str(good[-1]) in str(stopped.value)
    # The good checkpoint restarts (the scene unchanged, so it diverges again, from the good state).
    with pytest.raises(SolverError):
        Simulation.from_dict(scene, output_dir=tmp_path, restart=folder / "latest.h5").run(progress=False)


def test_a_run_that_stopped_before_its_first_checkpoint_runs_again_with_force(tmp_path):
    """It left only the stopped state (checkpoint_<step>_diverged.h5) and said "run again once fixed", but the
    output guard took that file for a checkpoint to continue and refused the new run even with --force (and a
    --restart of the folder found no latest.h5)."""
    import pytest

    from pdemfem import Simulation
    from pdemfem.errors import OutputError, SolverError

    scene = _grains_dict(heated=True, capacity=1e-30)
    scene["time"]["end"] = 0.02
    scene["checkpoint"] = {"every": 0.015}  # the temperatures blow up at t = 0.0144 s, before it
    with pytest.raises(SolverError) as stopped:
        Simulation.from_dict(scene, output_dir=tmp_path).run(progress=False)
    assert "run again with --force once fixed" in str(stopped.value)
    fixed = _grains_dict(heated=True, capacity=800.0)
    fixed["time"]["end"] = 0.002
    fixed["checkpoint"] = {"every": 0.001}
    with pytest.raises(OutputError) as refused:
        Simulation.from_dict(fixed, output_dir=tmp_path).run(progress=False)
    assert "_diverged.h5" in str(refused.value) and "--force" in str(refused.value)
    Simulation.from_dict(fixed, output_dir=tmp_path, force=True).run(progress=False)
    folder = tmp_path / "checkpoints"
    assert not list(folder.glob("*_diverged.h5")) and (folder / "latest.h5").is_file()
