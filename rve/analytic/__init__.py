"""Analytical reference solutions: the chapter-3 helix of the pinned wire in a field
(docs/analytic_helix.md)."""
__all__ = ["helix"]
