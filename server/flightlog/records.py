"""The records of a flight log besides the operator's view itself (which is `webui.view.SceneView`, recorded
as it is): the run's header, the audit record of every operator command, and the end record.

Each is a frozen dataclass; its JSON form and JSON Schema come from pydantic TypeAdapters over the
dataclass, so the file format is what these classes say. Add fields with defaults; never rename one (old logs
must stay readable).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from pydantic import TypeAdapter

from webui.arrays import Real

FORMAT = "skyring-flight-log"
VERSION = 2

Scalar = bool | int | float | str


class RecordError(ValueError):
    """Data that is not a record this reader understands (a field missing or of the wrong type)."""


@dataclass(frozen=True)
class LogHeader:
    """What was flown. command: "serve" (embedded simulation) or "serve --px4"; vehicles: number of MAVs;
    seed, method, trees, person: the world's settings; rate_hz: control rate; speed: simulated seconds per
    wall second; vehicle_urls: the MAVSDK URLs of PX4 vehicles (empty in simulation); sample_rate_hz: state
    samples per second of mission time; started_utc: wall time the log was opened, ISO 8601 UTC; format and
    version: what reads it."""

    command: str
    vehicles: int
    seed: int
    method: str
    trees: str
    person: str
    rate_hz: float
    speed: float
    sample_rate_hz: float
    started_utc: str
    vehicle_urls: tuple[str, ...] = ()
    format: str = FORMAT
    version: int = VERSION


@dataclass(frozen=True)
class AuditRecord:
    """One operator command, accepted or refused, and who sent it.

    time_s: mission time; utc: wall time (ISO 8601); command: the ground-station command (set_formation,
    land_all, ...); arguments: as the operator gave them (a value JSON cannot hold is kept as its text);
    operator: the signed-in name ("" when not signed in; "local" on a loopback station without sign-in;
    "station" for its own shutdown landing); role: "operator", "observer" or "" (not signed in); surface:
    "page", "api", "ws" or "station"; remote: the sender's address; command_id: unique per command (the
    API returns it in X-Command-Id); accepted: False when refused, and message then says why; result: what
    an accepted command returned, as text (an obstacle id, the MAVs told to land), else None.
    """

    time_s: Real
    utc: str
    command: str
    arguments: dict[str, Scalar]
    operator: str
    role: str
    surface: str
    remote: str
    command_id: str
    accepted: bool
    message: str = ""
    result: str | None = None

    @property
    def outcome(self) -> str:
        return "accepted" if self.accepted else "refused"


@dataclass(frozen=True)
class LogEnd:
    """Written when the log is closed cleanly (a log without it ended in a crash or a kill): the last mission
    time, and the records and write failures counted by the writer."""

    time_s: Real
    samples: int
    audit_records: int
    write_errors: int
    stats: dict[str, float] = field(default_factory=dict)


HEADER = TypeAdapter(LogHeader)
AUDIT = TypeAdapter(AuditRecord)
END = TypeAdapter(LogEnd)


def scalar(value: Any) -> Scalar:
    """An operator's argument as a log scalar: bools, ints, finite floats and strings as they are, anything
    else (NaN, infinity, objects) as its text: the log shows what was sent, even when it was nonsense."""
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value)
    return value if isinstance(value, bool | int | float | str) else repr(value)


def check_format(header: LogHeader) -> None:
    """RecordError unless `header` is one of a flight log this reader can read (format and version)."""
    if header.format != FORMAT:
        raise RecordError(f"not a skyring flight log (format {header.format!r}, expected {FORMAT!r})")
    if header.version != VERSION:
        raise RecordError(
            f"flight-log version {header.version!r} is not supported (this skyring reads version {VERSION})"
        )
