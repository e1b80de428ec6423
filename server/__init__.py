"""The ground station: fleet supervision, operator commands, FastAPI, flight log and replay, the `skyring`
command line, experiment and benchmark runners."""
