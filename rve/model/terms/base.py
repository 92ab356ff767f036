"""The term protocol: what a physics term gives the assembler (docs/coupled_fields.md,
"How the model is assembled (terms)").

Contract
--------
A term is an object with a ``name`` and any of these methods (the defaults of ``Term`` do
nothing, so a term implements only what it has):

* ``bind(pattern)``: called once by the assembler with its ``ElementPattern`` (a term that
  acts on assembled arrays finds its slots there, a constant operator is assembled here);
* ``mass_blocks()`` -> ``{(row_field, col_field): (E, ...)}``: element blocks of M;
* ``forms(state, jacobian)`` -> ``(R, K)``: ``R = {field: (E, nn, k) or reshapeable}``
  residual blocks, ``K = {(row_field, col_field, "x" | "w"): (E, nn, k_row, nn, k_col) or
  reshapeable}`` tangent blocks (``"x"``: derivative by the positions x, ``"w"`` by w:
  velocities, T, V). ``state`` is an ``ElementState`` (lazy element arrays of x, w, t).
  Each key appears at most once per term; the assembler adds the terms in list order;
* ``operator()`` -> a constant CSR matrix C on the pattern, or None: ``F += C w`` and
  ``Fw += C`` after the element sum (no per-call assembly of a constant block);
* ``add_to_residual(F, w)`` / ``add_to_tangent(Fx, Fw)``: terms acting on the assembled
  arrays (in place), after the element sum and the operators (circuits).

Terms of pair elements (contact) have their own protocol (``rve.model.terms.contact``).
"""
from __future__ import annotations

__all__ = ["Term"]


class Term:
    name = "term"

    def bind(self, pattern) -> None:
        return None

    def mass_blocks(self) -> dict:
        return {}

    def forms(self, state, jacobian: bool):
        return {}, {}

    def operator(self):
        return None

    def add_to_residual(self, F, w) -> None:
        return None

    def add_to_tangent(self, Fx, Fw) -> None:
        return None
