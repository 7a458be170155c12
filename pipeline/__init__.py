"""The science of jitroute, pure and testable without Prefect.

Conventions (everywhere in jitroute):
- wind and waves: directions are *coming-from* (meteorological), degrees clockwise from north;
- currents: *going-to* (oceanographic) u (east) / v (north) components;
- SI in the weather cube (m/s, m, s); knots and nautical miles in routing; tonnes for fuel;
- UTC everywhere; longitudes 0..360 east in the cube, -180..180 accepted at the edges.
"""
