"""Moved: the model with contact is ``rve.model.ContactSystem`` (rve/model/contact_model.py),
the contact term ``rve.model.terms.contact`` (docs/contact.md). This module only re-exports
them for the callers of the other branches until the merge (the lead deletes it)."""
from ..model import ContactParams, ContactSystem, beam_strain_energy

__all__ = ["ContactParams", "ContactSystem", "beam_strain_energy"]
