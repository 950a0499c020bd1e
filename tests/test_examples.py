"""Every examples/*.yaml runs a short window and obeys its physics (as a user would run it).

Each scene is run as shipped except `time.end` (the first WINDOW_FRACTION of the run, at most
WINDOW_STEPS steps or the fall of its highest grain: the grains land, collide or tumble in it) and its output (a temporary folder, one history row every ROW_STEPS steps, no field
series).  The history must show:

* no particle lost and none created (`particles` constant, `lost_particles` 0), unless the scene has
  a `domain.box` that grains may leave (then every loss is counted: particles + lost = inserted), or
  streams and outlets (then particles = inserted + particles_in - particles_out);
* the energy balance closed: the bookkeeping total (kinetic + rotational + potential + elastic +
  dissipated - wall work + the solids' kinetic, strain and load potential) stays within
  ENERGY_TOLERANCE of the energy that changed form in the window;
* the run was not stopped by the run monitor (Simulation.run raises SolverError when it is).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from pdemfem import Simulation
from pdemfem.monitor import total_energy
from pdemfem.plot import read_history
from pdemfem.scene import derived
from pdemfem.scene.loader import load_scene

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
WINDOW_FRACTION = 0.5
# The long scenes' windows (a conveyor, a discharging hopper) stop after this many steps, or once their
# highest grain can have fallen to the floor (derived.fall_height) if that takes longer: by then the grains
# have landed and the energy has changed form many times over; the rest of their half-time adds minutes.
WINDOW_STEPS = 10000
ROW_STEPS = 50
# Velocity Verlet resolving a contact in >= 30 steps (what dt auto and `check` enforce for every
# example) errs by ~(omega dt)^2 / 8 = (pi/30)^2 / 8 ~ 1.4e-3 of the contact's energy, and a grain's
# energy passes through several contacts before it is dissipated: measured in these windows, the
# drift is 1.1e-4 (coupled_demo) to 4.9e-3 (drum) of the energy that changed form (5.5e-3 at most
# over the whole runs, funnel).  2 % bounds that and
# still catches an energy source (a wrong sign or a missing work term moves the total by the whole
# energy it concerns).
ENERGY_TOLERANCE = 0.02


def example_paths():
    return sorted(EXAMPLES.glob("*.yaml"))


def short_scene(path: Path, folder: Path) -> dict:
    data = yaml.safe_load(path.read_text())
    scene, _ = load_scene(path)
    dt = float(derived.time_step(scene, base_dir=path.parent)) if scene.particles else None
    if dt is not None:
        gravity = float(np.linalg.norm(scene.gravity))
        fall = math.sqrt(2.0 * derived.fall_height(scene) / gravity) if gravity > 0.0 else 0.0
        data["time"]["end"] = min(WINDOW_FRACTION * scene.time.end, max(WINDOW_STEPS * dt, fall))
        data["output"] = {"dir": str(folder), "every": ROW_STEPS * dt, "particles": [], "solids": []}
    return data


@pytest.mark.parametrize("path", example_paths(), ids=lambda path: path.name)
def test_example_runs_a_window_with_its_particles_and_energy_accounted_for(path, tmp_path):
    data = short_scene(path, tmp_path / "out")
    simulation = Simulation.from_dict(data, base_dir=path.parent, output_dir=tmp_path / "out")
    inserted = simulation.particle_count()
    simulation.run(progress=False)  # raises SolverError (exit 3) when the run monitor stops it
    assert simulation.stopped_by is None
    history = read_history(tmp_path / "out" / "history.csv")
    assert history["step"][-1] == simulation.step_count > 0

    # Streams add particles and outlets take them (docs/streams.md): both are counted.
    streamed = history["particles_in"] - history["particles_out"] if "particles_in" in history else 0
    if data.get("domain", {}).get("box") is None:
        assert np.all(history["particles"] == inserted + streamed) and np.all(history["lost_particles"] == 0)
    else:
        assert np.all(history["particles"] + history["lost_particles"] == inserted + streamed)

    rows = [{name: history[name][index] for name in history} for index in range(len(history["time"]))]
    totals = np.array([total_energy(row) for row in rows])
    # Heat content (m c T) is not a mechanical energy: kept out of the scale as it is out of the total.
    forms = [name for name in history if (name.endswith("_energy") or name in (
        "wall_work", "solid_load_potential", "thermoelastic_work", "frame_work")) and "thermal_energy" not in name]
    changed = sum(float(np.ptp(history[name])) for name in forms)
    drift = float(np.abs(totals - totals[0]).max())
    # Something must happen: contacts formed (grains landed or collided), not a free fall only.
    assert history["contacts"].max() > 0 and history["dissipated_energy"][-1] > 0.0
    assert drift <= ENERGY_TOLERANCE * changed, (path.name, drift, changed)
    print(f"{path.name}: {simulation.step_count} steps, energy drift {drift:.3g} J of {changed:.3g} J moved "
          f"({drift / changed:.2e})")
