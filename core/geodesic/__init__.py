"""Geodesic distances by fast marching on the conformal plane (scikit-fmm, or the numpy sweep)."""
