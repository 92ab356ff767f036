"""Capture the sparse matrices the engine factorises (issue 10) and save them under
results/engine/ (scipy.sparse.save_npz, CSC as the solvers receive them; a JSON sidecar
with how each was made).

    python benchmarks/engine_matrices.py [--only NAME ...] [--out results/engine]

Matrices (docs/engine.md, "Supernodal backend (measured)"):

* ``min12_first``, ``min30_first``: the energy minimiser's first matrix K + σ₀ M
  (rve/contact/relax.py ``minimize_energy``: the free-dof tangent of ``StaticProblem`` at
  the designed state of the 80-fibril plain weave, configs/scenes/plain_weave_relax.yaml,
  contact map built there, σ₀ = 1e-6 of the stiffest mode's σ); usually indefinite.
* ``min12_pd``, ``min30_pd``: K + σ M with the first σ = 4ᵏ σ₀ whose factor has no negative
  pivot (what the minimiser then solves with).
* ``min12_K``: the unregularised tangent K (σ = 0).
* ``driven12``: the backward-Euler stage matrix M + h Fw + h² Fx of the strain step's
  driven phase (rve/homogenisation/strain.py: configs/rve/plain_weave.yaml, damping
  strain.damping, h = t_step / stretch_steps, ends moving with the affine field).
* ``damped30``: the same for the heavily damped relaxation (relax_damping, h = t_relax /
  relax_steps) at 30 elements per fibril.
* ``impact_stage``: a synthetic SDIRK2 stage matrix M + h a C + (h a)² K of a 32 × 32 plain
  weave of single-fibril yarns (d = 0.3 mm, spacing 1 mm, crimp amplitude R), 80 linear
  elements per fibril, fields mech + T + V (T and V of the RVE material, the contact
  conducting heat and current), ends pinned and held at T = V = 0, h = 5e-4 ms,
  a = 1 − √2/2, at the designed state with contact; ``impact_stage_mech``: mechanics only.
* ``impact_scene``, ``impact_scene_reduced``, ``induced_B3`` (only with ``--only``): stage
  matrices the scenes' kept factorisations (``StageFactorisation``) really receive, caught
  from short runs of configs/scenes/impact.yaml (full size: relaxation + 20 steps, into
  sphere contact; reduced: the config header's small version, 30 steps) and
  configs/scenes/induced_deformation.yaml (B3 full size, 70 steps to 0.35 ms: fabric contact)
  (docs/engine.md "Unsymmetric stage matrices (round 4)").
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _save(out: Path, name: str, A, meta: dict) -> None:
    out.mkdir(parents=True, exist_ok=True)
    A = sp.csc_matrix(A)
    sp.save_npz(out / f"{name}.npz", A, compressed=False)
    zeros = int(np.count_nonzero(A.data == 0.0))
    sym = float(abs(A - A.T).max() / max(abs(A).max(), 1e-300))
    meta = dict(meta, name=name, n=int(A.shape[0]), nnz=int(A.nnz), explicit_zeros=zeros, asymmetry=sym)
    (out / f"{name}.json").write_text(json.dumps(meta, indent=1))
    print(f"{name}: n={A.shape[0]} nnz={A.nnz} explicit zeros={zeros} ({zeros / A.nnz:.0%}) "
          f"asym={sym:.1e} {meta.get('note', '')}", flush=True)


def _neg(A) -> int:
    from rve.solvers.linear import factor_inertia

    return factor_inertia(A)[1]


def minimiser_matrices(elements: int, out: Path, pd: bool = True, with_K: bool = False) -> None:
    from rve.config.loader import load_config
    from rve.scenes.fabric_relax import setup
    from rve.solvers.static import StaticProblem

    t0 = time.perf_counter()
    cfg = load_config(ROOT / "configs/scenes/plain_weave_relax.yaml", [f"mesh.elements={elements}"])
    fab, system, x0 = setup(cfg)
    system.rebuild(x0)
    prob = StaticProblem(system, x0, np.zeros(system.n), 0.0)
    r, J = prob(prob.u0())
    Mff = prob.fd.matrix(system.mass())
    dK, dM = np.abs(J.diagonal()).max(), np.abs(Mff.diagonal()).max()
    scale = float(dK / dM)
    sigma = 1e-6 * scale
    tag = f"min{elements}"
    base = {"source": "minimize_energy first iteration, plain_weave_relax.yaml at the designed state",
            "elements": elements, "sigma_stiffest": scale, "build_s": time.perf_counter() - t0,
            "contact_pairs": int(system.map.e_plus.size) if hasattr(system, "map") else None}
    A = (J + sigma * Mff).tocsc()  # scipy's sum drops the explicit zeros of K (inactive pairs)
    neg = _neg(A)
    _save(out, f"{tag}_first", A, dict(base, sigma=sigma, negative_eigenvalues=neg, note=f"sigma0, {neg} negative"))
    # the same matrix on the fixed pattern of the contact map (explicit zeros kept)
    Jc, Mc = J.tocoo(), Mff.tocoo()
    Ak = sp.csc_matrix((np.r_[Jc.data, sigma * Mc.data], (np.r_[Jc.row, Mc.row], np.r_[Jc.col, Mc.col])),
                       shape=J.shape)
    _save(out, f"{tag}_first_keep", Ak, dict(base, sigma=sigma, note="sigma0, explicit zeros of the map kept"))
    if with_K:
        negK = _neg(J)
        _save(out, f"{tag}_K", J, dict(base, sigma=0.0, negative_eigenvalues=negK, note=f"K, {negK} negative"))
    if pd:
        for _ in range(40):
            if neg == 0:
                break
            sigma *= 4.0
            A = (J + sigma * Mff).tocsc()
            neg = _neg(A)
        _save(out, f"{tag}_pd", A, dict(base, sigma=sigma, negative_eigenvalues=neg, note=f"sigma={sigma:.3g}"))


def stage_matrix(system, x, w, t: float, haii: float):
    """M + h a Fw + (h a)² Fx diag(mech) on the free dofs, as DirkStepper's stage Newton."""
    from rve.solvers.system import FreeDofs, mech_mask

    idx, _ = system.constraints(t)
    fd = FreeDofs(system.n, np.asarray(idx, dtype=np.int64))
    M = sp.csr_matrix(system.mass())
    _, Fx, Fw = system.evaluate(x, w, t, jacobian=True)
    mechf = mech_mask(system).astype(float)
    return fd.combine([(M, 1.0, None), (Fw, haii, None), (Fx, haii * haii, mechf)])


