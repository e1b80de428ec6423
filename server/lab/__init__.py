"""Simulation runs and what is made of them: the deterministic runner, metrics, the paper's experiments, their
report and figures, and the benchmarks."""
