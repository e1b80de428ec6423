"""The flight-log header the tests write: a 3-MAV `serve` run, with any field replaced by a keyword."""

from __future__ import annotations

import dataclasses

from server.flightlog.records import LogHeader


def log_header(**overrides: object) -> LogHeader:
    """A `serve` header (3 MAVs, seed 3, paper trees and person, 20 Hz, 5 Hz samples); `overrides` replace
    fields, e.g. trees="none"."""
    base = LogHeader(
        command="serve",
        vehicles=3,
        seed=3,
        method="active",
        trees="paper",
        person="paper",
        rate_hz=20.0,
        speed=1.0,
        sample_rate_hz=5.0,
        started_utc="2025-06-01T12:00:00+00:00",
    )
    return dataclasses.replace(base, **overrides)