def strain_matrices(elements: int, out: Path, which: str) -> None:
    import rve.config.rve  # noqa: F401  (registers the "rve" scene)
    from rve.config.loader import load_config
    from rve.fabrics.setup import fabric_and_mesh
    from rve.homogenisation.strain import affine_velocity, clamped_ends, mech_system

    cfg = load_config(ROOT / "configs/rve/plain_weave.yaml", [f"mesh.elements={elements}"])
    fab, mesh = fabric_and_mesh(cfg)
    x = np.zeros((mesh.n_nodes, 9))
    x[:] = fab.initial_state(mesh)
    s = cfg.strain
    if which == "driven":
        rate = (s.total / s.steps) / s.t_step
        w = affine_velocity(x, "uniaxial", rate)
        ends, _, _ = clamped_ends(fab, mesh)
        system = mech_system(fab, mesh, cfg, s.damping, x.ravel(), end_velocity=w[ends, :3])
        h, damping = s.t_step / s.stretch_steps, s.damping
        w = w.ravel()
    else:
        system = mech_system(fab, mesh, cfg, s.relax_damping, x.ravel())
        h, damping = s.t_relax / s.relax_steps, s.relax_damping
        w = np.zeros(system.n)
    A = stage_matrix(system, x.ravel(), w, 0.0, h)
    _save(out, f"{which}{elements}", A, {"source": f"backward-Euler stage of the strain step's {which} phase, "
                                                   "configs/rve/plain_weave.yaml, designed state",
                                         "elements": elements, "h_ms": h, "damping": damping,
                                         "note": f"h={h:g} ms gamma={damping:g}"})


