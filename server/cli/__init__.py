"""The `skyring` command line. Each command lives in its own module; this file only wires them up.

Commands are registered by (name, "module:function"); the module is imported only when its command runs, so
`skyring --help` stays fast and a command's heavy imports (viser, filterpy, mavsdk) load only when needed.
"""

from __future__ import annotations

import importlib
import sys

import typer

app = typer.Typer(
    name="skyring",
    help="Active-perception formation control for multirotor teams: ground station, simulator, experiments.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


@app.callback()
def _root() -> None:
    """A group callback keeps typer in sub-command mode even when main() registers a single command."""


# name -> "module:function". The function is a typer command (typed keyword parameters with typer.Option).
COMMANDS: dict[str, str] = {
    "serve": "server.cli.serve:serve",
    "sim": "server.cli.sim:sim",
    "bench": "server.cli.bench:bench",
    "experiment": "server.cli.experiment:experiment",
    "replay": "server.cli.replay:replay",
    "agent": "server.cli.agent:agent",
    "detect": "server.cli.detect:detect",
}


def _register(name: str, target: str) -> None:
    module_name, func_name = target.split(":")
    module = importlib.import_module(module_name)
    app.command(name=name)(getattr(module, func_name))


def main() -> None:
    """Entry point: register the invoked command only (all of them for --help), then run typer."""
    wanted = [a for a in sys.argv[1:2] if a in COMMANDS]
    for name in wanted or list(COMMANDS):
        _register(name, COMMANDS[name])
    app()


if __name__ == "__main__":
    main()
