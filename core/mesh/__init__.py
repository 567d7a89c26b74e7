"""Mesh basics: geometry, operators, topology, validation."""
