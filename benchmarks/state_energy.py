"""Energy, free residual and inertia (negative pivots) of stored RVE states of the default
plain weave, to tell two equilibria apart:

    python benchmarks/state_energy.py A/states/shear_04.nc B/states/shear_04.nc
"""
import sys
import numpy as np
from rve.homogenisation.checkpoint import load_state
from rve.homogenisation.sweeps import load_run_config
from rve.fabrics.setup import fabric_and_mesh
from rve.homogenisation.strain import mech_system, free_residual
from rve.solvers.linear import factor_inertia
from rve.solvers.static import StaticProblem

spec = {"scene_config": "configs/rve/plain_weave.yaml"}
cfg = load_run_config(spec)
fab, mesh = fabric_and_mesh(cfg)
for path in sys.argv[1:]:
    st = load_state(path)
    x = st.x.reshape(-1)
    sysm = mech_system(fab, mesh, cfg, 0.0, x)
    sysm.rebuild(x)
    E = sysm.energy(x)
    prob = StaticProblem(sysm, x, np.zeros_like(x), 0.0)
    r, J = prob(prob.u0())
    _, neg = factor_inertia(J, backend="superlu")
    print(f"{path}: energy {E:.12e} mJ, |F_free| {np.linalg.norm(r):.2e} N, negative pivots {neg}, contact points {sysm.contact_state(x)['active_points']}")
