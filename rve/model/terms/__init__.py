"""The physics terms of the fibril model, one module per term (protocol: ``base.Term``;
docs/coupled_fields.md "How the model is assembled (terms)", docs/contact.md)."""
from .base import Term
from .circuits import Circuits
from .contact import ContactParams, ContactTerm
from .elasticity import Elasticity, beam_strain_energy
from .electromagnetic import Electromagnetic
from .heat import HeatConduction
from .inertia import Damping, Inertia
from .lorentz import PrescribedLorentz

__all__ = ["Term", "Elasticity", "PrescribedLorentz", "HeatConduction", "Electromagnetic", "Damping", "Inertia",
           "Circuits", "ContactParams", "ContactTerm", "beam_strain_energy"]
