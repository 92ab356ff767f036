"""The fibril model as a sum of physics terms (docs/coupled_fields.md "How the model is
assembled (terms)"; contact: docs/contact.md).

``materials`` (materials, boundary conditions, coupling flags), ``terms/`` (one module per
physics term), ``assembler`` (one assembler of terms through the dof layout), ``beam_model``
(``BeamModel``: the terms a scene declares), ``contact_model`` (``ContactSystem``: a model
with the contact term), ``post`` (``RowScaledSystem``, ``ThermalPostSystem``).
"""
from .beam_model import BeamModel
from .contact_model import ContactParams, ContactSystem
from .materials import BeamMaterial, CircuitBC, Couplings, DirichletBC, PrescribedCurrent, feedback_from_temperature
from .post import RowScaledSystem, ThermalPostSystem
from .terms.elasticity import beam_strain_energy

__all__ = ["BeamMaterial", "DirichletBC", "PrescribedCurrent", "Couplings", "CircuitBC", "BeamModel",
           "feedback_from_temperature", "RowScaledSystem", "ThermalPostSystem", "ContactParams", "ContactSystem",
           "beam_strain_energy"]
