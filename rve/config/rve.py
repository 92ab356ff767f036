"""Config model of the RVE homogenisation run (``scene: rve``; thesis ch. 7, docs/rve_pipeline.md).

One validated :class:`RVEConfig` describes everything one combination of the pipeline
computes: the fabric, material, contact law and mesh (the same sections as the
relaxation scene ``fabric_relax``, ``rve.config.fabric``), the relaxation, the strain
path of Algorithm 7.1 (``strain``), the probes (``probes``) and the probe solver
(``probe_solver``), and friction between the fibrils (``friction``, the section of
``rve.config.friction``; off by default, mu = 0) and the yarn pull-out (``pullout``, run only
by the ``rve_pullout`` target). Quantities accept numbers in internal units (mm, ms, g, N, MPa, K, A,
V) or strings with units. Named in ``rve.scenes.registry.SCENES`` (a pipeline scene:
``rve run`` prints the Snakemake command that builds its table, docs/configuration.md).

Parameter choices of the default (thesis Table 7.1) are documented in
docs/rve_pipeline.md; the config files are configs/rve/*.yaml.
"""
from __future__ import annotations

from typing import Literal, Optional

from pydantic import Field, field_validator, model_validator

from .weaves import WEAVE_PATTERNS
from .friction import FrictionSection, RVEFrictionSection
from .fabric import FabricContact, FabricMaterial, FabricMesh, FabricRelaxation, FabricSpec
from .fields import (
    DampingCoefficient, Dimensionless, ElectricConductivity, Integer, Length, Penalty, SceneConfig, Section,
    ThermalConductivity, Time, Voltage,
)

__all__ = ["default_probes", "thesis_probes", "RVEConfig", "FaultChecks", "RVEMaterial", "Settle", "StrainPath", "ProbeTerminal", "ProbeSpec", "ProbeSolver", "MODES", "PeriodicCell", "periodic_probes", "RVEOutput", "Packing", "FrictionSection", "Pullout"]

#: deformation modes of the strain path (rve.tables.MODES)
MODES = ("uniaxial", "shear", "uniaxial_y", "trellis")


class RVEMaterial(FabricMaterial):
    """Fibril material: mechanics (as the relaxation scene) + conduction of the probes."""

    electrical_conductivity: ElectricConductivity = Field(
        "10 S/mm", gt=0, description="sigma, reference configuration (Table 7.1)")
    thermal_conductivity: ThermalConductivity = Field(
        "1 W/(mm*K)", gt=0, description="k, reference configuration (Table 7.1)")
    seebeck: Dimensionless = Field(
        0.0, ge=0, le=0, description="S (V/K): must be 0 -- the probe solves are decoupled (thesis §7.3)")
    alpha_mu: Dimensionless = Field(
        0.0, ge=0, le=0, description="d mu/dT (MPa/K): must be 0 -- T does not feed back (thesis §7.3)")


class Settle(Section):
    """A second, moderately damped dynamic phase after the relaxation scene's heavily damped
    one (``relaxation``): the heavy damping resolves the initial interpenetrations but
    relaxes the soft modes (fibril tension, bending) only on times ~ gamma / E; with a
    tenth of the damping they settle within ~20 ms (docs/rve_pipeline.md)."""

    damping: DampingCoefficient = Field("2 N*ms/mm^4", ge=0, description="volumetric damping gamma")
    duration: Time = Field("0 ms", ge=0, description="duration (0: no settling phase)")
    steps: Integer = Field(20, ge=1, description="backward-Euler steps")


