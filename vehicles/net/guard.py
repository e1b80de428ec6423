"""The gate every received message passes: size, schema, version, team, sender, key and replay checks.

`MessageGuard.admit` never raises: a message it refuses is counted under its `Reason` and dropped, so a
malformed, foreign, oversized or replayed message can never reach (or stop) a control loop. It is called from
Zenoh's own threads, so it holds a lock.

Replay: each (sender, kind) must show a strictly growing (boot, seq): a later incarnation of the sender
(a restarted process has a larger boot stamp) starts afresh; an older one, or an old sequence number of the
current one, is a replay. This stops duplicates and replays of captured traffic by anyone who cannot write
a newer (boot, seq); authenticity itself (who may publish at all) is Zenoh's job: TLS/mTLS and access
control in the `--zenoh-config` file (docs/agents.md#security).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum

import msgspec

from vehicles.net import wire
from vehicles.net.keys import parse_key


class Reason(StrEnum):
    """Why a message was refused."""

    OVERSIZED = "oversized"  # more than wire.MAX_MESSAGE_BYTES
    MALFORMED = "malformed"  # not a header of the schema, or a body that does not decode as its kind
    VERSION = "version"  # another wire version
    TEAM = "team"  # another team (in the header or the key)
    UNKNOWN_SENDER = "unknown_sender"  # a sender id that is not a member of this team
    MISMATCHED = "mismatched"  # the key's id or topic does not match the header's sender or kind
    REPLAYED = "replayed"  # (boot, seq) not newer than the last one from that sender and kind
    INVALID = "invalid"  # decodes, but its values are refused (non-finite, wrong shapes)
    OVERFLOW = "overflow"  # accepted but dropped: the receiver's queue was full


@dataclass(frozen=True, eq=False)
class Received:
    """An admitted message: its header, its decoded body, the key it came on, and when (receiver's UTC)."""

    header: wire.Header
    body: msgspec.Struct
    key: str
    received_s: float


class MessageGuard:
    """Admits messages for `team` from the senders `is_member` accepts (vehicle ids; 0 is the station)."""

    def __init__(self, *, team: str, is_member: Callable[[int], bool], clock: Callable[[], float]) -> None:
        self.team = team
        self._is_member = is_member
        self._clock = clock
        self._lock = threading.Lock()
        self._last: dict[tuple[int, str], tuple[int, int]] = {}
        self._counts = dict.fromkeys(Reason, 0)
        self.accepted = 0

    def admit(self, key: str, payload: bytes) -> Received | None:
        """The decoded message, or None when refused (and counted)."""
        try:
            return self._admit(str(key), payload)
        except Exception:  # noqa: BLE001 - nothing received may raise into a loop; count it as malformed
            self.count(Reason.MALFORMED)
            return None

    def count(self, reason: Reason) -> None:
        """Count a refusal decided after admission (e.g. values a domain type refused: INVALID)."""
        with self._lock:
            self._counts[reason] += 1

    def counts(self) -> dict[str, int]:
        """Refusals so far by reason (every reason present, zeros included)."""
        with self._lock:
            return {r.value: n for r, n in self._counts.items()}

    @property
    def rejected(self) -> int:
        with self._lock:
            return sum(self._counts.values())

    def _admit(self, key: str, payload: bytes) -> Received | None:
        if len(payload) > wire.MAX_MESSAGE_BYTES:
            return self._refuse(Reason.OVERSIZED)
        try:
            header = wire.HEADER_DECODER.decode(payload)
        except msgspec.DecodeError:
            return self._refuse(Reason.MALFORMED)
        if header.v != wire.WIRE_VERSION:
            return self._refuse(Reason.VERSION)
        parsed = parse_key(key)
        if header.team != self.team or (parsed is not None and parsed.team != self.team):
            return self._refuse(Reason.TEAM)
        if not self._is_member(header.sender):
            return self._refuse(Reason.UNKNOWN_SENDER)
        if parsed is None or parsed.topic != header.kind or parsed.vehicle_id != header.sender:
            return self._refuse(Reason.MISMATCHED)
        decoder = wire.BODY_DECODERS.get(header.kind)
        if decoder is None:
            return self._refuse(Reason.MALFORMED)
        try:
            body = decoder.decode(header.body)
        except msgspec.DecodeError:
            return self._refuse(Reason.MALFORMED)
        with self._lock:
            slot = (header.sender, header.kind)
            last = self._last.get(slot)
            if last is not None and (header.boot, header.seq) <= last:
                self._counts[Reason.REPLAYED] += 1
                return None
            self._last[slot] = (header.boot, header.seq)
            self.accepted += 1
        return Received(header=header, body=body, key=key, received_s=self._clock())

    def _refuse(self, reason: Reason) -> None:
        self.count(reason)
        return None
