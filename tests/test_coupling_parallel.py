"""The coupled scenes give the same results on 1 and 3 ranks (FEM and DEM on the same communicator).

Tolerance from round-off: the ranks sum forces (FE assembly, MatMult, contact spreading via ADD_VALUES,
the reductions) in another order, which perturbs the state by a few ulp per step; the collisions then
amplify that.  The serial run with every particle shifted by one ulp measures that amplification; the
parallel difference must stay within 100x of it, above a floor of 1e4 eps of the scale: a few eps per step
over the 400 / 1500 / 600 steps (pile_window: fem_every = 3, the contact dashpots of a window reach the solid
at its end).  Records of particles that change rank within a window are shared and balanced where the
particle lives; tests/test_restart.py runs that path (a mid-window checkpoint of 1 rank restarted on 2).  The case script converges the solids' static start to rtol 1e-13, so that it
does not differ between partitions by the default 1e-10's slack (at 1e-10 the block's surface displacements
differed by 6.7e-11 of their scale).  Measured (3 ranks vs 1, relative to the scale, over several runs):
positions <= 2.7e-16, velocities <= 3.6e-15, surface force history <= 1.4e-13, support reaction <= 1.6e-14,
surface displacements <= 1.3e-14: all below the floor (2.2e-12).  Since the P2 faces spread the contact force by
their flat sub-triangles' weights the pile's force history differs by 2.4e-12 of its scale (41x its one-ulp growth,
5.8e-14; shifting particle 0 alone, as before, changed nothing in the window: it touched nothing).
"""
import numpy as np
import pytest

from mpi_harness import run_under_mpi

EPS = np.finfo(float).eps


def run(tmp_path, ranks, case, steps, *extra):
    out = tmp_path / f"{case}_{ranks}{'_'.join(extra)}.npz"
    run_under_mpi(ranks, "coupling_agreement.py", out, case, steps, *extra)
    return dict(np.load(out))


@pytest.mark.mpi
@pytest.mark.parametrize("case, steps", [("ball", 400), ("pile", 1500), ("pile_blended", 1500), ("pile_window", 600)])
def test_one_and_three_ranks_agree(tmp_path, case, steps):
    serial = run(tmp_path, 1, case, steps)
    nudged = run(tmp_path, 1, case, steps, "ulp")
    parallel = run(tmp_path, 3, case, steps)
    assert np.array_equal(serial["ids"], parallel["ids"])
    assert np.max(np.abs(serial["forces"])) > 0  # the particles touched the solid
    for key in ("positions", "velocities", "forces", "reaction", "surface"):
        scale = np.max(np.abs(serial[key]))
        growth = np.max(np.abs(nudged[key] - serial[key]))
        difference = np.max(np.abs(parallel[key] - serial[key]))
        floor = 1e4 * EPS * scale
        tolerance = max(100 * growth, floor)
        print(f"{case} {key}: 3 ranks vs 1 {difference:.3g}, one-ulp growth {growth:.3g}, tolerance {tolerance:.3g} "
              f"(scale {scale:.3g})")
        assert difference <= tolerance, key