class StrainPath(Section):
    """Algorithm 7.1: ``steps`` strain steps of ``total / steps`` per mode, each a driven
    phase (velocity field for ``t_step``), a heavily damped relaxation (``t_relax``) and a
    static solve."""

    modes: list[Literal["uniaxial", "shear", "uniaxial_y", "trellis"]] = Field(
        ["uniaxial", "shear"], min_length=1,
        description="deformation modes (each its own chain of steps): uniaxial (along the warp x), shear "
                    "(simple shear), uniaxial_y (along the weft y), trellis (picture-frame shear; its strain is "
                    "the angle drop in rad)")
    total: Dimensionless = Field(0.25, gt=0, le=1, description="final strain (engineering / shear / trellis "
                                 "angle drop in rad)")
    steps: Integer = Field(10, ge=1, le=99, description="strain steps per mode")
    t_step: Time = Field("0.01 ms", gt=0, description="duration of the driven phase of a step (short: inertia "
                         "carries the affine field)")
    stretch_steps: Integer = Field(2, ge=1, description="backward-Euler steps of the driven phase")
    damping: DampingCoefficient = Field(
        "0.1 N*s/m^4", ge=0, description="gamma of the driven phase (Table 7.1's 0.1 N s/m as a volumetric density)")
    t_relax: Time = Field("2 ms", gt=0, description="duration of the heavily damped relaxation of a step")
    relax_steps: Integer = Field(2, ge=1, description="backward-Euler steps of the damped relaxation")
    relax_damping: DampingCoefficient = Field(
        "20 N*ms/mm^4", ge=0, description="damping of the relaxation phase (heavy, as the relaxation scene)")
    rebuild_every: Integer = Field(2, ge=1, description="contact map rebuilt every k time steps")
    newton_rtol: Dimensionless = Field(1e-3, gt=0, description="stage Newton relative tolerance (dynamic phases)")
    newton_max_iter: Integer = Field(8, ge=1, description="stage Newton iterations (then the step is cut)")
    static_method: Literal["energy", "newton"] = Field(
        "energy", description="static solve of a step: energy minimisation (rve.solvers.minimize.minimize_energy) "
                              "or the capped Newton of the dynamic relaxation path")
    static_atol: Dimensionless = Field(1e-9, gt=0, description="static solve tolerance on |F| (N)")
    follow_branch: bool = Field(
        True, description="one equilibrium path (rve.homogenisation.branch): test every step's energy balance and "
                           "inertia, redo a step that jumped to another equilibrium in halves from the previous "
                           "state")
    branch_energy_rtol: Dimensionless = Field(
        0.05, gt=0, le=1, description="jump test: energy mismatch allowed, fraction of the step's work "
                                      "(|d| max |dPi/deps|)")
    branch_max_halvings: Integer = Field(3, ge=0, le=8, description="jump test: recursion depth of the step halving "
                                                                   "(floor: the step / 2^n)")
    branch_state_tol: Length = Field("1e-4 mm", gt=0, description="naive and followed end states closer than this "
                                                                   "(max centroid distance) are one equilibrium")
    branch_persist_ratio: Dimensionless = Field(
        0.5, ge=0, description="jump test: a failing half that keeps this share of its parent's energy mismatch holds "
                               "the jump itself (a limit point, not halved further; 0: halve down to the floor)")
    branch_method: Literal["arc_length", "halving"] = Field(
        "halving", description="how a step with a detected jump is followed: pseudo-arclength continuation of "
                                  "the static equilibria in (dofs, strain), through limit points "
                                  "(rve.homogenisation.continuation; halving where it fails), or step halving "
                                  "from the previous state down to branch_max_halvings")
    arc_corrector: Literal["newton", "dogleg"] = Field(
        "newton", description="corrector of the arc-length continuation (branch_method: arc_length): Newton with "
                              "backtracking, or Powell's dogleg on |R|^2 in the arc's hyperplane "
                              "(rve.homogenisation.branch)")
    arc_penalty: Optional[Penalty] = Field(
        None, gt=0, description="augmented Lagrangian, periodic cell: P* at which the continuation runs (the "
                                "start's multipliers re-expressed there, as at the Uzawa loop's raised P*; back to "
                                "contact.penalty for the loop at its end); null: contact.penalty")
    static_rounds: Integer = Field(1, ge=1, description="static solves, each after a map rebuild ('newton')")
    static_max_iter: Integer = Field(
        1000, ge=1, description="iterations of the static solve (energy: the minimiser's cap; a step that "
                                "rearranges the plain weave's stacks took 463; newton: per round)")

    path: Literal["algorithm_7_1", "quasi_static"] = Field(
        "algorithm_7_1", description="how a step moves the cell: algorithm_7_1 (the thesis: driven dynamics, damped "
                                     "relaxation, static solve) or quasi_static (substeps sub-increments, each the "
                                     "affine increment as predictor and a static solve; with friction each is one "
                                     "committed backward-Euler step of the slip, docs/contact.md; in the periodic "
                                     "cell, which has no dynamic phases, algorithm_7_1 is one such increment)")
    substeps: Integer = Field(2, ge=1, le=50, description="sub-increments of a quasi_static step")
    max_cuts: Integer = Field(
        2, ge=0, le=5, description="times a step whose static solve fails is solved again from its start in twice "
                                   "as many sub-increments (the periodic cell) or parts (the pinned cell: Algorithm "
                                   "7.1 or the quasi-static path on each part; 0: none; the record's cuts)")
    cycle_modes: list[Literal["uniaxial", "shear", "uniaxial_y", "trellis"]] = Field(
        [], description="modes that also get a loading-unloading cycle from the relaxed state: cycle_steps steps "
                        "up to cycle_total, as many back to 0 (the hysteresis loop; docs/rve_pipeline.md "
                        "'Loading-unloading cycles')")
    cycle_total: Optional[Dimensionless] = Field(
        None, gt=0, le=1, description="strain at the turning point of a cycle (null: total)")
    cycle_steps: Optional[Integer] = Field(
        None, ge=1, le=49, description="strain steps of each leg of a cycle (null: steps)")

    @field_validator("modes", "cycle_modes")
    @classmethod
    def _unique_modes(cls, v):
        if len(set(v)) != len(v):
            raise ValueError(f"modes must be unique, got {v}")
        return v


