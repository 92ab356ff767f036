"""What the friction verification scenes share (``rve.scenes.capstan``,
``rve.scenes.friction_crossing``; docs/contact.md "Friction").

Contract
--------
* ``DeadLoad(system, load)``: ``system`` with a constant external force vector ``load``
  (n,) (``F -> F - load``; the tangents are the system's); every other attribute is the
  system's;
* ``friction_law(section)``: the ``FrictionLaw`` of a validated ``FrictionSection``;
* ``initial_state(mesh, layout)``: x of the natural configuration (velocities zero);
* ``reaction(system, x, dofs)``: the force the supports exert at constrained ``dofs``
  (their residual entries: ``F = 0`` at a free dof, the support force at a held one);
* ``step(system, x, t, newton, scene, phase, index)``: one frictional static step
  (``rve.solvers.frictional``) with the config's Newton settings; a failure is a
  ``SceneFailure`` that carries the last good state. Returns ``(x, result, dissipated)``.
"""
from __future__ import annotations

import numpy as np

from ..model.terms.friction import FrictionLaw
from ..solvers.frictional import frictional_static_step
from ..solvers.system import DeadLoad
from .protocol import SceneFailure

__all__ = ["DeadLoad", "friction_law", "initial_state", "reaction", "step"]


def friction_law(section) -> FrictionLaw:
    mu, stiffness, pairs = section.law_args()
    return FrictionLaw(mu, stiffness, pairs)


def initial_state(mesh, layout) -> np.ndarray:
    x = np.zeros(layout.n)
    layout.as_nodal(x)[:, :9] = mesh.X0
    return x


def reaction(system, x, dofs) -> np.ndarray:
    F, _, _ = system.evaluate(x, np.zeros_like(x), 0.0, jacobian=False)
    return np.asarray(F)[np.asarray(dofs)]


def step(system, x, t, newton, scene: str, phase: str, index: int):
    opts = {"atol": newton.atol, "rtol": newton.rtol, "max_iter": newton.max_iter,
            "label": f"{scene} {phase} step {index}"}
    xs, _, res, dissipated = frictional_static_step(system, x, np.zeros_like(x), t, opts)
    if not res.converged:
        raise SceneFailure(scene, f"static Newton did not converge ({res.reason})", phase=phase, step=index,
                           state={"x": x}, model=system, details={"residuals": list(res.residuals)})
    return xs, res, dissipated
