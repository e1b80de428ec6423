"""`python -m server.cli` runs the `skyring` command line."""

from server.cli import main

main()
