"""The channels a run publishes through the Foxglove SDK, to the MCAP flight log and to a live Foxglove
client alike (both are sinks of one `foxglove.Context`).

| topic | schema | what |
|---|---|---|
| `/scene` | `foxglove.SceneUpdate` (protobuf) | the operator's 3-D scene in the `world` frame |
| `/skyring/state` | `skyring.SceneView` (JSON Schema) | the operator's view itself, as the API serves it |
| `/skyring/audit` | `skyring.AuditRecord` (JSON Schema) | every command and its sender |
| `/skyring/header` | `skyring.LogHeader` (JSON Schema) | the run's settings, first message of a log |
| `/skyring/end` | `skyring.LogEnd` (JSON Schema) | written on a clean stop only |

Messages are logged at the wall time (ns since the epoch); mission time is inside each message.
"""

from __future__ import annotations

import json

import foxglove
from foxglove import Channel, Schema
from foxglove.channels import SceneUpdateChannel

from server.flightlog.foxglove_scene import scene_update
from server.flightlog.records import AUDIT, END, HEADER, AuditRecord, LogEnd, LogHeader
from webui.schema import SCENE, scene_json
from webui.view import SceneView

SCENE_TOPIC = "/scene"
STATE_TOPIC = "/skyring/state"
AUDIT_TOPIC = "/skyring/audit"
HEADER_TOPIC = "/skyring/header"
END_TOPIC = "/skyring/end"


def _json_channel(topic: str, name: str, schema: dict, context: foxglove.Context) -> Channel:
    data = json.dumps(schema, separators=(",", ":")).encode()
    return Channel(
        topic,
        schema=Schema(name=name, encoding="jsonschema", data=data),
        message_encoding="json",
        context=context,
    )


class SkyringChannels:
    """The run's channels in `context`; each `log_*` sends one message to every sink of the context."""

    def __init__(self, context: foxglove.Context) -> None:
        self.context = context
        self.scene = SceneUpdateChannel(SCENE_TOPIC, context=context)
        self.state = _json_channel(
            STATE_TOPIC, "skyring.SceneView", SCENE.json_schema(mode="serialization"), context
        )
        self.audit = _json_channel(
            AUDIT_TOPIC, "skyring.AuditRecord", AUDIT.json_schema(mode="serialization"), context
        )
        self.header = _json_channel(
            HEADER_TOPIC, "skyring.LogHeader", HEADER.json_schema(mode="serialization"), context
        )
        self.end = _json_channel(END_TOPIC, "skyring.LogEnd", END.json_schema(mode="serialization"), context)

    def log_view(self, view: SceneView, log_time_ns: int) -> None:
        self.state.log(scene_json(view), log_time=log_time_ns)
        self.scene.log(scene_update(view), log_time=log_time_ns)

    def log_audit(self, record: AuditRecord, log_time_ns: int) -> None:
        self.audit.log(AUDIT.dump_json(record), log_time=log_time_ns)

    def log_header(self, header: LogHeader, log_time_ns: int) -> None:
        self.header.log(HEADER.dump_json(header), log_time=log_time_ns)

    def log_end(self, end: LogEnd, log_time_ns: int) -> None:
        self.end.log(END.dump_json(end), log_time=log_time_ns)

    def close(self) -> None:
        for channel in (self.scene, self.state, self.audit, self.header, self.end):
            channel.close()
