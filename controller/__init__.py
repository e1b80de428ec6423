"""The method itself (Tallamraju et al., RA-L 2019): messages, parameters, measurement model, person tracker,
potential fields, the MPC, and the formation controller with its two baselines.

Pure, synchronous and deterministic: no I/O, no clocks, no asyncio, no globals. Time is always an argument.
"""
