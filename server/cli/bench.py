"""`skyring bench`: benchmarks that print medians and ratios. Speed targets live here, never in tests."""

from __future__ import annotations

import importlib
from typing import Annotated

import typer

# suite name -> "module:function"; each function takes (repeats: int) and prints its own table.
SUITES: dict[str, str] = {
    "controller": "server.lab.bench_controller:run",
    "sim": "server.lab.bench_sim:run",
    "links": "server.lab.bench_links:run",
    "agents": "server.lab.bench_agents:run",
    "detect": "server.lab.bench_detect:run",
    "protocol": "server.lab.bench_protocol:run",
}


def bench(
    suite: Annotated[
        str, typer.Argument(help="controller, sim, links, agents, detect, protocol, or all")
    ] = "all",
    repeats: Annotated[int, typer.Option(min=1, help="repetitions per measurement")] = 200,
) -> None:
    """Run a benchmark suite and print medians, p99 and ratios."""
    names = list(SUITES) if suite == "all" else [suite]
    for name in names:
        if name not in SUITES:
            raise typer.BadParameter(
                f"unknown suite {name!r}; choose from {', '.join(SUITES)} or all", param_hint="SUITE"
            )
        module_name, func_name = SUITES[name].split(":")
        getattr(importlib.import_module(module_name), func_name)(repeats=repeats)
