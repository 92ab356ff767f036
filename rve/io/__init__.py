"""Input/output that every layer may use: atomic writes (``atomic``), provenance (log
files, package version, JSON-safe conversion, CF global attributes: ``provenance``) and
VTK tube meshes and headless renders (``vtk``). Imports no other rve layer."""
__all__ = ["atomic", "provenance", "vtk"]