def impact_matrix(out: Path, fields=("mech", "T", "V"), n_yarns: int = 32, elements: int = 80,
                  h: float = 5e-4, name: str = "impact_stage") -> None:
    import rve.config.rve  # noqa: F401  (registers the "rve" scene)
    from rve.config.loader import load_config
    from rve.model.contact_model import ContactParams, ContactSystem
    from rve.fabrics import weave
    from rve.model import BeamMaterial, BeamModel, DirichletBC
    from rve.solvers.dirk import SDIRK2

    cfg = load_config(ROOT / "configs/rve/plain_weave.yaml")
    m, c = cfg.material, cfg.contact
    d = 0.3
    fab = weave("plain", n_yarns, n_yarns, spacing=1.0, amplitude=d / 2, fibril_diameter=d, rows=(1,))
    mesh = fab.mesh(elements, 1)
    ends = np.array([tg.node(mesh) for tg in fab.end_tags], dtype=np.int64)
    first = mesh.node_offsets[:-1].astype(np.int64)
    mat = BeamMaterial(m.youngs_modulus, m.poisson_ratio, m.density, damping=0.0,
                       electrical_conductivity=m.electrical_conductivity if "V" in fields else 0.0,
                       thermal_conductivity=m.thermal_conductivity if "T" in fields else 0.0,
                       heat_capacity=1.2e3 if "T" in fields else 0.0)
    base0 = BeamModel(mesh, mat, fields=fields)
    lay = base0.layout
    bcs = [DirichletBC(lay.dofs("r", ends), 0.0), DirichletBC(lay.dofs("g1", first, comp=2), 0.0)]
    for f in ("T", "V"):
        if f in fields:
            bcs.append(DirichletBC(lay.dofs(f, ends), 0.0))
    base = BeamModel(mesh, mat, disk_points=4, fields=fields, bcs=bcs)
    params = ContactParams(penalty=c.penalty, heat_transfer=c.heat_transfer if "T" in fields else 0.0,
                           conductance=c.conductance if "V" in fields else 0.0, n_gp=c.n_gp, margin=c.margin,
                           g_eps=c.g_eps, recompute_closest=c.recompute_closest)
    x = np.zeros(base.n)
    base.nodal(x)[:, :9] = fab.initial_state(mesh)
    system = ContactSystem(base, params, x)
    haii = h * float(SDIRK2.A[0, 0])
    w = np.zeros(system.n)
    A = stage_matrix(system, x, w, 0.0, haii)
    _save(out, name, A, {"source": f"SDIRK2 stage, {n_yarns}x{n_yarns} plain weave of single-fibril yarns, "
                                   f"{elements} linear elements per fibril, fields {fields}",
                         "h_ms": h, "a": float(SDIRK2.A[0, 0]), "fields": list(fields),
                         "note": f"h a = {haii:.3g} ms, fields {'+'.join(fields)}"})


def _hook_stage_matrices(keep: int):
    """Record the matrices ``StageFactorisation`` receives (the restricted, row-scaled stage
    matrices of the DIRK Newton): the last ``keep`` of them, with their sequence numbers."""
    from rve.solvers import newton

    seen = {"count": 0, "last": []}
    orig = newton.StageFactorisation.__init__

    def init(self, J, backend):
        seen["count"] += 1
        seen["last"] = (seen["last"] + [(seen["count"], sp.csc_matrix(J, copy=True))])[-keep:]
        orig(self, J, backend)

    newton.StageFactorisation.__init__ = init
    return seen, lambda: setattr(newton.StageFactorisation, "__init__", orig)


