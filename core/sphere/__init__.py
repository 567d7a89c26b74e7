"""Sphere mode: conformal maps of closed genus-0 meshes to the unit sphere, the Moebius choice, the
spherical UV layout and geodesics through two stereographic charts."""
