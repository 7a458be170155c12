"""The compiled core every routing search shares: sailing a leg in the weather it meets (`leg`), the label
primitives of the label searches (`labels`: growing label stores, the prefix-minimum look-up, the time spans), the
bounds they prune with (`bounds`: the finish bounds as one `FinishBounds`, the least cost of what a label can still
become), the one relaxation step they take (`relax`), and the searches themselves: the label DP (`label_search`),
the grid DP with waits (`grid_search`), the engine plans of a fixed route under a hold (`hold_search`) and the
BFOA's swarm (`swarm`) with its engine timing (`timing`) and random walks (`random_walk`). The solvers (dp.py, dp_grid.py, bfoa.py,
engine_limits.py, ...) are plain-Python strategies over these: they build the bounds, choose the search and its
mode, and read its answer.
"""
