"""The Python API's step count: a whole number of steps, or a clear error."""
from __future__ import annotations

import numpy as np
import pytest

from pdemfem import Simulation

SCENE = {
    "time": {"end": 0.001, "dt": "auto"},
    "gravity": [0, 0, -9.81],
    "materials": {"grain": {"density": 2500, "youngs_modulus": 5e6, "poisson_ratio": 0.25}},
    "particles": [{"name": "bead", "material": "grain", "radius": 0.002,
                   "insert": {"kind": "list", "positions": [[0.01, 0.01, 0.01]]}}],
}


@pytest.mark.parametrize("count", [2.5, -5, "3", True])
def test_step_refuses_a_count_that_is_not_a_whole_number_of_steps(count):
    """sim.step(2.5) ran 2 steps and sim.step(-5) none, without a word."""
    simulation = Simulation.from_dict(SCENE)
    with pytest.raises(ValueError, match="count is a whole number of steps >= 0"):
        simulation.step(count)
    assert simulation.step_count == 0
    simulation.step(np.int64(2))  # numpy's integers are whole numbers too
    assert simulation.step_count == 2