class ProbeTerminal(Section):
    """All fibril ends of one yarn on one side of the box: the yarn is picked by its
    direction and position (warp: its y, weft: its x, knit course 'loop': its y)."""

    yarn: Literal["warp", "weft", "loop"] = Field(description="yarn direction")
    position: Length = Field(description="yarn position across the fabric (mm)")
    end: Literal["x-", "x+", "y-", "y+"] = Field(description="box side of the yarn end")


class ProbeSpec(Section):
    """A probe: the test voltage on the first terminal ('+'), 0 V on the second ('-'); or,
    in a periodic cell, a macro field along ``field`` (the test voltage across one period)."""

    name: str = Field(pattern=r"^[A-Za-z][A-Za-z0-9_]*$", description="probe name (table coordinate)")
    terminals: list[ProbeTerminal] = Field(
        [], max_length=2, description="[+ terminal, - terminal] (pinned cell; empty for a field probe)")
    field: Optional[Literal["x", "y"]] = Field(
        None, description="periodic cell: direction of the macro field (the potential jumps by the test voltage "
                          "across one period); null for a terminal probe")

    @model_validator(mode="after")
    def _terminals_or_field(self):
        if self.field is None and len(self.terminals) != 2:
            raise ValueError(f"probe {self.name}: terminals needs exactly 2 entries (+, -), got "
                             f"{len(self.terminals)} (or give field: x | y in a periodic cell)")
        if self.field is not None and self.terminals:
            raise ValueError(f"probe {self.name}: a field probe ({self.field}) has no terminals")
        return self


class ProbeSolver(Section):
    voltage: Voltage = Field("1 V", gt=0, description="test voltage across the terminals")
    insulation_factor: Dimensionless = Field(
        1e12, gt=1, description="weakened insulation: pull-down R_ext = factor x the fibril's own resistance")
    insulation_ends: Literal["both", "start"] = Field("both", description="pull-down on both ends or the first")
    temperature: bool = Field(True, description="Joule-heating temperature solve (T = 0 at every fibril end)")
    newton_atol: Dimensionless = Field(1e-12, gt=0, description="absolute tolerance of the probe solves")
    newton_rtol: Dimensionless = Field(1e-12, gt=0, description="relative tolerance of the probe solves")


def thesis_probes() -> list[dict]:
    """The three probes of thesis Fig. 7.2.2 on the 4 x 4 plain weave (also valid on a 2 x 2
    weave with yarns at -1 and +1)."""
    return [
        {"name": "probe1", "terminals": [{"yarn": "warp", "position": -1.0, "end": "x+"},
                                         {"yarn": "warp", "position": -1.0, "end": "x-"}]},
        {"name": "probe2", "terminals": [{"yarn": "warp", "position": -1.0, "end": "x+"},
                                         {"yarn": "warp", "position": 1.0, "end": "x-"}]},
        {"name": "probe3", "terminals": [{"yarn": "warp", "position": -1.0, "end": "x+"},
                                         {"yarn": "weft", "position": -1.0, "end": "y+"}]},
    ]


def periodic_probes() -> list[dict]:
    """The probes of a periodic cell: a macro field along the warp (x) and along the weft (y)."""
    return [{"name": "field_x", "field": "x"}, {"name": "field_y", "field": "y"}]


