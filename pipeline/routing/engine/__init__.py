"""The compiled core every routing search shares: sailing a leg in the weather it meets (`leg`), the label
primitives of the label searches (`labels`: growing label stores, the prefix-minimum look-up, the time spans) and
the bounds they prune with (`bounds`: the finish bounds as one `FinishBounds`, the least cost of what a label can
still become). A search (dp, dp_grid, bfoa, engine_limits, ...) is built over these; what is compiled and shared
between searches belongs here, what one search alone needs stays with it.
"""
