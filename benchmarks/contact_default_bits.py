"""Dump the default contact system's arrays (plain-weave relaxation scene, 12 el/fibril,
designed state; mechanics only and with T, V): F, Fx, Fw data, contact_state, fibril contact
forces, energy, conductances. Run it under two trees and compare bit for bit:

    PYTHONPATH=/work/main python benchmarks/contact_default_bits.py /tmp/a.npz
    PYTHONPATH=. python benchmarks/contact_default_bits.py /tmp/b.npz
    python benchmarks/contact_default_bits.py --compare /tmp/a.npz /tmp/b.npz
(with RVE_KERNELS=numpy for the reference forms)."""
import sys

import numpy as np
from pathlib import Path
from rve.config.loader import load_config
from rve.scenes.fabric_relax import setup
from rve.model import ContactSystem, BeamModel
import rve
if sys.argv[1] == "--compare":
    a, b = np.load(sys.argv[2]), np.load(sys.argv[3])
    for k in a.files:
        print(f"{k:8s} {a[k].shape} identical: {np.array_equal(a[k], b[k])}")
    sys.exit(0)
out = {}
cfg = load_config(Path(__file__).resolve().parents[1] / 'configs/scenes/plain_weave_relax.yaml', ["mesh.elements=12"])
_, system, x = setup(cfg)
w = np.zeros(system.n)
F, Fx, Fw = system.evaluate(x, w, 0.0)
out['F'] = F; out['Fx'] = Fx.data
st = system.contact_state(x)
out['state'] = np.array([st[k] for k in sorted(st)])
out['fc'] = system.fibril_contact_forces(x)
out['E'] = np.array([system.energy(x)])
# with T and V
base = system.base
mat = base.material
from dataclasses import replace
from rve.model import BeamMaterial
m2 = replace(mat, electrical_conductivity=10.0, thermal_conductivity=1.0, heat_capacity=1.0)
b2 = BeamModel(base.mesh, m2, fields=("mech", "T", "V"))
x2 = np.zeros(b2.n); b2.nodal(x2)[:, :9] = base.nodal(x)[:, :9]
p2 = replace(system.params, heat_transfer=0.1, conductance=1.0)
s2 = ContactSystem(b2, p2, x2)
w2 = np.zeros(b2.n); rng = np.random.default_rng(0); w2[~s2.mech] = rng.normal(size=(~s2.mech).sum())
F2, Fx2, Fw2 = s2.evaluate(x2, w2, 0.0)
out['F2'] = F2; out['Fx2'] = Fx2.data; out['Fw2'] = Fw2.data
G = s2.contact_conductance(x2, "V")
out['G'] = np.array([G[k] for k in sorted(G)])
st2 = s2.contact_state(x2)
out['state2'] = np.array([st2[k] for k in sorted(st2)])
np.savez(sys.argv[1], **out)
print("rve from", rve.__file__)
