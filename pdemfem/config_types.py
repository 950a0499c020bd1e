"""Base types of every scene model (scene.schema, fem.config): strict models and checked numbers.

A module of its own so that the scene schema can include the FE solid's keys
and the FE config can use the same base without an import cycle.
"""
from __future__ import annotations

import json
import typing
from typing import Annotated, Tuple

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, field_validator

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


def _accepts_bool(annotation) -> bool:
    """Does a field's type admit true/false anywhere (bool, Optional[bool], a union with bool)?"""
    if annotation is bool:
        return True
    return any(_accepts_bool(argument) for argument in typing.get_args(annotation))


def _holds_bool(value) -> bool:
    if isinstance(value, bool):
        return True
    return isinstance(value, (list, tuple)) and any(_holds_bool(item) for item in value)


class StrictModel(BaseModel):
    # Unknown keys are errors: a misspelt key must never be silently ignored.  NaN and
    # infinity are errors: one non-finite number (a modulus, a coordinate) poisons every
    # force it enters, and a wall with a NaN vertex silently stops holding anything.
    model_config = ConfigDict(extra="forbid", frozen=False, allow_inf_nan=False)

    @field_validator("*", mode="before")
    @classmethod
    def _no_bool_as_number(cls, value, info):
        # pydantic reads true as 1 and false as 0; `count: true` or `youngs_modulus: true` is
        # a slip, not a number.
        if _holds_bool(value) and not _accepts_bool(cls.model_fields[info.field_name].annotation):
            raise ValueError(f"true/false is not a number here (got {json.dumps(value)}); write a number")
        return value
