"""Mesh basics: geometry, discrete operators, topology, validation, triangulation and sparse solves.

Nothing here knows about UVs, islands or spheres; the algorithms build on these modules."""
