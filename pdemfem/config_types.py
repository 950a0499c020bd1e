"""Base types of every scene model (scene.schema, fem.config): strict models and checked numbers.

A module of its own so that the scene schema can include the FE solid's keys
and the FE config can use the same base without an import cycle.
"""
from __future__ import annotations

from typing import Annotated, Tuple

from pydantic import BaseModel, ConfigDict, Field

PositiveFloat = Annotated[float, Field(gt=0)]
NonNegativeFloat = Annotated[float, Field(ge=0)]
Vector3 = Tuple[float, float, float]


class StrictModel(BaseModel):
    # Unknown keys are errors: a misspelt key must never be silently ignored.
    model_config = ConfigDict(extra="forbid", frozen=False)