def impact_scene_matrices(out: Path, steps: int = 20, keep: int = 2, reduced: bool = False) -> None:
    """Stage matrices of the impact scene itself (configs/scenes/impact.yaml, full size
    unless ``reduced``: the config header's small version): relax, then ``steps`` steps of
    0.5 µs (contact from about step 14), the last ``keep`` matrices factorised saved as
    ``impact_scene[_reduced]_<k>``; the relaxed state is kept in ``out`` for the A/B runs."""
    from rve.config.loader import load_config
    from rve.scenes import impact
    from rve.scenes.impact.scene import schur_border

    ov = ["output.vtk=false", "output.png=false"]
    if reduced:
        ov += ["geometry.n_warp=8", "geometry.n_weft=8", "geometry.span=12.7 mm", "mesh.elements=16",
               "projectile.radius=4.5 mm"]
    tag = "impact_scene_reduced" if reduced else "impact_scene"
    cfg = load_config(ROOT / "configs/scenes/impact.yaml", ov)
    t0 = time.perf_counter()
    state = out / f"{tag}_relaxed.npz"
    if state.exists():
        x = np.load(state)["x"]
        rinfo = None
    else:
        x, rinfo = impact.relax(cfg)
        out.mkdir(parents=True, exist_ok=True)
        np.savez(state, x=x)
    print(f"  relaxed in {time.perf_counter() - t0:.1f} s", flush=True)
    seen, undo = _hook_stage_matrices(keep)
    try:
        res = impact.solve(cfg, x_start=x, relax_info=rinfo, record=False, t_end=5e-4 * steps, steps=steps)
    finally:
        undo()
    s = res.summary
    for k, (seq, A) in enumerate(seen["last"]):
        _save(out, f"{tag}_{k}", A, {"source": f"impact scene {'reduced' if reduced else 'full size'}, the "
                                               f"{seq}-th of {seen['count']} stage factorisations of {steps} steps "
                                               "of 0.5 us from the relaxed state (row-scaled, restricted)",
                                     "border": schur_border(res.model), "steps": steps,
                                     "sphere_pairs_active_max": s.get("sphere_pairs_active_max"),
                                     "contact_pairs_max": s.get("contact_pairs_max"),
                                     "note": f"factorisation {seq}/{seen['count']}, border {schur_border(res.model)}"})


def induced_scene_matrices(out: Path, t_end: float = 0.35, steps: int = 70, keep: int = 2,
                           orientation: str = "B3") -> None:
    """Stage matrices of the induced-deformation scene (configs/scenes/induced_deformation.yaml,
    full size) in its contact phase: ``steps`` steps to ``t_end`` ms (B3: contact from about
    0.3 ms), the last ``keep`` factorised saved as ``induced_<orientation>_<k>``."""
    from rve.config.loader import load_config
    from rve.scenes.induced import solve

    cfg = load_config(ROOT / "configs/scenes/induced_deformation.yaml",
                      ["output.vtk=false", "output.png=false", "time.adaptive.enabled=false", f"field.orientation={orientation}"])
    seen, undo = _hook_stage_matrices(keep)
    try:
        res = solve(cfg, t_end=t_end, steps=steps, record=False)
    finally:
        undo()
    for k, (seq, A) in enumerate(seen["last"]):
        _save(out, f"induced_{orientation}_{k}", A,
              {"source": f"induced_deformation.yaml {orientation}, the {seq}-th of {seen['count']} stage "
                         f"factorisations of {steps} steps to {t_end} ms", "t_end_ms": t_end, "steps": steps,
               "note": f"factorisation {seq}/{seen['count']}"})


BUILDERS = {
    "min12": lambda out: minimiser_matrices(12, out, pd=True, with_K=True),
    "driven12": lambda out: strain_matrices(12, out, "driven"),
    "min30": lambda out: minimiser_matrices(30, out, pd=True),
    "damped30": lambda out: strain_matrices(30, out, "damped"),
    "impact_stage": lambda out: impact_matrix(out),
    "impact_stage_mech": lambda out: impact_matrix(out, fields=("mech",), name="impact_stage_mech"),
    "impact_scene": lambda out: impact_scene_matrices(out),
    "impact_scene_reduced": lambda out: impact_scene_matrices(out, steps=30, reduced=True),
    "induced_B3": lambda out: induced_scene_matrices(out),
}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", nargs="*", choices=sorted(BUILDERS), help="matrices to build (default all)")
    ap.add_argument("--out", default=str(ROOT / "results/engine"))
    a = ap.parse_args(argv)
    out = Path(a.out)
    for name in a.only or [b for b in BUILDERS if not b.endswith(("_scene", "_reduced", "_B3"))]:
        t0 = time.perf_counter()
        BUILDERS[name](out)
        print(f"  [{name} built in {time.perf_counter() - t0:.1f} s]", flush=True)


if __name__ == "__main__":
    main()
