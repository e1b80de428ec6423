"""The JSON form of the operator's view, derived from the view dataclasses themselves (pydantic TypeAdapters
over `webui.view`): what the REST API returns and documents, what the WebSocket streams and what the flight
log's state channel records. Nothing here lists a field by hand.
"""

from __future__ import annotations

import functools
import json
from typing import Any

from pydantic import TypeAdapter

from webui.view import Alert, ObstacleView, SceneView, VehicleView

SCENE = TypeAdapter(SceneView)
VEHICLE = TypeAdapter(VehicleView)
OBSTACLES = TypeAdapter(tuple[ObstacleView, ...])
ALERT = TypeAdapter(Alert)
ALERTS = TypeAdapter(tuple[Alert, ...])


def scene_json(view: SceneView) -> bytes:
    """The view as compact JSON (non-finite numbers as null)."""
    return SCENE.dump_json(view)


def scene_from_json(data: bytes | str) -> SceneView:
    """A view back from `scene_json` (ValueError if it is not one)."""
    return SCENE.validate_json(data)


def scene_dict(view: SceneView) -> dict[str, Any]:
    """The view as the JSON-ready dict the API returns."""
    return SCENE.dump_python(view, mode="json")


@functools.cache
def scene_json_schema() -> dict[str, Any]:
    """JSON Schema (draft 2020-12) of `scene_json`'s output: the flight log's state channel declares it."""
    return SCENE.json_schema(mode="serialization")


def scene_json_schema_bytes() -> bytes:
    return json.dumps(scene_json_schema(), separators=(",", ":")).encode()
