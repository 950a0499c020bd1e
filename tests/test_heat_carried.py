"""Heat carried in by streams and out by outlets and the domain box: history heat_in and heat_out (docs/heat.md).

The heated pour (tests/mpi_cases/stream_scenes.py: heated_pile_stream) drops grains at 300 K onto a floor
held at 400 K beside a side wall held at 250 K; a box outlet takes the grains reaching one edge and the
domain box those rolling past another, so grains come in and leave (by both paths) while the walls heat
and cool them.  The particles' heat content must then change by exactly what the books say,

    particle_thermal_energy(t) - particle_thermal_energy(0) = heat_floor + heat_side + heat_in - heat_out,

up to round-off.  Without heat_in and heat_out the balance of this run misses 3.26e-3 J at its end (the
7.02e-3 J the 112 inserted grains brought in less the 3.76e-3 J the 57 removed ones took out).
"""
from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from mpi_harness import run_under_mpi
from pdemfem import Simulation
from pdemfem.errors import SceneError
from pdemfem.plot import read_history

sys.path.insert(0, str(Path(__file__).parent / "mpi_cases"))
from stream_scenes import (FLOOR_TEMPERATURE, GRAIN_HEAT_CAPACITY, SIDE_TEMPERATURE,  # noqa: E402
                           STREAM_TEMPERATURE, heated_pile_stream)

EPS = np.finfo(float).eps
CARRIED = ("heat_in", "heat_out")


def _wall_books(history) -> np.ndarray:
    """Sum of heat_<wall> over the walls (the heat they gave the particles), per row."""
    return sum(history[column] for column in history if column.startswith("heat_") and column not in CARRIED)


def _balance_residual(history) -> np.ndarray:
    content = history["particle_thermal_energy"]
    return content - content[0] - _wall_books(history) - history["heat_in"] + history["heat_out"]


def _round_off(history, steps: int) -> float:
    """What round-off may leave of the balance: every step rounds each particle's T += dt Q / (m c) (at most
    eps/2 of its m c T: eps/2 of the content in all) and each wall ledger's running sum (eps/2 of it, two
    walls), so 2 eps of the largest amount in the books per step; each sum over the particles (the content,
    an insertion's or a removal's heat) rounds once per term."""
    magnitude = max(float(np.abs(history[column]).max())
                    for column in ("particle_thermal_energy", "heat_in", "heat_out", "heat_floor", "heat_side"))
    return (2 * steps + float(history["particles_in"].max())) * EPS * magnitude


def _removed_heat_bounds(mass_removed: float) -> tuple:
    """The heat content of `mass_removed` kg of grains: every grain stays between the coldest and the hottest
    wall (the maximum principle of the update while dt sum(H) / (m c) <= 1, which the run guards)."""
    return (GRAIN_HEAT_CAPACITY * SIDE_TEMPERATURE * mass_removed,
            GRAIN_HEAT_CAPACITY * FLOOR_TEMPERATURE * mass_removed)


@pytest.fixture(scope="module")
def poured(tmp_path_factory):
    """The heated pour run to its end on one rank: (simulation, its output directory, its history)."""
    out = tmp_path_factory.mktemp("heated_pour") / "full"
    sim = Simulation.from_dict(heated_pile_stream(out), output_dir=out)
    sim.run(progress=False)
    return sim, out, read_history(out / "history.csv")


