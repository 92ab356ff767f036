"""Input/output that every layer may use: atomic writes (``atomic``), checksummed files
and their bounded-time verified open (``checksum``), provenance (log files, package
version, JSON-safe conversion, CF global attributes: ``provenance``) and VTK tube meshes
and headless renders (``vtk``). Imports no other rve layer."""
__all__ = ["atomic", "checksum", "provenance", "vtk"]
