"""Operator-facing formation parameters and the bundle of every controller parameter.

Each concept's own parameters live beside it (`MpcParams` in mpc.py, `FieldParams` in fields.py,
`TrackerParams` in tracker.py, `NoiseParams` in measurement.py); this module gathers them so a MAV's whole
controller configuration is one frozen value.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

from controller.baselines import PriceParams
from controller.fields import FieldParams
from controller.measurement import NoiseParams
from controller.mpc import MpcParams
from controller.reference import ReferenceParams
from controller.separation import SeparationParams
from controller.tracker import TrackerParams

MAX_TEAM_SIZE = 16
"""The largest team the controller is tuned and tested for (K = 2..16). At the paper's d_des = 8 m the ring of
16 MAVs leaves 3.12 m between neighbours, just outside a fresh teammate-repulsion d_max of 3.0 m; a 17th MAV
would put the finished formation inside it (docs/method.md#avoidance-guarantee)."""


class ParameterError(ValueError):
    """A parameter out of its range: `field` names it, `reason` says what is allowed and what was given."""

    def __init__(self, field: str, reason: str) -> None:
        super().__init__(f"{field} {reason}")
        self.field = field
        self.reason = reason


class Method(str, Enum):  # noqa: UP042 - str() and format() must stay as they are in reports
    """Formation method: the paper's (`active`) or one of its two baselines (docs/method.md#baselines)."""

    ACTIVE = "active"
    DQMPC = "dqmpc"
    PRICE = "price"


@dataclass(frozen=True)
class FormationParams:
    """What the operator sets while flying.

    d_des_m: desired horizontal distance of every MAV from the person (paper: 8 m);
    h_des_m: desired height of every MAV above the person (paper: 8 m).
    """

    d_des_m: float = 8.0
    h_des_m: float = 8.0


@dataclass(frozen=True)
class ControllerParams:
    """Everything one MAV's controller needs, with the defaults of docs/method.md."""

    method: Method = Method.ACTIVE
    mpc: MpcParams = field(default_factory=MpcParams)
    fields: FieldParams = field(default_factory=FieldParams)
    tracker: TrackerParams = field(default_factory=TrackerParams)
    noise: NoiseParams = field(default_factory=NoiseParams)
    reference: ReferenceParams = field(default_factory=ReferenceParams)
    price: PriceParams = field(default_factory=PriceParams)
    separation: SeparationParams = field(default_factory=SeparationParams)
