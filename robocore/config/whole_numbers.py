"""Whole numbers written with a point (``5.0``): JSON Schema's ``integer`` takes them, so robocore does too."""

from __future__ import annotations

from types import UnionType
from typing import Any, Union, get_args, get_origin


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
