"""Geometry the method stands on: rotations, closest point on a mesh, rasterisation, UV."""
