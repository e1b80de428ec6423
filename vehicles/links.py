"""The radio links between MAVs: every message is broadcast to every teammate.

`SimLinks` emulates a lossy, delayed link in-process: each (message, receiver) pair is delivered independently
with probability 1 - loss, after latency_s plus a uniform jitter in [0, jitter_s] (so messages may arrive out
of order, as they do over Wi-Fi); seeded, hence deterministic. A networked back-end implements the same
two-method `Links` protocol.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from controller.messages import Detection, HorizonPlan

Message = Detection | HorizonPlan


class Links(Protocol):
    """Broadcast messages from one vehicle to its teammates."""

    def send(self, now_s: float, sender_id: int, message: Message) -> None:
        """Broadcast `message` from sender_id at now_s."""

    def receive(self, now_s: float, receiver_id: int) -> tuple[Message, ...]:
        """Every message for receiver_id that has arrived by now_s and was not received yet, oldest first."""
        ...


@dataclass(frozen=True)
class LinkParams:
    """loss: probability in [0, 1] that a message does not reach one receiver; latency_s, jitter_s >= 0."""

    loss: float = 0.0
    latency_s: float = 0.03
    jitter_s: float = 0.02

    def __post_init__(self) -> None:
        if not (math.isfinite(self.loss) and 0.0 <= self.loss <= 1.0):
            raise ValueError(f"link loss must be in [0, 1], got {self.loss}")
        if not (
            math.isfinite(self.latency_s)
            and self.latency_s >= 0
            and math.isfinite(self.jitter_s)
            and self.jitter_s >= 0
        ):
            raise ValueError("link latency_s and jitter_s must be non-negative")


@dataclass(frozen=True)
class LinkStats:
    """Counts of (message, receiver) pairs: sent, delivered (received so far), dropped, pending (in
    flight)."""

    sent: int
    delivered: int
    dropped: int
    pending: int


class SimLinks:
    """In-process broadcast between `vehicle_ids` with seeded loss, latency and jitter."""

    def __init__(
        self, *, vehicle_ids: Iterable[int], params: LinkParams = LinkParams(), rng: np.random.Generator
    ) -> None:
        self._ids = tuple(sorted(int(v) for v in vehicle_ids))
        if len(set(self._ids)) != len(self._ids):
            raise ValueError("vehicle ids must be unique")
        self._p = params
        self._rng = rng
        self._queues: dict[int, list[tuple[float, int, Message]]] = {v: [] for v in self._ids}
        self._seq = 0
        self._sent = self._delivered = self._dropped = 0

    @property
    def params(self) -> LinkParams:
        return self._p

    def send(self, now_s: float, sender_id: int, message: Message) -> None:
        receivers = [v for v in self._ids if v != sender_id]
        if not receivers:
            return
        n = len(receivers)
        self._sent += n
        if self._p.loss >= 1.0:
            self._dropped += n
            return
        # Drawn as numpy draws them, then taken as Python floats (the same arithmetic as on the arrays): every
        # message goes out to every teammate, and numpy's per-call cost would be most of this loop.
        p, queues, seq = self._p, self._queues, self._seq
        draws = self._rng.random(n).tolist()
        jitters = self._rng.random(n).tolist()
        for receiver, draw, jitter in zip(receivers, draws, jitters, strict=True):
            if draw >= p.loss:
                seq += 1
                heapq.heappush(queues[receiver], (now_s + (p.latency_s + p.jitter_s * jitter), seq, message))
        self._dropped += n - (seq - self._seq)
        self._seq = seq

    def receive(self, now_s: float, receiver_id: int) -> tuple[Message, ...]:
        queue = self._queues.get(receiver_id)
        if not queue:
            return ()
        out = []
        while queue and queue[0][0] <= now_s:
            out.append(heapq.heappop(queue)[2])
        self._delivered += len(out)
        return tuple(out)

    def stats(self) -> LinkStats:
        pending = sum(len(q) for q in self._queues.values())
        return LinkStats(sent=self._sent, delivered=self._delivered, dropped=self._dropped, pending=pending)
