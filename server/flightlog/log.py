"""The flight log of a ground-station run: an MCAP file written through the Foxglove SDK (`channels.py`
lists its channels), which opens in Foxglove with a 3-D panel of the operator's scene.

What a crash loses: the SDK collects messages into a chunk in memory; this writer closes the chunk and hands
it to the kernel (`flush`) every `FLUSH_PERIOD_S` and right after every audit record, and fsyncs the file at
that period, so a kill -9 of the ground station loses at most the last second of state samples and no audit
record (measured by the kill -9 test in `tests/server/flightlog/test_flight_log.py`); a power cut can also
lose what was flushed but not yet fsynced, under a second more. A log cut short has no summary section: the
reader (`server.flightlog.reader`) reads it record by record up to the cut.

Why it never stops the MAVs: every failure to build or write a record is caught here, logged once and
counted (`write_errors`); the ground station keeps flying without the records it could not write.
"""

from __future__ import annotations

import logging
import math
import os
import threading
import time
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import BinaryIO

import foxglove
from foxglove.mcap import MCAPCompression, MCAPWriteOptions

from server.flightlog.channels import SkyringChannels
from server.flightlog.records import AuditRecord, LogEnd, LogHeader
from webui.view import SceneView

log = logging.getLogger(__name__)

DEFAULT_SAMPLE_RATE_HZ = 5.0
FLUSH_PERIOD_S = 0.75  # plus one 0.2 s sample period: a kill -9 loses under a second
CHUNK_SIZE_BYTES = 256 * 1024  # a chunk is closed sooner by the once-a-second flush at the default rates


def default_log_path(now: datetime | None = None) -> Path:
    """runs/flight-<UTC timestamp>.mcap, relative to the working directory."""
    stamp = (now or datetime.now(UTC)).strftime("%Y%m%dT%H%M%SZ")
    return Path("runs") / f"flight-{stamp}.mcap"


def utc_now_iso() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


class FlightLog:
    """Publishes a run on the skyring channels of a Foxglove context and, given a file, records them as MCAP.

    The header goes out at once; then state samples (`record_sample`, every `sample_period_s` of mission
    time), audit records and, on close, the end record. clock: wall clock of the once-a-second flush;
    wall_ns: the log time of each message. Thread-safe. `FlightLog.create(path, ...)` records to a file;
    `FlightLog(header=..., file=None)` only publishes (for a live Foxglove client without a log).
    """

    def __init__(
        self,
        *,
        header: LogHeader,
        file: BinaryIO | None = None,
        name: str = "flight log",
        context: foxglove.Context | None = None,
        clock: Callable[[], float] = time.monotonic,
        wall_ns: Callable[[], int] = time.time_ns,
    ) -> None:
        if not (math.isfinite(header.sample_rate_hz) and header.sample_rate_hz > 0):
            raise ValueError(f"sample rate must be a positive number of Hz, got {header.sample_rate_hz}")
        self.name = name
        self.header = header
        self.sample_period_s = 1.0 / header.sample_rate_hz
        self.context = context or foxglove.Context()
        self._file = file
        self._clock = clock
        self._wall_ns = wall_ns
        self._lock = threading.Lock()
        self._next_sample_s: float | None = None
        self._first_sample_s: float | None = None
        self._last_time_s = math.nan
        self._last_flush = clock()
        self._closed = False
        self.samples = 0
        self.audit_records = 0
        self.write_errors = 0
        self._writer = None
        if file is not None:
            options = MCAPWriteOptions(compression=MCAPCompression.Zstd, chunk_size=CHUNK_SIZE_BYTES)
            self._writer = foxglove.open_mcap(file, context=self.context, writer_options=options)
        self.channels = SkyringChannels(self.context)
        self.channels.log_header(header, self._wall_ns())
        self._flush(sync=True, raise_errors=True)  # a log that cannot even start is refused up front

    @property
    def recording(self) -> bool:
        """Whether this log writes a file (False: it only publishes, to a live Foxglove client)."""
        return self._file is not None

    @classmethod
    def create(cls, path: Path, *, header: LogHeader, context: foxglove.Context | None = None) -> FlightLog:
        """Create `path` (and its folder; an existing file is refused) and write the header; OSError if that
        is impossible."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        file = open(path, "xb")  # noqa: SIM115 - owned by the log, closed in close()
        try:
            return cls(header=header, file=file, name=str(path), context=context)
        except BaseException:
            file.close()
            raise

    # ---- recording (never raises) ------------------------------------------------------------------------
    def sample_due(self, time_s: float) -> bool:
        """Whether a state sample is due at mission time time_s."""
        return self._next_sample_s is None or time_s >= self._next_sample_s - 1e-9

    def record_sample(self, build: Callable[[], SceneView]) -> None:
        """Record the operator's view `build()` makes (a failure to build it counts as a failed write)."""
        try:
            view = build()
        except Exception:  # noqa: BLE001 - recording must never stop the control loop
            self._failed("building a state sample failed")
            return
        with self._lock:
            if self._closed:
                return
            if self._first_sample_s is None and math.isfinite(view.time_s):
                self._first_sample_s = view.time_s
            if self._first_sample_s is not None and math.isfinite(view.time_s):
                k = math.floor((view.time_s - self._first_sample_s) / self.sample_period_s + 1e-6) + 1
                self._next_sample_s = self._first_sample_s + k * self.sample_period_s
            try:
                self.channels.log_view(view, self._wall_ns())
            except Exception:  # noqa: BLE001
                self._count_error("writing a state sample failed", exc_info=True)
                return
            self.samples += 1
            self._last_time_s = view.time_s
            if self._clock() - self._last_flush >= FLUSH_PERIOD_S:
                self._flush(sync=True)

    def record_audit(self, record: AuditRecord) -> None:
        """Record one operator command and its outcome, and hand it to the kernel at once."""
        with self._lock:
            if self._closed:
                return
            try:
                self.channels.log_audit(record, self._wall_ns())
            except Exception:  # noqa: BLE001
                self._count_error("writing an audit record failed", exc_info=True)
                return
            self.audit_records += 1
            if math.isfinite(record.time_s):
                self._last_time_s = record.time_s
            self._flush(sync=self._clock() - self._last_flush >= FLUSH_PERIOD_S)

    def close(self, stats: dict[str, float] | None = None) -> None:
        """Write the end record, finish the MCAP file (summary and footer), fsync and close (idempotent)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            end = LogEnd(
                time_s=self._last_time_s,
                samples=self.samples,
                audit_records=self.audit_records,
                write_errors=self.write_errors,
                stats=dict(stats or {}),
            )
            try:
                self.channels.log_end(end, self._wall_ns())
                if self._writer is not None:
                    self._writer.close()
                if self._file is not None:
                    self._file.flush()
                    os.fsync(self._file.fileno())
            except Exception as exc:  # noqa: BLE001
                self._count_error(f"closing failed: {exc}")
            finally:
                self.channels.close()
                if self._file is not None:
                    self._file.close()

    # ---- internals ----------------------------------------------------------------------------------------
    def _flush(self, *, sync: bool, raise_errors: bool = False) -> None:
        if self._writer is None or self._file is None:
            return
        try:
            self._writer.flush()
            self._file.flush()
            if sync:
                os.fsync(self._file.fileno())
                self._last_flush = self._clock()
        except Exception as exc:  # noqa: BLE001
            if raise_errors:
                raise
            self._count_error(f"writing failed: {exc}")

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
