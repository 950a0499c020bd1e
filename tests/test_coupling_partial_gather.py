"""Partial gather of a solid's contact surface (pdemfem.coupling.selection): each rank gathers the nodes near its
own particles, and the physics is the whole gather's.

The wide plate (0.4 x 0.1 m, 165 surface nodes) of tests/mpi_cases/partial_gather_case.py on 2 ranks:

- spread: grains over the whole plate; each rank's largest selection is a part of the surface (its RCB half
  plus the margin), the 2-rank run is bit-identical to the 2-rank run with the whole gather (the selected
  vertices get the same values by the same arithmetic, and the left-out triangles are never within reach of a
  particle, so every contact sums the same terms in the same order), and agrees with the serial run as
  tests/test_coupling_parallel.py asserts (tolerance: 100 x the serial run's growth of a one-ulp
  perturbation, above a floor of 1e4 eps of the scale; measured 3e-13 of 6.2 N in the forces).
- fall: grains above the plate, first selections empty: the particles' region, checked at the list builds,
  brings the plate in as they fall;
- rise: no gravity, the plate driven up into grains at rest: the surface's drift, checked after the advances,
  brings it in.
- hot: spread with heat and fem_every 3: the gathered surface temperatures, the contacts' heat and the
  dashpot records of 3-step windows give bit-identical particles and temperatures.
In fall and rise the selection is made anew several times and the run is bit-identical to the whole gather; the
negative control keeps the first selection: the contacts then use stale vertices (fall: the plate's dents
under the impacts are missed; rise: the plate never arrives) and the results differ by more than 1e-3 of
their scale, nine orders above round-off.
"""
import numpy as np
import pytest

from mpi_harness import run_under_mpi

EPS = np.finfo(float).eps


def run(tmp_path, ranks, case, steps, mode="partial"):
    out = tmp_path / f"{case}_{ranks}_{mode}.npz"
    run_under_mpi(ranks, "partial_gather_case.py", out, case, steps, mode)
    return dict(np.load(out))


@pytest.mark.mpi
def test_each_rank_gathers_its_share_and_the_physics_is_unchanged(tmp_path):
    steps = 1500
    serial = run(tmp_path, 1, "spread", steps)
    nudged = run(tmp_path, 1, "spread", steps, "ulp")
    partial = run(tmp_path, 2, "spread", steps)
    whole = run(tmp_path, 2, "spread", steps, "whole")
    nodes = int(partial["nodes"])
    print(f"surface nodes {nodes}, largest selection per rank {partial['selected']}, "
          f"selections {partial['selections']}")
    assert np.all(whole["selected"] == nodes)
    assert np.all(serial["selected"] == nodes)  # one rank: the whole gather is a local copy, kept
    # Each rank's half of the grains (x < 0.2 or x > 0.2) plus the margin (4 radii + reach, 2.8 cm): about
    # 60 % of the plate, never the whole of it.
    assert np.all(partial["selected"] < 0.75 * nodes) and np.all(partial["selected"] > 0)
    assert np.max(np.abs(serial["forces"])) > 0  # the grains touched the plate
    for key in ("positions", "velocities", "forces"):
        assert np.array_equal(partial[key], whole[key]), key
        scale = np.max(np.abs(serial[key]))
        growth = np.max(np.abs(nudged[key] - serial[key]))
        difference = np.max(np.abs(partial[key] - serial[key]))
        tolerance = max(100 * growth, 1e4 * EPS * scale)
        print(f"{key}: 2 ranks (partial) vs 1 {difference:.3g}, tolerance {tolerance:.3g} (scale {scale:.3g})")
        assert difference <= tolerance, key


@pytest.mark.mpi
@pytest.mark.parametrize("case", ["fall", "rise"])
def test_the_selection_follows_the_particles_and_the_surface(tmp_path, case):
    steps = 1000
    partial = run(tmp_path, 2, case, steps)
    whole = run(tmp_path, 2, case, steps, "whole")
    frozen = run(tmp_path, 2, case, steps, "frozen")
    print(f"{case}: selections {partial['selections']}, largest per rank {partial['selected']} of {partial['nodes']}; "
          f"frozen: {frozen['selected']}")
    assert partial["selections"] > 2  # made anew as the grains fell / the plate rose
    assert np.all(frozen["selected"] == 0)  # the first selection: nothing within reach
    assert np.max(np.abs(whole["forces"])) > 0  # the grains met the plate
    for key in ("positions", "velocities", "forces"):
        assert np.array_equal(partial[key], whole[key]), key
    # Negative control: stale vertices change the results far beyond round-off.
    scale = np.max(np.abs(whole["forces"]))
    assert np.max(np.abs(frozen["forces"] - whole["forces"])) > 1e-3 * scale


@pytest.mark.mpi
def test_heat_and_windows_are_unchanged(tmp_path):
    partial = run(tmp_path, 2, "hot", 1500)
    whole = run(tmp_path, 2, "hot", 1500, "whole")
    assert np.all(partial["selected"] < partial["nodes"])
    assert np.min(whole["temperatures"]) < 499.0  # the grains gave the plate heat (they start at 500 K)
    for key in ("positions", "velocities", "forces", "temperatures"):
        assert np.array_equal(partial[key], whole[key]), key


@pytest.mark.mpi
def test_a_scene_with_a_stream_keeps_the_whole_gather(tmp_path):
    """A stream's insertion tests its candidates against every triangle on every rank (all ranks must accept
    the same ones), so no rank may hold stale triangles."""
    result = run(tmp_path, 2, "stream", 300)
    assert result["selections"] == 0
    assert np.all(result["selected"] == result["nodes"])
    assert len(result["ids"]) > 48  # the stream inserted grains while the plate was in the scene