def default_probes() -> list[dict]:
    """The thesis probes and a 4th: the x = -1 weft yarn end to end, so the network fit
    separates the warp and weft yarn resistances (docs/macro_export.md §2)."""
    return thesis_probes() + [
        {"name": "probe4", "terminals": [{"yarn": "weft", "position": -1.0, "end": "y+"},
                                         {"yarn": "weft", "position": -1.0, "end": "y-"}]}]


# ---------------------------------------------------------------- fault checks (one block)
class FaultChecks(Section):
    """What the jobs check before and after they compute (docs/fault_tolerance.md)."""

    keep_unconverged: bool = Field(
        False, description="false: a relax/strain job whose final |F| exceeds its tolerance (or is not finite) "
                           "fails and keeps the state as <name>.unconverged.nc; true: the state is stored and "
                           "the table marks it (converged = 0)")
    residual_refuse_factor: Dimensionless = Field(
        10.0, gt=1, description="the probe job refuses a state whose equilibrium residual, recomputed at load, "
                                "exceeds this factor x max(recorded residual, the stage's tolerance)")
    max_design_overlap: Dimensionless = Field(
        0.5, gt=0, lt=1, description="largest overlap 2R - d of two fibrils of different yarns at the designed "
                                     "state, as a fraction of the diameter 2R (the default plain weave: 25 %, "
                                     "resolved by the relaxation)")
    memory_limit_mb: Optional[Integer] = Field(
        None, ge=1, description="refuse a mesh whose estimated memory exceeds this (MB); null: the machine's "
                                "available memory")


# --- pictures and perturbed packings: the `output` and `packing` sections --------------
class RVEOutput(Section):
    """Pictures of every stored state (``rve.homogenisation.pictures``): a tube mesh per
    state (.vtp, written by its probe job), a .pvd series per mode and PNG renders."""

    pictures: bool = Field(True, description="write the tube meshes, .pvd series and PNG renders of the states")
    n_theta: Integer = Field(12, ge=3, le=64, description="points around each fibril section of the tube meshes")


class Packing(Section):
    """A perturbed packing of the fibrils (thesis §7.5; ``rve.fabrics.perturb``): every
    fibril of a stack is moved in its section plane by a random offset and the crimp of
    every yarn shifted along it by a random phase, both uniform in [-a R, a R], drawn from
    ``numpy.random.default_rng(seed)``. ``perturbation: 0`` (the default) is the designed
    packing itself: the fabric is not touched, so the default run is unchanged."""

    seed: Integer = Field(0, ge=0, description="seed of the random offsets (one realisation per seed)")
    perturbation: Dimensionless = Field(0.0, ge=0, le=0.5, description="in-plane offset amplitude a of the "
                                        "fibrils in each stack, fraction of R (0: the designed packing)")
    crimp_phase: Optional[Dimensionless] = Field(None, ge=0, le=5, description="crimp phase shift amplitude along "
                                                 "each yarn, fraction of R (null: = perturbation)")


class PeriodicCell(Section):
    """The periodic cell (``boundary: periodic``; docs/periodic.md): the
    smallest repeat of the weave pattern (plain 2 x 2 yarns, twill 2/1 3 x 3, twill 2/2 and
    basket 4 x 4), ``repeat`` times in each direction; every fibril spans one period and
    its end is tied to its start."""

    repeat: Integer = Field(1, ge=1, le=8, description="pattern repeats per cell side (n x n)")
    contact_images: bool = Field(True, description="the contact search sees the periodic images of the fibrils "
                                                   "across the cell faces (false: only the pairs inside the cell)")


class Pullout(Section):
    """Yarn pull-out (``rve.homogenisation.pullout``): from the relaxed state, one yarn's ends on
    the + side (x+ warp, y+ weft) pulled along its axis, its ends on the - side released, every
    other fibril end pinned; ``steps`` quasi-static steps (``strain.substeps`` sub-increments each)."""

    yarn: Literal["warp", "weft"] = Field("warp", description="direction of the pulled yarn")
    position: Length = Field("-1 mm", description="position of the pulled yarn across the fabric (warp: y, weft: x)")
    displacement: Length = Field("0.5 mm", gt=0, description="total pull-out displacement of the pulled ends")
    steps: Integer = Field(10, ge=1, le=99, description="pull-out steps")
    release_steps: Integer = Field(4, ge=1, le=50, description="decrements in which the released ends' clamp force "
                                                               "is taken off before the pull")
    max_halvings: Integer = Field(4, ge=0, le=10, description="a pull-out sub-increment that fails is undone and "
                                                             "halved, at most this deep")
    sliding_fraction: Dimensionless = Field(
        1.0 / 3.0, gt=0, le=1, description="the sliding force is the mean force over this last fraction of the "
                                           "displacement")


