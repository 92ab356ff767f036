"""Is the difference between two meshes at a strain a discretisation error or a different
equilibrium? Each run's stored state is carried onto the other run's mesh (the Lagrange
interpolant along every fibril, ``rve.fem.transfer.interpolate_nodal``) and solved there at
the same strain, from no multipliers (the Uzawa loop rebuilds them), so each mesh is solved
from both packings (docs/table_accuracy.md "Is the fold state a mesh error or another
equilibrium").

    python benchmarks/fold_basins.py RUN_A STATES_A RUN_B STATES_B STATE [--mode uniaxial]
        [--only A|B] [--set-a KEY=VALUE ...] [--out DIR] [--figures-only]

RUN_*: runs of configs/pipeline.yaml; STATES_*: their state directories; STATE: the state's
file name (e.g. uniaxial_03.nc). ``--only A`` solves on A's mesh only (B's state carried to
it), ``--only B`` the other way. ``--set-a``: config overrides of run A (another mesh, say);
where A's stored state does not fit the mesh they give, its own-state row is left out.
``--figures-only``: the two stored states' rows alone, no solve. For each mesh it prints, for its own stored state and for
the solution from the other mesh's state: the potential (``periodic_energy``, the true
overlaps and the multipliers of the state), the face forces x+ x and y+ y, the stack shapes
(height / width of the yarn sections at the crossings, mean over yarns), the Uzawa record
and the CPU time of the solve, and the largest and rms centroid distance between the two
states of that mesh. Two equilibria of one mesh with each other's forces mean that the
meshes picked different packings; one equilibrium reached from both means the difference
is the mesh's.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from snap_step import figures  # noqa: E402
from snap_through import setup  # noqa: E402


def line(label, fig):
    e, fx, fy, sh = fig
    return (f"  {label:34s} energy {e:.6e} N mm, x+ x {fx:.5f} N, y+ y {fy:.5f} N, "
            f"weft h/w {sh['weft'][0]:.3f}/{sh['weft'][1]:.3f}, warp h/w {sh['warp'][0]:.3f}/{sh['warp'][1]:.3f} mm")


def stored_figures(run, states, name, mode):
    """Print the row of a run's stored state."""
    from rve.homogenisation.checkpoint import load_state

    cfg, fab, mesh = setup(run)
    st = load_state(Path(states) / name)
    print(line(f"{run} ({name})", figures(cfg, fab, mesh, st.x, st.multipliers, mode, float(st.strain))))


def solve_on(run, own_states, other_run, other_states, name, mode, out, overrides=()):
    """Solve ``run``'s mesh (its config with ``overrides``) at the state's strain from
    ``other_run``'s state; print both."""
    from rve.fem.transfer import interpolate_nodal
    from rve.homogenisation.checkpoint import load_state
    from rve.homogenisation.multipliers import multiplier_record
    from rve.homogenisation.periodic import periodic_strain_step

    cfg, fab, mesh = setup(run, list(overrides))
    _, _, other_mesh = setup(other_run)
    own = load_state(Path(own_states) / name)
    other = load_state(Path(other_states) / name)
    eps = float(own.strain)
    if abs(float(other.strain) - eps) > 1e-12:
        raise SystemExit(f"the two states are at different strains ({eps} and {other.strain})")
    x0 = interpolate_nodal(other_mesh, other.x.reshape(other_mesh.n_nodes, -1), mesh)
    c0 = time.process_time()
    x, system, info = periodic_strain_step(cfg, fab, mesh, x0, None, mode, 1, eps_range=(eps, eps), multipliers=None)
    cpu = time.process_time() - c0
    rec = multiplier_record(system)
    al = info["static"].get("augmented_lagrangian", {})
    print(f"\n{run} mesh ({mesh.n_elements} elements{', ' + ' '.join(overrides) if overrides else ''}), "
          f"{mode} strain {eps:g}:")
    fits = own.x.size == mesh.n_nodes * 9
    if fits:
        print(line(f"its own state ({name})", figures(cfg, fab, mesh, own.x, own.multipliers, mode, eps)))
    print(line(f"solved from {other_run}'s state", figures(cfg, fab, mesh, x, rec, mode, eps)))
    if fits:
        d = np.linalg.norm(np.asarray(x).reshape(mesh.n_nodes, -1)[:, :3] - own.x.reshape(mesh.n_nodes, -1)[:, :3],
                           axis=1)
        print(f"  the two states: centroids {d.max():.4f} mm apart at most, {np.sqrt((d ** 2).mean()):.4f} mm rms")
    d0 = np.linalg.norm(np.asarray(x).reshape(mesh.n_nodes, -1)[:, :3] - x0[:, :3], axis=1)
    print(f"  the solution from the carried state: {d0.max():.4f} mm at most, {np.sqrt((d0 ** 2).mean()):.4f} mm rms")
    print(f"  the solve: converged {info['converged']}, |F| {info['residual_N']:.2e} N, Uzawa updates "
          f"{al.get('updates')}, met {al.get('met')}, overlap {al.get('max_penetration_over_R', float('nan')):.2e} R, "
          f"{cpu:.1f} CPU s")
    if out:
        Path(out).mkdir(parents=True, exist_ok=True)
        np.savez(Path(out) / f"{run}_{mesh.n_elements}_from_{other_run}.npz", x=x, keys=rec[0], values=rec[1], cpu=cpu,
                 info=json.dumps(info, default=str))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run_a")
    ap.add_argument("states_a")
    ap.add_argument("run_b")
    ap.add_argument("states_b")
    ap.add_argument("state")
    ap.add_argument("--mode", default="uniaxial")
    ap.add_argument("--only", choices=("A", "B"))
    ap.add_argument("--set-a", action="append", default=[])
    ap.add_argument("--out")
    ap.add_argument("--figures-only", action="store_true")
    a = ap.parse_args()
    if a.figures_only:
        for run, states in ((a.run_a, a.states_a), (a.run_b, a.states_b)):
            stored_figures(run, states, a.state, a.mode)
        return
    if a.only != "B":
        solve_on(a.run_a, a.states_a, a.run_b, a.states_b, a.state, a.mode, a.out, a.set_a)
    if a.only != "A":
        solve_on(a.run_b, a.states_b, a.run_a, a.states_a, a.state, a.mode, a.out)


if __name__ == "__main__":
    main()
