"""The base of every robot.yaml model (:class:`Strict`): frozen, unknown keys are errors, and a whole number written
with a point (``5.0``) is that number, as JSON Schema's ``integer`` (and so ``robocore schema``) already says."""

from __future__ import annotations

from types import UnionType
from typing import Any, Union, get_args, get_origin

from pydantic import BaseModel, ConfigDict, ValidationInfo, field_validator


class Strict(BaseModel):
    """Base for every robot.yaml model: frozen, unknown keys are errors."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    @field_validator("*", mode="before")
    @classmethod
    def _whole_numbers(cls, value: Any, info: ValidationInfo) -> Any:
        if isinstance(value, float) and info.field_name:
            return whole_float(value, cls.model_fields[info.field_name].annotation)
        return value


def whole_float(value: Any, annotation: Any) -> Any:
    """``5.0`` as ``5`` for a field of ``annotation`` that holds a whole number (:data:`Number`, or ``Number | None``):
    JSON Schema's ``integer`` takes ``5.0`` (so every editor checking robot.yaml against ``robocore schema`` calls it
    fine), and robocore must not reject what the schema accepts. Anything else is left for the field's own check."""
    if isinstance(value, float) and value.is_integer() and _holds_int(annotation):
        return int(value)
    return value


def _holds_int(annotation: Any) -> bool:
    if annotation is int:
        return True
    return get_origin(annotation) in (Union, UnionType) and any(_holds_int(arg) for arg in get_args(annotation))
