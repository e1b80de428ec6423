"""Reading a flight log back: the header, the operator's view at every sample, the audit records and the end.

The file is read record by record from the start (the `mcap` library's stream reader), so a log cut short by
a crash or a kill -9 reads up to its last whole chunk; what follows is reported as `truncated`, not an
error. A message that does not decode is skipped and counted.
"""

from __future__ import annotations

import io
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader
from pydantic import ValidationError

from server.flightlog.channels import AUDIT_TOPIC, END_TOPIC, HEADER_TOPIC, STATE_TOPIC
from server.flightlog.records import (
    AUDIT,
    END,
    HEADER,
    AuditRecord,
    LogEnd,
    LogHeader,
    RecordError,
    check_format,
)
from webui.schema import scene_from_json
from webui.view import SceneView

MCAP_MAGIC = b"\x89MCAP0\r\n"


class FlightLogError(ValueError):
    """A file that is not a readable flight log; the message names the file and says why."""


@dataclass(frozen=True)
class FlightRecord:
    """A flight log read back: the header, the views and audit records in file order, the end record (None
    when the run did not stop cleanly), whether the file was cut short, and how many messages did not
    decode and were skipped."""

    path: Path
    header: LogHeader
    samples: tuple[SceneView, ...]
    audit: tuple[AuditRecord, ...]
    end: LogEnd | None
    truncated: bool
    bad_messages: int


def read_flight_log(path: Path) -> FlightRecord:
    """Read a flight log. FlightLogError (naming the file) if it is missing, unreadable, not MCAP, has no
    skyring header or an unsupported version; a file cut short is read up to the cut."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise FlightLogError(f"{path}: cannot read the flight log ({exc.strerror or exc})") from None
    if not data.startswith(MCAP_MAGIC):
        raise FlightLogError(f"{path}: not a skyring flight log: not an MCAP file")
    channels: dict[int, str] = {}
    header: LogHeader | None = None
    samples: list[SceneView] = []
    audit: list[AuditRecord] = []
    end: LogEnd | None = None
    bad = 0
    truncated = False
    decoders: dict[str, Callable[[bytes], Any]] = {
        HEADER_TOPIC: HEADER.validate_json,
        STATE_TOPIC: scene_from_json,
        AUDIT_TOPIC: AUDIT.validate_json,
        END_TOPIC: END.validate_json,
    }
    try:
        for record in StreamReader(io.BytesIO(data), skip_magic=False).records:
            if isinstance(record, Channel):
                channels[record.id] = record.topic
                continue
            if not isinstance(record, Message):
                continue
            topic = channels.get(record.channel_id)
            decode = decoders.get(topic or "")
            if decode is None:
                continue  # the Foxglove scene, or a channel a newer skyring added
            try:
                value = decode(record.data)
            except (ValidationError, ValueError):
                bad += 1
                continue
            if topic == HEADER_TOPIC and header is None:
                header = value
            elif topic == STATE_TOPIC:
                samples.append(value)
            elif topic == AUDIT_TOPIC:
                audit.append(value)
            elif topic == END_TOPIC:
                end = value
    except Exception:  # noqa: BLE001 - a cut or damaged tail: everything before it stands
        truncated = True
    if header is None:
        raise FlightLogError(f"{path}: not a skyring flight log: no {HEADER_TOPIC} header message")
    try:
        check_format(header)
    except RecordError as exc:
        raise FlightLogError(f"{path}: {exc}") from None
    return FlightRecord(
        path=path,
        header=header,
        samples=tuple(samples),
        audit=tuple(audit),
        end=end,
        truncated=truncated,
        bad_messages=bad,
    )
