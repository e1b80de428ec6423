"""The method itself (Tallamraju et al., RA-L 2019): messages, parameters, measurement model, person tracker,
potential fields, the MPC, and the formation controller with its two baselines.

Pure, synchronous and deterministic: no I/O, no clocks, no asyncio, no globals. Time is always an argument.

Equation numbers cited in this package follow the paper's numbering
(paper/active-perception-formation-control.tex): (1) spherical->Cartesian detection covariance, (2) its
compact form under the paper's assumptions, (3) trace = kappa r^2, (4) MPC cost J_ACT, (5) the MPC problem,
(6) dynamics, (7) state bounds, (8) input bounds, (9) A and B, (10) active-tracking magnitude,
(11) active-tracking sum, (12) teammate repulsion, (13) static-obstacle repulsion, (14) clamping of the
total external input, (15) the avoidance guarantee's d_min and d_max.
"""
