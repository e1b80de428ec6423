"""The flight log of a ground-station run: a JSON Lines file that survives a crash, and its reader.

Why it is crash-safe: every record is encoded first and handed to the kernel in one `os.write` of a whole line
(no buffer in this process), so a crash of the ground station loses nothing already recorded; the file is
fsynced at most once a second (and on close) so a power cut loses at most about a second. A line cut short
(power cut, or a failed write on a full disk) is skipped and counted by the reader; after a failed write the
next record starts on a fresh line so one bad write never spoils the next record.

Why it never stops the MAVs: every failure to build or write a record is caught here, logged once and
counted (`write_errors`); the ground station keeps flying without the records it could not write.
"""

from __future__ import annotations

import json
import logging
import math
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Protocol

from server.flightlog.records import (
    LogCommand,
    LogEnd,
    LogHeader,
    LogSample,
    RecordError,
    check_format,
)

log = logging.getLogger(__name__)

DEFAULT_SAMPLE_RATE_HZ = 5.0
SYNC_PERIOD_S = 1.0


class LogSink(Protocol):
    """Where the lines go: `write` takes whole encoded lines, `sync` makes them durable."""

    def write(self, data: bytes) -> None: ...

    def sync(self) -> None: ...

    def close(self) -> None: ...


class FileSink:
    """An append-only file written with unbuffered `os.write` calls (each record reaches the kernel whole)."""

    def __init__(self, path: Path) -> None:
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            written = os.write(self._fd, view)
            view = view[written:]

    def sync(self) -> None:
        os.fsync(self._fd)

    def close(self) -> None:
        os.close(self._fd)


def default_log_path(now: datetime | None = None) -> Path:
    """runs/flight-<UTC timestamp>.jsonl, relative to the working directory."""
    stamp = (now or datetime.now(UTC)).strftime("%Y%m%dT%H%M%SZ")
    return Path("runs") / f"flight-{stamp}.jsonl"


def utc_now_iso() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


