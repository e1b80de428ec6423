"""How numpy arrays and non-finite numbers of the view types appear in JSON (API, WebSocket, flight log).

The view dataclasses annotate their numpy fields with `Array(shape)`: pydantic then validates a nested list
of numbers into a read-only float64 array of that shape, writes the array back as nested lists, and
advertises it in JSON Schema/OpenAPI as nested arrays of fixed length. JSON has no NaN or infinity: a
non-finite element is written as null and read back as NaN (`Real` does the same for a scalar; `Age` reads
null back as infinity, "never").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np
from pydantic import GetCoreSchemaHandler, GetJsonSchemaHandler
from pydantic.json_schema import JsonSchemaValue
from pydantic_core import core_schema


def _finite_or_none(x: float) -> float | None:
    return x if math.isfinite(x) else None


def _nested(arr: np.ndarray) -> Any:
    """An array as nested lists with None in place of every non-finite element."""
    if arr.ndim == 0:
        return _finite_or_none(float(arr))
    if arr.ndim == 1:
        return [_finite_or_none(float(x)) for x in arr]
    return [_nested(row) for row in arr]


def _number_or_null() -> JsonSchemaValue:
    return {"anyOf": [{"type": "number"}, {"type": "null"}]}


@dataclass(frozen=True)
class Array:
    """pydantic metadata for an `np.ndarray` field of the given shape (-1: any length along that axis)."""

    shape: tuple[int, ...]

    def __get_pydantic_core_schema__(
        self, _source: Any, _handler: GetCoreSchemaHandler
    ) -> core_schema.CoreSchema:
        def validate(value: Any) -> np.ndarray:
            if isinstance(value, np.ndarray):
                raw = value
            else:
                raw = np.array(_nan_for_none(value), dtype=float)
            arr = np.array(raw, dtype=float)
            if arr.ndim != len(self.shape) or any(
                s not in (-1, a) for s, a in zip(self.shape, arr.shape, strict=True)
            ):
                if arr.size == 0 and -1 in self.shape[:1]:  # an empty list for an (M, 3) array: M = 0
                    arr = arr.reshape(tuple(0 if s == -1 else s for s in self.shape))
                else:
                    raise ValueError(f"expected an array of shape {self.shape}, got {arr.shape}")
            arr.setflags(write=False)
            return arr

        return core_schema.no_info_plain_validator_function(
            validate,
            serialization=core_schema.plain_serializer_function_ser_schema(_nested, when_used="always"),
        )

    def __get_pydantic_json_schema__(
        self, _schema: core_schema.CoreSchema, _handler: GetJsonSchemaHandler
    ) -> JsonSchemaValue:
        schema: JsonSchemaValue = _number_or_null()
        for n in reversed(self.shape):
            schema = {"type": "array", "items": schema}
            if n >= 0:
                schema["minItems"] = schema["maxItems"] = n
        return schema


def _nan_for_none(value: Any) -> Any:
    if value is None:
        return math.nan
    if isinstance(value, list | tuple):
        return [_nan_for_none(v) for v in value]
    return value


@dataclass(frozen=True)
class _NullableFloat:
    """A float written as null when it is not finite, read back from null as `missing`."""

    missing: float

    def __get_pydantic_core_schema__(
        self, _source: Any, _handler: GetCoreSchemaHandler
    ) -> core_schema.CoreSchema:
        def validate(value: Any) -> float:
            if value is None:
                return self.missing
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ValueError(f"expected a number or null, got {value!r}")
            return float(value)

        return core_schema.no_info_plain_validator_function(
            validate,
            serialization=core_schema.plain_serializer_function_ser_schema(
                lambda x: _finite_or_none(float(x)), when_used="always"
            ),
        )

    def __get_pydantic_json_schema__(
        self, _schema: core_schema.CoreSchema, _handler: GetJsonSchemaHandler
    ) -> JsonSchemaValue:
        return _number_or_null()


Real = Annotated[float, _NullableFloat(math.nan)]
"""A float that may be NaN or infinite (null in JSON, read back as NaN)."""

Age = Annotated[float, _NullableFloat(math.inf)]
"""An age in seconds that is infinite for "never" (null in JSON, read back as infinity)."""

Vec2 = Annotated[np.ndarray, Array((2,))]
Vec3 = Annotated[np.ndarray, Array((3,))]
Points3 = Annotated[np.ndarray, Array((-1, 3))]
Cov6 = Annotated[np.ndarray, Array((6, 6))]
