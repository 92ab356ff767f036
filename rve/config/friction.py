"""Config models of friction between fibrils: the ``friction`` section and the two friction
verification scenes (``scene: capstan``, ``scene: friction_crossing``; docs/contact.md
"Friction").

Contract
--------
* :class:`FrictionSection`: ``coefficient`` mu of every pair of fibrils (0 <= mu <= 2, 0:
  frictionless), ``pairs`` ``{"family_a-family_b": mu}`` overriding it for the pairs of two
  fibril families (the yarn directions ``warp``, ``weft``, ``loop``; unordered, so
  ``warp-weft`` and ``weft-warp`` are one key), ``stiffness`` eps_T / P* (the tangential
  penalty relative to the normal one, > 0). ``law_args()`` is ``(coefficient, stiffness,
  ((family_a, family_b, mu), ...))``, the arguments of ``rve.model.terms.friction.FrictionLaw``.
* :class:`RVEFrictionSection`: the RVE's ``friction`` section, the above plus ``frame``, the
  frame the anchor of the stick history turns with: ``section`` (default) or ``chord`` (the
  position-based law, the - direction's smallest rotation). ``section`` is the -
  cross-section's frame from the first director of one node of the - element, objective
  under every rotation, on every contact geometry and mesh order (docs/contact.md
  "Objectivity").
* :class:`DynamicFrictionSection`: the induced deformation's ``friction`` section, the RVE's
  (``frame`` included; the dynamic scenes' friction power and checkpoints carry the section
  frame's director part: ``rve.scenes.dynamic_friction``).
* :class:`ImpactFrictionSection`: the impact's ``friction`` section, the above plus
  ``projectile`` mu_p of the projectile-fibril sphere contact (0 <= mu_p <= 2, default 0:
  frictionless; its own key, not the fibrils' coefficient: docs/impact.md "Friction at the
  projectile"), with the same ``stiffness``.
* :class:`CapstanConfig`: a fibril wrapped over a clamped thick straight fibril (a rigid
  cylinder), tension T1 held at one end, the other end pulled until the wrap slides.
  Both scenes' ``contact.geometry`` is ``chord`` (default), ``curve`` or ``smooth``.
* :class:`FrictionCrossingConfig`: one crossing of two fibrils pressed together, one end
  pair moved tangentially in a load-unload cycle (stick, slip, hysteresis).
Named in ``rve.scenes.registry.SCENES``; the scenes are ``rve.scenes.capstan`` and
``rve.scenes.friction_crossing``; the config files configs/scenes/capstan*.yaml and
configs/scenes/crossing*.yaml.
"""
from __future__ import annotations

import math
from typing import Literal

from pydantic import Field, field_validator

from .fields import Angle, Dimensionless, Force, Integer, Length, Penalty, SceneConfig, Section, Stress
from .sections import Newton

__all__ = ["FrictionSection", "RVEFrictionSection", "DynamicFrictionSection", "ImpactFrictionSection", "FIBRIL_FAMILIES", "MAX_FRICTION_COEFFICIENT", "CapstanConfig",
           "FrictionCrossingConfig"]

#: the fibril families a pair coefficient may name (the yarn directions of rve.fabrics)
FIBRIL_FAMILIES = ("warp", "weft", "loop")
#: largest accepted friction coefficient (the same bound as rve.model.terms.friction)
MAX_FRICTION_COEFFICIENT = 2.0


class FrictionSection(Section):
    coefficient: Dimensionless = Field(
        0.0, ge=0, le=MAX_FRICTION_COEFFICIENT, description="Coulomb coefficient mu of every fibril pair (0: none)")
    stiffness: Dimensionless = Field(
        1.0, gt=0, description="tangential penalty eps_T relative to the normal penalty P* (regularisation)")
    pairs: dict[str, Dimensionless] = Field(
        {}, description="mu per pair of fibril families, keys 'warp-weft', 'warp-warp', 'weft-weft', 'loop-loop', ...")

    @field_validator("pairs")
    @classmethod
    def _pair_keys(cls, v):
        seen = {}
        for key, mu in v.items():
            parts = key.split("-")
            if len(parts) != 2 or any(p not in FIBRIL_FAMILIES for p in parts):
                raise ValueError(f"friction pair key {key!r} must be 'a-b' with a, b in {FIBRIL_FAMILIES}")
            if not 0.0 <= mu <= MAX_FRICTION_COEFFICIENT:
                raise ValueError(f"friction.pairs[{key!r}] = {mu} must be in [0, {MAX_FRICTION_COEFFICIENT}]")
            canon = "-".join(sorted(parts))
            if canon in seen:
                raise ValueError(f"friction pair keys {seen[canon]!r} and {key!r} name the same pair")
            seen[canon] = key
        return v

    def law_args(self) -> tuple:
        pairs = tuple((*k.split("-"), float(mu)) for k, mu in self.pairs.items())
        return float(self.coefficient), float(self.stiffness), pairs


