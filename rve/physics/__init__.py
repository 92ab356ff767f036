"""Element forms: pure functions of element arrays (residuals and exact tangents) for the
Neo-Hookean beam, the Lorentz force, current conservation, heat and contact
(docs/engine.md, docs/coupled_fields.md, docs/contact.md). Imports only ``rve.fem``. The
modules are the API (imported on demand)."""
__all__ = ["elasticity", "beam_forms", "electric_forms", "thermal_forms", "contact_forms"]