class RVEConfig(SceneConfig):
    """RVE homogenisation: relax, strain step by step, probe every stored state (thesis ch. 7)."""

    scene: Literal["rve"] = Field(description="scene name")
    fabric: FabricSpec = Field(default_factory=FabricSpec)
    material: RVEMaterial = Field(default_factory=RVEMaterial)
    contact: FabricContact = Field(default_factory=FabricContact)
    mesh: FabricMesh = Field(default_factory=FabricMesh)
    relaxation: FabricRelaxation = Field(default_factory=FabricRelaxation)
    settle: Settle = Field(default_factory=Settle)
    strain: StrainPath = Field(default_factory=StrainPath)
    probes: list[ProbeSpec] = Field(default_factory=lambda: [ProbeSpec(**p) for p in default_probes()],
                                    min_length=1, description="probes (thesis Fig. 7.2.2 and a weft yarn end to "
                                                              "end by default)")
    probe_solver: ProbeSolver = Field(default_factory=ProbeSolver)
    checks: FaultChecks = Field(default_factory=FaultChecks, description="fault checks (docs/fault_tolerance.md)")
    output: RVEOutput = Field(default_factory=RVEOutput)
    packing: Packing = Field(default_factory=Packing)
    boundary: Literal["pinned", "periodic"] = Field(
        "pinned", description="pinned: the thesis's cell, every fibril end pinned (Algorithm 7.1); periodic: the "
                              "smallest repeat with periodic ties (section cell)")
    cell: PeriodicCell = Field(default_factory=PeriodicCell, description="the periodic cell (boundary: periodic)")
    pullout: Pullout = Field(default_factory=Pullout, description="yarn pull-out (rve_pullout; docs/rve_pipeline.md)")
    friction: RVEFrictionSection = Field(
        default_factory=RVEFrictionSection,
        description="regularised Coulomb friction between fibrils along the strain path (mu = 0: none; the "
                    "relaxation is frictionless; docs/contact.md 'Friction in the RVE pipeline')")

    @property
    def has_friction(self) -> bool:
        """Whether any fibril pair has mu > 0 (then the strain steps carry a friction term)."""
        return self.friction.coefficient > 0 or any(float(m) > 0 for m in self.friction.pairs.values())

    @model_validator(mode="after")
    def _cycles_in_the_pinned_cell(self):
        if self.strain.cycle_modes and self.boundary != "pinned":
            raise ValueError(f"strain.cycle_modes = {self.strain.cycle_modes}: loading-unloading cycles are "
                             f"available in the pinned cell only (boundary = {self.boundary!r})")
        return self

    @model_validator(mode="after")
    def _unique_probe_names(self):
        names = [p.name for p in self.probes]
        if len(set(names)) != len(names):
            raise ValueError(f"probe names must be unique, got {names}")
        return self

    @model_validator(mode="after")
    def _periodic_cell(self):
        """A periodic cell takes its yarn counts from the pattern and ``cell.repeat`` and has
        field probes; an explicit contradicting key is an error naming it."""
        field_probes = [p.name for p in self.probes if p.field is not None]
        if self.boundary == "pinned":
            if field_probes:
                raise ValueError(f"probes {field_probes}: field probes need boundary: periodic")
            return self
        if self.fabric.kind == "knit":
            raise ValueError("boundary: periodic is defined for the weaves (fabric.kind plain, twill_2_1, "
                             "twill_2_2, basket_2_2), not the knit")
        m, n = WEAVE_PATTERNS[self.fabric.kind].shape
        want = {"n_warp": m * self.cell.repeat, "n_weft": n * self.cell.repeat}
        for key, value in want.items():
            if key in self.fabric.model_fields_set and getattr(self.fabric, key) != value:
                raise ValueError(f"fabric.{key} = {getattr(self.fabric, key)}: a periodic {self.fabric.kind} cell "
                                 f"with cell.repeat = {self.cell.repeat} has {value} (leave it out)")
            object.__setattr__(self.fabric, key, value)
        if "probes" not in self.model_fields_set:
            object.__setattr__(self, "probes", [ProbeSpec(**p) for p in periodic_probes()])
        elif len(field_probes) != len(self.probes):
            raise ValueError("boundary: periodic takes field probes only (probes: [{name: ..., field: x | y}])")
        return self
