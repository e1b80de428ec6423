"""Imported once by the experiments' fork server (`experiments._fresh_process_pool`): it loads the
controller's compiled kernels (or compiles them, on a fresh install), so every run's new process, forked from
that server, starts with them in memory instead of loading each from numba's cache on its first call."""

from controller.warmup import warm_up

warm_up()
