"""The `skyring` command line. Each command lives in its own module; this file only wires them up.

Commands are registered by (name, "module:function"); the module is imported only when its command runs, so
`skyring --help` stays fast and a command's heavy imports (viser, filterpy, mavsdk) load only when needed.
A bad option ends any command with exit status 2 and exactly one line on stderr, "Error: ..." naming the
option (typer's own error panel takes a dozen lines, too many for a field terminal or a script's log).
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
    "users": "server.cli.users:users",
    "agent": "server.cli.agent:agent",
    "detect": "server.cli.detect:detect",
}


_registered: set[str] = set()


def _register(name: str, target: str) -> None:
    """Add command `name` to the app once (main() may run more than once in one process, as in tests)."""
    if name in _registered:
        return
    _registered.add(name)
    module_name, func_name = target.split(":")
    module = importlib.import_module(module_name)
    app.command(name=name)(getattr(module, func_name))


def main() -> None:
    """Entry point: register the invoked command only (all of them for --help), then run typer."""
    wanted = [a for a in sys.argv[1:2] if a in COMMANDS]
    for name in wanted or list(COMMANDS):
        _register(name, COMMANDS[name])
    try:
        code = app(standalone_mode=False)
    except typer.Abort:
        typer.echo("Aborted.", err=True)
        sys.exit(1)
    except typer.TyperException as exc:  # a usage error: one line, the option named
        format_message = getattr(exc, "format_message", None)
        typer.echo(f"Error: {format_message() if format_message else exc}", err=True)
        sys.exit(getattr(exc, "exit_code", 2))
    sys.exit(code if isinstance(code, int) else 0)


if __name__ == "__main__":
    main()