class RVEFrictionSection(FrictionSection):
    frame: Literal["chord", "section"] = Field(
        "section", description="frame the stick history's anchor turns with: section (the - cross-section's, from the "
                             "first director of a node of the - element: objective under every rotation) or chord "
                             "(position-based: a twist of a - fibril at a sticking contact reads as slip)")


class DynamicFrictionSection(RVEFrictionSection):
    """The ``friction`` section of the dynamic fabric scenes: the RVE's, ``frame`` included."""


class ImpactFrictionSection(DynamicFrictionSection):
    projectile: Dimensionless = Field(
        0.0, ge=0, le=MAX_FRICTION_COEFFICIENT,
        description="Coulomb coefficient mu_p of the projectile-fibril (sphere) contact (0: none; not the fibrils' "
                    "coefficient: Table 8.2 gives none)")


class CapstanGeometry(Section):
    wrap_angle: Angle = Field(math.pi, gt=0, le=math.pi, description="wrap angle theta of the fibril over the cylinder")
    cylinder_radius: Length = Field(1.0, gt=0, description="radius of the clamped straight fibril (the cylinder)")
    fibril_radius: Length = Field(0.005, gt=0, description="radius of the wrapped fibril")
    tail_length: Length = Field(0.3, gt=0, description="length of each straight tail beyond the wrap")


class CapstanLoad(Section):
    tension: Force = Field(7.854e-4, gt=0, description="T1, the dead load held at the free end")
    pull: Length = Field(0.05, gt=0, description="displacement of the pulled end along its tail")
    steps: Integer = Field(25, ge=1, description="load steps of the pull")
    pretension_steps: Integer = Field(4, ge=1, description="frictionless load steps of T1 before the pull")
    rebuild_every: Integer = Field(5, ge=1, description="contact map rebuilt every k steps (the history carried)")


class CapstanMesh(Section):
    elements_per_radian: Integer = Field(
        60, ge=4, description="elements of the wrapped fibril per radian of wrap (the tails have the same size)")
    order: Integer = Field(1, ge=1, le=4, description="Lagrange element order")


class FrictionContact(Section):
    penalty: Penalty = Field("10 N/mm^2", gt=0, description="P*: penalty line load per unit overlap")
    n_gp: Integer = Field(2, ge=1, description="contact points per element pair")
    geometry: Literal["chord", "curve", "smooth"] = Field(
        "chord", description="contact geometry (rve.model.terms.contact.ContactParams.geometry): the elements' "
                             "chords, their Lagrange centroid curves (two half passes) or the C1 Hermite curve")


class FrictionMaterial(Section):
    youngs_modulus: Stress = Field("1000 MPa", gt=0, description="Young's modulus E of both fibrils")


class CapstanConfig(SceneConfig):
    """Capstan: a fibril wrapped over a rigid cylinder slides at T2/T1 = exp(mu theta)."""

    scene: Literal["capstan"] = Field(description="scene name")
    geometry: CapstanGeometry
    load: CapstanLoad
    mesh: CapstanMesh
    material: FrictionMaterial
    contact: FrictionContact
    friction: FrictionSection
    newton: Newton


class CrossingGeometry(Section):
    radius: Length = Field(0.1, gt=0, description="radius of both fibrils")
    slider_length: Length = Field(4.0, gt=0, description="length of the pressed (sliding) fibril")
    base_length: Length = Field(2.0, gt=0, description="length of the clamped fibril it slides along")
    base_elements: Integer = Field(1, ge=1, description="elements of the clamped fibril")
    base_offset: Length = Field(0.0, description="shift of the clamped fibril along its axis (its nodes move with it)")
    indentation: Length = Field(0.02, gt=0, description="how far the slider's clamped ends are lowered")


class CrossingLoad(Section):
    amplitude: Length = Field(0.1, gt=0, description="tangential displacement amplitude U of the slider's ends")
    steps_per_leg: Integer = Field(40, ge=2, description="steps of each leg 0 -> U -> -U -> U")
    indentation_steps: Integer = Field(4, ge=1, description="steps of the normal indentation")


class CrossingMesh(Section):
    elements: Integer = Field(5, ge=1, description="elements of the slider (odd: the crossing at an element centre)")
    order: Integer = Field(1, ge=1, le=4, description="Lagrange element order")

    @field_validator("elements")
    @classmethod
    def _odd(cls, v):
        if v % 2 != 1:
            raise ValueError(f"mesh.elements must be odd (the crossing at the centre of an element), got {v}")
        return v


class CrossingContact(FrictionContact):
    n_gp: Integer = Field(1, ge=1, description="contact points per element pair (1: one point at the crossing)")


class FrictionCrossingConfig(SceneConfig):
    """One crossing, stick then slip: a pressed fibril slid along a clamped one and back."""

    scene: Literal["friction_crossing"] = Field(description="scene name")
    geometry: CrossingGeometry
    load: CrossingLoad
    mesh: CrossingMesh
    material: FrictionMaterial
    contact: CrossingContact
    friction: FrictionSection
    newton: Newton
