"""Base types of every scene model (scene.schema, fem.config): strict models and checked numbers.

A module of its own so that the scene schema can include the FE solid's keys
and the FE config can use the same base without an import cycle.
"""
from __future__ import annotations

from typing import Annotated, Tuple

from pydantic import AfterValidator, BaseModel, ConfigDict, Field

PositiveFloat = Annotated[float, Field(gt=0)]
NonNegativeFloat = Annotated[float, Field(ge=0)]
Vector3 = Tuple[float, float, float]


def _ordered_box(box):
    low, high = box
    if any(h <= l for l, h in zip(low, high)):
        raise ValueError("box must be [[xmin,ymin,zmin],[xmax,ymax,zmax]] with every max > min")
    return box


# An axis-aligned box [[xmin, ymin, zmin], [xmax, ymax, zmax]].
Box = Annotated[Tuple[Vector3, Vector3], AfterValidator(_ordered_box)]


class StrictModel(BaseModel):
    # Unknown keys are errors: a misspelt key must never be silently ignored.
    model_config = ConfigDict(extra="forbid", frozen=False)