def test_the_heat_balance_of_a_heated_pour_closes_to_round_off(poured):
    sim, _, history = poured
    # Not vacuous: grains came in and left by the outlet and by the domain box, and both walls moved heat.
    assert history["particles_in"][-1] > 100 and history["particles_out"][-1] > 0
    assert history["lost_particles"][-1] > 0
    assert history["heat_in"][-1] > 0 and history["heat_out"][-1] > 0
    assert history["heat_floor"][-1] > 0 and history["heat_side"][-1] < 0
    tolerance = _round_off(history, sim.step_count)
    residual = np.abs(_balance_residual(history))
    print(f"largest residual {residual.max():.3g} J, round-off bound {tolerance:.3g} J, heat_in "
          f"{history['heat_in'][-1]:.6g} J, heat_out {history['heat_out'][-1]:.6g} J")
    assert residual.max() <= tolerance, (residual.max(), tolerance)
    # heat_in is the inserted mass at the stream's temperature (a sum over the same particles in another order).
    expected_in = GRAIN_HEAT_CAPACITY * STREAM_TEMPERATURE * history["mass_in"]
    assert np.all(np.abs(history["heat_in"] - expected_in) <= history["particles_in"] * EPS * expected_in)
    # heat_out is the content of the mass that left (outlet and domain box), within the walls' temperatures.
    state = sim.particle_system.state
    removed = history["mass_in"][-1] - float(np.sum(state.mass[:state.owned_count]))
    low, high = _removed_heat_bounds(removed)
    assert low < history["heat_out"][-1] < high


def test_a_restart_continues_heat_in_and_heat_out_bit_identically(poured, tmp_path):
    full, out, history = poured
    copy = tmp_path / "restarted"
    shutil.copytree(out, copy)
    first = sorted((copy / "checkpoints").glob("checkpoint_*.h5"))[0]
    restarted = Simulation.from_dict(heated_pile_stream(copy), output_dir=copy, restart=first)
    at_checkpoint = restarted.heat_carried()
    restarted.run(progress=False)
    # Grains came in and left after the checkpoint: the continuation carried both books on.
    assert history["heat_in"][-1] > at_checkpoint["heat_in"] and history["heat_out"][-1] > at_checkpoint["heat_out"]
    assert restarted.heat_carried() == full.heat_carried()
    assert (out / "history.csv").read_text() == (copy / "history.csv").read_text()


@pytest.mark.mpi
def test_the_heat_balance_closes_on_two_ranks_with_each_rank_booking_its_own(tmp_path):
    """On 2 ranks each rank books the grains it inserts and removes; the books are summed only when a row is
    written.  Both ranks inserted and removed grains here, and the sums close the balance as on one rank (a
    grain booked on both ranks, or on neither, would miss it by its whole heat content)."""
    out = tmp_path / "two"
    run_under_mpi(2, "heat_stream_case.py", out, tmp_path / "result.json")
    result = json.loads((tmp_path / "result.json").read_text())
    history = read_history(out / "history.csv")
    booked = np.array(result["booked"])  # (rank, in/out)
    assert np.all(booked > 0), booked
    assert history["lost_particles"][-1] > 0 and history["particles_out"][-1] > 0
    tolerance = _round_off(history, result["steps"])
    residual = np.abs(_balance_residual(history))
    print(f"2 ranks: largest residual {residual.max():.3g} J, round-off bound {tolerance:.3g} J, booked per rank "
          f"{booked.tolist()}")
    assert residual.max() <= tolerance, (residual.max(), tolerance)
    # The rows' sums are the ranks' bookings (each rank's running sum, then the sum of two).
    for column, index in zip(CARRIED, range(2)):
        assert abs(history[column][-1] - booked[:, index].sum()) <= 4 * EPS * history[column][-1], column
    expected_in = GRAIN_HEAT_CAPACITY * STREAM_TEMPERATURE * result["mass_in"]
    assert abs(history["heat_in"][-1] - expected_in) <= history["particles_in"][-1] * EPS * expected_in
    low, high = _removed_heat_bounds(result["mass_in"] - result["mass_present"])
    assert low < history["heat_out"][-1] < high


@pytest.mark.parametrize("name", ["in", "out"])
def test_walls_named_in_or_out_are_refused_with_heat_on(tmp_path, name):
    """heat_<wall> would be read as heat_in or heat_out."""
    scene = heated_pile_stream(tmp_path)
    scene["walls"][1]["name"] = name
    with pytest.raises(SceneError) as error:
        Simulation.from_dict(scene, output_dir=tmp_path)
    assert f"'{name}'" in str(error.value) and "heat_in" in str(error.value)
    scene["heat"] = {"enabled": False}  # without heat there are no heat columns: the name is free
    Simulation.from_dict(scene, output_dir=tmp_path)
