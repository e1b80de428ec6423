"""The Zenoh session of one skyring process, and `Bus`: stamped publishing and guarded subscriptions on it.

Configuration (`NetConfig`): peer mode; explicit endpoints to connect to and listen on (`tcp/HOST:PORT`,
`udp/...`, `tls/...`); multicast scouting on or off (on by default, as on a field network; tests turn it off);
and `--zenoh-config FILE`, a Zenoh JSON5 configuration read first (TLS/mTLS certificates, access control,
anything Zenoh offers), to which the explicit options are then applied. Peers gossip the endpoints they
know, so agents that each reach the station also find each other and keep talking when the station is gone.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from vehicles.net import realtime, wire
from vehicles.net.guard import MessageGuard, Received
from vehicles.net.keys import check_team

log = logging.getLogger(__name__)

DEFAULT_TEAM = "skyring"
_SCHEMES = ("tcp/", "udp/", "tls/", "quic/", "ws/", "unixsock-stream/")


@dataclass(frozen=True)
class NetConfig:
    """How a process joins the team's network. connect/listen: Zenoh endpoints such as tcp/10.0.0.1:7447;
    multicast_scouting: find peers on the LAN by multicast; config_file: a Zenoh JSON5 file applied first."""

    team: str = DEFAULT_TEAM
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    multicast_scouting: bool = True
    config_file: Path | None = None

    def __post_init__(self) -> None:
        check_team(self.team)
        for endpoint in (*self.connect, *self.listen):
            if not endpoint.startswith(_SCHEMES) or ":" not in endpoint:
                raise ValueError(f"{endpoint!r} is not a Zenoh endpoint; expected e.g. tcp/192.168.1.10:7447")
        if self.config_file is not None and not Path(self.config_file).is_file():
            raise ValueError(f"Zenoh configuration file {self.config_file} does not exist")

    def zenoh_config(self):
        """The zenoh.Config for this process."""
        import zenoh

        config = zenoh.Config.from_file(str(self.config_file)) if self.config_file else zenoh.Config()
        config.insert_json5("mode", '"peer"')
        config.insert_json5("scouting/multicast/enabled", "true" if self.multicast_scouting else "false")
        if self.connect:
            config.insert_json5("connect/endpoints", json.dumps(list(self.connect)))
        if self.listen:
            config.insert_json5("listen/endpoints", json.dumps(list(self.listen)))
        return config


def boot_stamp() -> int:
    """This incarnation's boot stamp: UTC nanoseconds now (a restarted process gets a larger one)."""
    return time.time_ns()


@dataclass
class _Counter:
    value: int = 0
    lock: threading.Lock = field(default_factory=threading.Lock)

    def next(self) -> int:
        with self.lock:
            self.value += 1
            return self.value


class Bus:
    """One Zenoh session: publish bodies stamped with this process's header, subscribe through a guard.

    sender: this process's id (0 for the station); senders it publishes for (a simulated world plays every
    vehicle) pass `sender=` per message. is_member: which sender ids the guard admits. clock: UTC seconds.
    handler_priority: the SCHED_FIFO priority Zenoh's callback threads take at their first message (0: the
    normal scheduler; `realtime.handler_priority`).
    """

    def __init__(
        self,
        config: NetConfig,
        *,
        sender: int,
        is_member: Callable[[int], bool],
        clock: Callable[[], float] = time.time,
        session=None,
        handler_priority: int = 0,
    ) -> None:
        import zenoh

        self.config = config
        self.team = config.team
        self.sender = int(sender)
        self.boot = boot_stamp()
        self.clock = clock
        self.guard = MessageGuard(team=config.team, is_member=is_member, clock=clock)
        self._session = session if session is not None else zenoh.open(config.zenoh_config())
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._subscribers: list[zenoh.Subscriber] = []
        self._seq: dict[tuple[int, str], _Counter] = {}
        self._lock = threading.Lock()
        self.sent_bytes = 0
        self.sent_messages = 0
        self.handler_errors = 0
        self._closed = False
        realtime.check_priority(handler_priority)
        self._handler_priority = handler_priority
        self._raised_threads: set[int] = set()

    def publish(self, key: str, body: wire.Body, *, sender: int | None = None) -> int:
        """Stamp and publish `body` on `key`; returns the bytes sent (0 when closed)."""
        sender = self.sender if sender is None else int(sender)
        kind = wire.KIND_OF[type(body)]
        with self._lock:
            if self._closed:
                return 0
            counter = self._seq.setdefault((sender, kind), _Counter())
            publisher = self._publishers.get(key)
            if publisher is None:
                publisher = self._publishers[key] = self._session.declare_publisher(key)
        payload = wire.encode(
            team=self.team, sender=sender, boot=self.boot, seq=counter.next(), stamp=self.clock(), body=body
        )
        publisher.put(payload)
        with self._lock:
            self.sent_bytes += len(payload)
            self.sent_messages += 1
        return len(payload)

    def put_raw(self, key: str, payload: bytes) -> None:
        """Publish bytes as they are (tests and tools that forge or replay messages)."""
        self._session.put(key, payload)

    def subscribe(self, key: str, handler: Callable[[Received], None]) -> None:
        """Call handler(message) on Zenoh's thread for every message on `key` the guard admits. A handler that
        raises is counted (`handler_errors`) and logged, never propagated."""

        def on_sample(sample) -> None:
            self._raise_handler_thread()
            try:
                received = self.guard.admit(str(sample.key_expr), sample.payload.to_bytes())
                if received is not None:
                    handler(received)
            except Exception:  # noqa: BLE001 - Zenoh's thread must survive any handler
                self.handler_errors += 1
                log.exception("handling a message on %s failed", key)

        self._subscribers.append(self._session.declare_subscriber(key, on_sample))

    def _raise_handler_thread(self) -> None:
        """Put the calling Zenoh thread under SCHED_FIFO at handler_priority, once per thread. A handler
        holds the interpreter lock; preempted by normal work while it does, it would keep a real-time control
        thread waiting for the lock for a whole time slice."""
        if self._handler_priority == 0:
            return
        ident = threading.get_ident()
        if ident in self._raised_threads:
            return
        self._raised_threads.add(ident)
        refused = realtime.raise_calling_thread(self._handler_priority)
        if refused is not None:
            log.warning("Zenoh's message handlers run under the normal scheduler: %s", refused)

    def peers(self) -> Sequence[str]:
        """The Zenoh ids of the peers this session is connected to."""
        return [str(z) for z in self._session.info.peers_zid()]

    def close(self) -> None:
        """Undeclare everything and close the session (a process must do this before it exits)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        for sub in self._subscribers:
            try:
                sub.undeclare()
            except Exception:  # noqa: BLE001
                pass
        try:
            self._session.close()
        except Exception:  # noqa: BLE001
            log.debug("closing the Zenoh session failed", exc_info=True)