class FlightLog:
    """Writes one flight log: the header at once, then commands, periodic samples and, on close, the end.

    sample_period_s: mission seconds between state samples (a sample is taken on the first tick at or after
    each multiple of it from the first sample). clock: wall clock for the once-a-second fsync. Thread-safe.
    Use `FlightLog.create(path, ...)` for a file; the constructor takes any `LogSink`.
    """

    def __init__(
        self,
        *,
        sink: LogSink,
        header: LogHeader,
        name: str = "flight log",
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if not (math.isfinite(header.sample_rate_hz) and header.sample_rate_hz > 0):
            raise ValueError(f"sample rate must be a positive number of Hz, got {header.sample_rate_hz}")
        self.name = name
        self.header = header
        self.sample_period_s = 1.0 / header.sample_rate_hz
        self._sink = sink
        self._clock = clock
        self._lock = threading.Lock()
        self._first_sample_s: float | None = None
        self._next_sample_s: float | None = None
        self._last_time_s = math.nan
        self._last_sync = clock()
        self._broken_line = False
        self._closed = False
        self.samples = 0
        self.commands = 0
        self.write_errors = 0
        self._write(header.to_json(), raise_errors=True)  # a log that cannot even start is refused up front

    @classmethod
    def create(cls, path: Path, *, header: LogHeader) -> FlightLog:
        """Open `path` for appending (creating its folder) and write the header; OSError if impossible."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        sink = FileSink(path)
        try:
            return cls(sink=sink, header=header, name=str(path))
        except BaseException:
            sink.close()
            raise

    # ---- recording (never raises) ------------------------------------------------------------------------
    def sample_due(self, time_s: float) -> bool:
        """Whether a state sample is due at mission time time_s."""
        return self._next_sample_s is None or time_s >= self._next_sample_s - 1e-9

    def record_sample(self, build: Callable[[], LogSample]) -> None:
        """Record the sample `build()` makes (a failure to build it is counted like a failed write)."""
        try:
            sample = build()
        except Exception:  # noqa: BLE001 - recording must never stop the control loop
            self._failed("building a state sample failed")
            return
        with self._lock:
            if self._first_sample_s is None or not math.isfinite(self._first_sample_s):
                self._first_sample_s = sample.time_s
            if math.isfinite(sample.time_s):  # the next multiple of the period after this sample
                k = math.floor((sample.time_s - self._first_sample_s) / self.sample_period_s + 1e-6) + 1
                self._next_sample_s = self._first_sample_s + k * self.sample_period_s
        if self._write(sample.to_json()):
            self.samples += 1
        self._last_time_s = sample.time_s

    def record_command(self, command: LogCommand) -> None:
        """Record one operator command and its outcome."""
        if self._write(command.to_json()):
            self.commands += 1
        self._last_time_s = command.time_s

    def close(self) -> None:
        """Write the end record, fsync and close (idempotent)."""
        with self._lock:
            if self._closed:
                return
        end = LogEnd(
            time_s=self._last_time_s,
            samples=self.samples,
            commands=self.commands,
            write_errors=self.write_errors,
        )
        self._write(end.to_json())
        with self._lock:
            self._closed = True
            for action in (self._sink.sync, self._sink.close):
                try:
                    action()
                except OSError as exc:
                    self._count_error(f"closing failed: {exc}")

    # ---- internals ----------------------------------------------------------------------------------------
    def _write(self, record: dict[str, Any], *, raise_errors: bool = False) -> bool:
        try:
            line = json.dumps(record, allow_nan=False, separators=(",", ":")) + "\n"
        except (TypeError, ValueError):
            if raise_errors:
                raise
            self._failed(f"a {record.get('kind')} record could not be encoded")
            return False
        data = line.encode()
        with self._lock:
            if self._closed:
                return False
            try:
                # a record after a failed write starts on a fresh line: the failed one may have been cut short
                self._sink.write(b"\n" + data if self._broken_line else data)
                self._broken_line = False
                now = self._clock()
                if now - self._last_sync >= SYNC_PERIOD_S:
                    self._last_sync = now
                    self._sink.sync()
            except OSError as exc:
                if raise_errors:
                    raise
                self._broken_line = True
                self._count_error(f"writing failed: {exc}")
                return False
        return True

    def _failed(self, what: str) -> None:
        with self._lock:
            self._count_error(what, exc_info=True)

    def _count_error(self, what: str, *, exc_info: bool = False) -> None:
        self.write_errors += 1
        if self.write_errors == 1:
            log.error(
                "%s: %s; the ground station keeps flying, records that cannot be written are lost (counted)",
                self.name,
                what,
                exc_info=exc_info,
            )


# ---- reading ----------------------------------------------------------------------------------------------


class FlightLogError(ValueError):
    """A file that is not a readable flight log; the message names the file and says why."""


@dataclass(frozen=True)
class FlightRecord:
    """A flight log read back: the header, the samples and commands in file order, the end record (None when
    the run did not stop cleanly), and how many lines were cut short or damaged and skipped."""

    path: Path
    header: LogHeader
    samples: tuple[LogSample, ...]
    commands: tuple[LogCommand, ...]
    end: LogEnd | None
    truncated_lines: int


def read_flight_log(path: Path) -> FlightRecord:
    """Read a flight log. FlightLogError (naming the file) if it is missing, unreadable, does not start with a
    flight-log header or has an unsupported version; lines cut short later on are skipped and counted."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise FlightLogError(f"{path}: cannot read the flight log ({exc.strerror or exc})") from None
    lines = data.split(b"\n")
    try:
        first = json.loads(lines[0])
        check_format(first)
        header = LogHeader.from_json(first)
    except (ValueError, RecordError) as exc:  # json.JSONDecodeError and UnicodeDecodeError are ValueErrors
        reason = str(exc) if isinstance(exc, RecordError) else "the first line is not JSON"
        raise FlightLogError(f"{path}: not a skyring flight log: {reason}") from None
    samples: list[LogSample] = []
    commands: list[LogCommand] = []
    end: LogEnd | None = None
    truncated = 0
    readers: dict[str, Callable[[dict[str, Any]], object]] = {
        "sample": LogSample.from_json,
        "command": LogCommand.from_json,
        "end": LogEnd.from_json,
    }
    for raw in lines[1:]:
        if not raw.strip():
            continue
        try:
            obj = json.loads(raw)
            kind = obj.get("kind") if isinstance(obj, dict) else None
            if kind not in readers:
                continue  # a record kind added by a newer skyring: not ours to judge
            record = readers[kind](obj)
        except (ValueError, RecordError):
            truncated += 1
            continue
        if isinstance(record, LogSample):
            samples.append(record)
        elif isinstance(record, LogCommand):
            commands.append(record)
        elif isinstance(record, LogEnd):
            end = record
    return FlightRecord(
        path=path,
        header=header,
        samples=tuple(samples),
        commands=tuple(commands),
        end=end,
        truncated_lines=truncated,
    )
