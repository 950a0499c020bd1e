"""Partition independence: 1, 2 and 3 ranks give the same solid to solver tolerance / round-off."""
import numpy as np
import pytest

from fem_helpers import dense
from mpi_harness import run_under_mpi
from pdemfem.fem import Solid, SolidConfig
from pdemfem.scene.schema import MaterialConfig

RTOL = 1e-12  # as in tests/mpi_cases/fem_case.py


def _condition_number_of_constrained_stiffness(element):
    # the case's solid, serially in this process: kappa(K) on the free dofs, by dense eigenvalues
    config = SolidConfig(name="block", mesh={"box": [[0, 0, 0], [3.0, 1.0, 1.0]], "cells": [6, 2, 2]}, material="steel",
                         element=element, fixed=["xmin"])
    solid = Solid(config, MaterialConfig(density=7800.0, youngs_modulus=2e11, poisson_ratio=0.3))
    free = ~solid.constrained_dofs
    eigenvalues = np.linalg.eigvalsh(dense(solid.stiffness)[np.ix_(free, free)])
    return eigenvalues[-1] / eigenvalues[0]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """One mpiexec per rank count computes both elements (process start-up dominates these small cases)."""
    directories = {}
    for ranks in (1, 2, 3):
        directories[ranks] = tmp_path_factory.mktemp(f"fem_ranks{ranks}")
        run_under_mpi(ranks, "fem_case.py", directories[ranks], "P1", "P2")
    return directories


@pytest.mark.mpi
@pytest.mark.parametrize("element", ["P1", "P2"])
def test_one_two_three_ranks_agree(runs, element):
    results = [np.load(runs[ranks] / f"{element}.npz") for ranks in (1, 2, 3)]
    assert [int(r["ranks"]) for r in results] == [1, 2, 3]
    kappa = _condition_number_of_constrained_stiffness(element)
    # each static solve has ||u - u*|| / ||u*|| <= kappa(K) * rtol (true residual); two runs differ by twice that
    static_tolerance = 2 * kappa * RTOL
    reference = results[0]
    for other in results[1:]:
        assert bool(other["surface_ok"])  # gathered surface = owners' positions, identical on every rank
        assert int(other["n_triangles"]) == int(reference["n_triangles"])

        def difference(key):
            return np.abs(other[key] - reference[key]).max() / np.abs(reference[key]).max()

        assert difference("static_u") <= static_tolerance
        assert difference("static_vm") <= static_tolerance * 10  # stresses: gradients over cells of size h = 0.5
        # reactions sum K u - f: the residual of the solve (<= rtol ||b||) shows up relative to the reaction
        assert difference("reaction") <= static_tolerance * 10
        # 100 explicit steps propagate the static difference through a stable (non-growing) scheme; the
        # nodal forces come from rank 0 only and reach their owners through PETSc's assembly
        assert difference("dynamic_u") <= static_tolerance * 10
        # from rest, without a linear solve: summation order only, ~1e-15 per step over 100 steps (measured
        # 1.8e-15 .. 2.8e-15)
        assert difference("rest_u") <= 100 * 1e-15
        # energies and work involve velocities, differences of displacements over one step (x ~1e3)
        for key in ("kinetic", "work"):
            assert abs(float(other[key]) - float(reference[key])) <= static_tolerance * 1e3 * abs(float(reference[key]))
