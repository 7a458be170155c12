"""Fleet operation planning: which vessel lifts which cargo contract, in which order, with which ballast legs
between, so that every load window is met at the least cost; the planned legs then become voyages that the
nightly routes just in time.

inputs.py      validation of contracts.csv, vessel availability and ports (rows good or refused with a reason)
sea_distances  port-to-port distances along the routing graph's shortest sea route
fuel.py        fuel per nautical mile laden and in ballast from a vessel's performance model
problem.py     the planning problem: vessels, contracts, distances → per-vessel arcs, times and costs
routes.py      every feasible contract sequence per vessel, best order per set (the MILP's columns)
milp.py        the planner: set partitioning on HiGHS (scipy.optimize.milp); the arc-flow model for a bound
colgen.py      column generation for fleets too big to enumerate: pricing, with a proven lower bound
master_lp.py   the set-partitioning LP kept warm in one HiGHS instance between solves
branch_price   branch-and-price on vessel–contract pairs: raises the LP bound, dives for plans
local_search   moves of single contracts between vessels and the spot market, after each dive
gap_columns    every column whose reduced cost is within the gap between plan and bound (the exact finish)
brute.py       the brute-force reference for small instances (tests, bench)
voyages.py     a plan's legs as voyage rows
"""
