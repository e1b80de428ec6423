"""Command-line options shared by the `skyring` commands, typed with their ranges.

typer (click) checks each option's type and range before a command runs; what spans several options (a
warm-up shorter than the run, a re-planning rate below the control rate) is checked by the settings
(server/settings.py), whose `ParameterError` names the field: `OPTION_OF_FIELD` turns it into the option.
"""

from __future__ import annotations

import math
from enum import StrEnum
from typing import Annotated, Any

import typer

from controller.params import Method
from server.settings import MAX_VEHICLES, RATE_RANGE_HZ
from vehicles.sim.trees import TreeSpec


class PersonMode(StrEnum):
    """`--person`: vehicles.sim.person.PERSON_MODES as a choice."""

    paper = "paper"
    random = "random"
    still = "still"


class StartLayout(StrEnum):
    """`--start`: vehicles.sim.scenario.START_LAYOUTS as a choice."""

    ring = "ring"
    cluster = "cluster"


# settings field -> command-line option, for errors that only the settings can find
OPTION_OF_FIELD = {
    "vehicles": "--vehicles",
    "seed": "--seed",
    "method": "--method",
    "trees": "--trees",
    "person": "--person",
    "comm_loss": "--comm-loss",
    "start": "--start",
    "d_des_m": "--d-des",
    "h_des_m": "--h-des",
    "rate_hz": "--rate",
    "replan_hz": "--replan-rate",
    "duration_s": "--duration",
    "warmup_s": "--warmup",
}


def tree_spec(text: str) -> str:
    """`--trees`: "paper", "none" or a number of random trees, in its canonical spelling."""
    try:
        return str(TreeSpec.parse(text))
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from None


def positive_number(text: str) -> float:
    """A finite number above zero."""
    try:
        value = float(text)
    except ValueError:
        raise typer.BadParameter(f"{text!r} is not a number") from None
    if not (math.isfinite(value) and value > 0.0):
        raise typer.BadParameter(f"must be a number above 0, got {text}")
    return value


def positive(help_text: str, metavar: str) -> Any:
    """A float option that must be finite and above zero."""
    return typer.Option(metavar=metavar, help=help_text, parser=positive_number)


Vehicles = Annotated[
    int, typer.Option(min=1, max=MAX_VEHICLES, metavar="K", help=f"number of MAVs (1 to {MAX_VEHICLES})")
]
Seed = Annotated[int, typer.Option(min=0, metavar="N", help="seed of every random choice")]
MethodOption = Annotated[Method, typer.Option(case_sensitive=False, help="formation method")]
Trees = Annotated[
    str,
    typer.Option(
        parser=tree_spec, metavar="{paper,none,N}", help="the paper's 13 trees, none, or N random ones"
    ),
]
Person = Annotated[
    PersonMode,
    typer.Option(case_sensitive=False, help="the paper's walk, a random walker, or standing still"),
]
Rate = Annotated[
    float,
    typer.Option(
        min=RATE_RANGE_HZ[0],
        max=RATE_RANGE_HZ[1],
        metavar="HZ",
        help="control rate (the paper: 100 Hz)",
    ),
]
