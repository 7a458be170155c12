"""The science of jitroute, pure and testable without Prefect.

Conventions (everywhere in jitroute):
- wind and waves: directions are *coming-from* (meteorological), degrees clockwise from north;
- currents: *going-to* (oceanographic) u (east) / v (north) components;
- SI in the weather cube (m/s, m, s); knots and nautical miles in routing; tonnes for fuel;
- UTC everywhere; longitudes 0..360 east in the cube, -180..180 accepted at the edges.
"""

from pipeline import compile_cache as _compile_cache

_compile_cache.configure()  # before any kernel is defined: numba's cache keyed on these sources (see compile_cache)
