"""What a probe solve returns and what every probe solve shares (the pinned terminal
probes of ``rve.homogenisation.probes`` and the periodic field probes of
``rve.homogenisation.periodic_probes``).

* :class:`ProbeResult` -- one probe's voltage, terminal currents, temperatures and
  diagnostics; ``record()`` is its entry of an ``rve.tables`` record;
* :func:`conduction_material` -- the beam material with the conductivities of ``cfg.material``;
* :func:`_length_weights` -- nodal weights of the reference fibril length (lumped).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from ..model import BeamMaterial

__all__ = ["ProbeResult", "conduction_material"]


@dataclass
class ProbeResult:
    name: str
    voltage: float
    current_plus: float
    current_minus: float
    leak: float
    conservation_error: float
    temperature_max: float = float("nan")
    temperature_mean: float = float("nan")
    newton_iterations: dict = field(default_factory=dict)
    wall_s: dict = field(default_factory=dict)
    connected: bool = True
    #: further entries of the record (a periodic field probe's per-width figures)
    extra: dict = field(default_factory=dict)
    V: Optional[np.ndarray] = field(default=None, repr=False)
    T: Optional[np.ndarray] = field(default=None, repr=False)

    @property
    def resistance(self) -> float:
        i = 0.5 * (self.current_plus - self.current_minus)
        return self.voltage / i if i != 0 else float("inf")

    def record(self) -> dict:
        """The probe's entry of an ``rve.tables`` record (+ diagnostics)."""
        return {"voltage": self.voltage, "current": {"+": self.current_plus, "-": self.current_minus},
                "temperature_max": self.temperature_max, "temperature_mean": self.temperature_mean,
                "leak_current": self.leak, "conservation_error": self.conservation_error,
                "resistance": self.resistance, "connected": self.connected, "newton_iterations": self.newton_iterations,
                "wall_s": self.wall_s, **self.extra}


def conduction_material(cfg) -> BeamMaterial:
    m = cfg.material
    return BeamMaterial(m.youngs_modulus, m.poisson_ratio, m.density, electrical_conductivity=m.electrical_conductivity,
                        thermal_conductivity=m.thermal_conductivity)


def _length_weights(mesh) -> np.ndarray:
    """Nodal weights int N_a ds of the reference fibril length (lumped: each element's
    length shared equally by its nodes)."""
    nn = mesh.conn.shape[1]
    return np.bincount(mesh.conn.ravel(), weights=np.repeat(mesh.elem_length / nn, nn), minlength=mesh.n_nodes)
