"""Fleet operation planning: which vessel lifts which cargo contract, in which order, with which ballast legs
between, so that every load window is met at the least cost; the planned legs then become voyages that the
nightly routes just in time.

inputs.py      validation of contracts.csv, vessel availability and ports (rows good or refused with a reason)
sea_distances  port-to-port distances along the routing graph's shortest sea route
fuel.py        fuel per nautical mile laden and in ballast from a vessel's performance model
problem.py     the planning problem: vessels, contracts, distances → per-vessel arcs, times and costs
milp.py        the exact planner (scipy.optimize.milp / HiGHS)
brute.py       the brute-force reference for small instances (tests, bench)
voyages.py     a plan's legs as voyage rows
"""
