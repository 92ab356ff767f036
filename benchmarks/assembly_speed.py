"""Assembly speed of the model (issue 10, item 3): the numpy reference kernels against the
compiled (numba) ones, interleaved call by call in one process (docs/kernels.md).

    python benchmarks/assembly_speed.py [--elements 12 30] [--repeat 10] [--wire-elements 40]
                                        [--reference DIR]

For the 80-fibril thesis plain weave (configs/scenes/plain_weave_relax.yaml, built as the
relaxation scene builds it: rve.scenes.fabric_relax.setup, at the designed state) at each
``--elements`` per fibril, prints dofs, contact pairs (candidates and active), the union nnz
and the median wall time (ms, ``--repeat`` calls, numpy and numba alternating) of:

* ``beam``: the Neo-Hookean element kernel (the elasticity term's forms), with / without
  the tangent;
* ``contact``: the contact term's forms (gap pass, geometry, penalty residual and tangent
  of the active pairs), with / without the tangent; ``gaps`` (the energy's pass);
* ``scatter``: the element sums' bincounts (vector + CSR) and the pair bincounts + the
  union add of the element matrix;
* ``evaluate``: the whole ``ContactSystem.evaluate`` with / without the tangent;
* the rebuild: ``build_contact_map``, ``UnionPattern`` and ``ContactSystem.rebuild`` with the
  pair set unchanged (the union kept) or forced new; with ``--reference DIR`` also the
  ``UnionPattern`` and ``build_contact_map`` of another source tree (e.g. /work/baseline or
  a ``git archive`` of main), interleaved with this one;
* the max relative differences (max |a - b| / max |b|) of F, Fx, Fw numba vs numpy, and
  whether the two-thread kernels give the one-thread bits.

Modes: ``numpy`` (the reference), ``numba`` (compiled, one thread), ``numba_t2`` (compiled,
elements and pairs split over two threads: ``rve.threads.run_chunked``).

Then the dynamic wire (configs/scenes/dynamic_wire.yaml, ``--wire-elements``; coupled T):
the electromagnetic term (EMF + Lorentz + Joule kernel), the elasticity term (with thermal
softening) and the whole ``BeamModel.evaluate``. Finally numba's version, its import time
and the first call of every compiled kernel in this process (JIT compile, or the load of
numba's on-disk cache when present), and the peak RSS. The machine is shared: quote the
ratios of one run, not absolute times across runs.
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

#: numpy: the reference; numba: compiled on one thread; numba_t2: compiled, the elements /
#: pairs split over two threads (rve.threads.run_chunked, the relaxation job's setting)
MODES = ("numpy", "numba", "numba_t2")


def _set(mode):
    os.environ["RVE_KERNELS"] = "numba" if mode.startswith("numba") else mode
    if mode == "auto":
        os.environ.pop("RVE_PARDISO_THREADS", None)
    else:
        os.environ["RVE_PARDISO_THREADS"] = "2" if mode.endswith("_t2") else "1"


def interleaved(funcs: dict, repeat: int) -> dict:
    """{mode: median ms} with the modes alternating call by call."""
    t = {m: [] for m in funcs}
    for _ in range(repeat):
        for m, f in funcs.items():
            _set(m)
            t0 = time.perf_counter()
            f()
            t[m].append(time.perf_counter() - t0)
    _set("auto")
    return {m: 1e3 * float(np.median(v)) for m, v in t.items()}


def _row(name, d, unit="ms"):
    vals = "  ".join(f"{m} {d[m]:8.2f}" for m in d)
    ratio = f"  x{d['numpy'] / d['numba']:.2f}" if "numba" in d and "numpy" in d and d["numba"] > 0 else ""
    if "numba_t2" in d and d["numba_t2"] > 0:
        ratio += f"  (2 threads x{d['numba'] / d['numba_t2']:.2f})"
    print(f"  {name:34s} {vals} {unit}{ratio}", flush=True)


def _rel(a, b):
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


def _load_reference(tree: Path):
    mods = {}
    for name, rel in (("assembly", "rve/fem/assembly.py"), ("search", "rve/contact/search.py")):
        spec = importlib.util.spec_from_file_location(f"_ref_{name}", tree / rel)
        mod = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = mod
        spec.loader.exec_module(mod)
        mods[name] = mod
    return mods


def weave(elements: int, repeat: int, reference=None, jit: dict | None = None) -> None:
    from rve.config.loader import load_config
    from rve.contact.search import build_contact_map
    from rve.fem.assembly import UnionPattern
    from rve.model.assembler import ElementState
    from rve.scenes.fabric_relax import setup

    cfg = load_config(ROOT / "configs/scenes/plain_weave_relax.yaml", [f"mesh.elements={elements}"])
    _, system, x = setup(cfg)
    w = np.zeros(system.n)
    ca, term, A = system.assembler, system.term, system.base.assembler
    elast = A.term("elasticity")
    u = ca.union
    act = term.active_pairs(x)
    print(f"\nplain weave, {elements} el/fibril: dofs {system.n}, contact pairs {term.map.n_pairs} "
          f"(active at the designed state {act.size}), union nnz {u.nnz}, element pattern nnz {A.pattern.nnz}")
    if jit is not None:  # first calls in this process: JIT compile or cache load
        for name, f in (("beam", lambda: elast.forms(ElementState(A.basis, A.layout, x, w, 0.0), True)),
                        ("contact forms", lambda: term.forms(x, w, True)), ("contact gaps", lambda: term.gaps(x))):
            _set("numba")
            t0 = time.perf_counter()
            f()
            jit[name] = time.perf_counter() - t0
        _set("auto")
    st = lambda: ElementState(A.basis, A.layout, x, w, 0.0)  # noqa: E731
    for jac in (True, False):
        _row(f"beam kernel{' + tangent' if jac else ''}", interleaved({m: (lambda j=jac: elast.forms(st(), j))
                                                                       for m in MODES}, repeat))
    for jac in (True, False):
        _row(f"contact forms{' + tangent' if jac else ''}", interleaved({m: (lambda j=jac: term.forms(x, w, j))
                                                                         for m in MODES}, repeat))
    _row("contact gaps (energy pass)", interleaved({m: (lambda: term.gaps(x)) for m in MODES}, repeat))
    _set("numpy")
    Re, Kx, _ = A.element_sums(st(), True)
    a_, Rl, Kl, _ = term.forms(x, w, True)
    ev = A.evaluate(x, w, 0.0, True, system.base.row_scale)
    _set("auto")

    def scatter_elements():
        A.pattern.assemble_vector(Re)
        A.pattern.assemble_csr(Kx)

    def scatter_pairs():
        np.bincount(u.gdofs[a_].ravel(), weights=Rl.ravel(), minlength=system.n)
        dx = np.bincount(u.slots[a_].ravel(), weights=Kl.ravel(), minlength=u.nnz)
        u.add(dx, ev.Fx)
        u.csr(dx)

    sc = interleaved({"numpy": scatter_elements}, repeat)["numpy"]
    sp_ = interleaved({"numpy": scatter_pairs}, repeat)["numpy"]
    print(f"  {'scatter: elements (vector + CSR)':34s} {sc:8.2f} ms;  pairs (bincounts + union add) {sp_:8.2f} ms")
    for jac in (True, False):
        _row(f"ContactSystem.evaluate{' + tangent' if jac else ''}",
             interleaved({m: (lambda j=jac: system.evaluate(x, w, 0.0, j)) for m in MODES}, repeat))
    # the rebuild
    xn = system.nodal(x)[:, :3]
    local = term.rebuild(x)
    funcs = {"build_contact_map": lambda: build_contact_map(xn, term.mesh, term.cutoff, term.params.n_gp),
             "UnionPattern": lambda: UnionPattern(A.pattern, local, term.comps)}
    if reference is not None:
        funcs["reference build_contact_map"] = lambda: reference["search"].build_contact_map(
            xn, term.mesh, term.cutoff, term.params.n_gp)
        funcs["reference UnionPattern"] = lambda: reference["assembly"].UnionPattern(A.pattern, local, term.comps)
    times = {k: [] for k in funcs}
    for _ in range(max(5, repeat // 2)):
        for k, f in funcs.items():
            t0 = time.perf_counter()
            f()
            times[k].append(time.perf_counter() - t0)
    for k, v in times.items():
        print(f"  {k:34s} {1e3 * np.median(v):8.2f} ms")

    def forced():
        ca._local = None
        system.rebuild(x)

    rb = {"unchanged pairs (union kept)": lambda: system.rebuild(x), "forced new union": forced}
    times = {k: [] for k in rb}
    for _ in range(max(5, repeat // 2)):
        for k, f in rb.items():
            t0 = time.perf_counter()
            f()
            times[k].append(time.perf_counter() - t0)
    for k, v in times.items():
        print(f"  {'ContactSystem.rebuild, ' + k:34s} {1e3 * np.median(v):8.2f} ms")
    # agreement of the two paths on the weave
    out = {}
    for m in MODES:
        _set(m)
        out[m] = system.evaluate(x, w, 0.0, True)
    _set("auto")
    a, b, c = out["numpy"], out["numba"], out["numba_t2"]
    print(f"  max rel. difference numba vs numpy: F {_rel(b[0], a[0]):.1e}, Fx {_rel(b[1].data, a[1].data):.1e}, "
          f"Fw {_rel(b[2].data, a[2].data):.1e}; 2 threads vs 1 bitwise equal: "
          f"{np.array_equal(b[0], c[0]) and np.array_equal(b[1].data, c[1].data)}")


def wire(elements: int, repeat: int, jit: dict | None = None) -> None:
    from rve.config.loader import load_config
    from rve.model.assembler import ElementState
    from rve.scenes.dynamic_wire import setup

    cfg = load_config(ROOT / "configs/scenes/dynamic_wire.yaml", [f"mesh.elements={elements}"])
    model = setup(cfg)
    A = model.assembler
    rng = np.random.default_rng(0)
    x = np.zeros(model.n)
    model.nodal(x)[:, :9] = model.mesh.X0 + 1e-3 * rng.standard_normal(model.mesh.X0.shape)
    w = 1e-2 * rng.standard_normal(model.n)
    t = 1e-3
    print(f"\ndynamic wire, {elements} elements: dofs {model.n}, terms {[tm.name for tm in A.terms]}")
    em, el = A.term("electromagnetic"), A.term("elasticity")
    st = lambda: ElementState(A.basis, A.layout, x, w, t)  # noqa: E731
    if jit is not None:
        _set("numba")
        t0 = time.perf_counter()
        em.forms(st(), True)
        jit["EMF"] = time.perf_counter() - t0
        _set("auto")
    for jac in (True, False):
        _row(f"electromagnetic forms{' + tangent' if jac else ''}",
             interleaved({m: (lambda j=jac: em.forms(st(), j)) for m in MODES}, repeat))
    _row("elasticity forms + tangent", interleaved({m: (lambda: el.forms(st(), True)) for m in MODES}, repeat))
    for jac in (True, False):
        _row(f"BeamModel.evaluate{' + tangent' if jac else ''}",
             interleaved({m: (lambda j=jac: model.evaluate(x, w, t, j)) for m in MODES}, repeat))
    out = {}
    for m in MODES:
        _set(m)
        out[m] = model.evaluate(x, w, t, True)
    _set("auto")
    a, b = out["numpy"], out["numba"]
    print(f"  max rel. difference numba vs numpy: F {_rel(b[0], a[0]):.1e}, Fx {_rel(b[1].data, a[1].data):.1e}, "
          f"Fw {_rel(b[2].data, a[2].data):.1e}")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--elements", type=int, nargs="+", default=[12, 30])
    ap.add_argument("--repeat", type=int, default=10)
    ap.add_argument("--wire-elements", type=int, default=40)
    ap.add_argument("--reference", type=Path, default=None, help="another source tree for the rebuild A/B")
    args = ap.parse_args(argv)
    from rve.kernels import numba_available

    if not numba_available():
        sys.exit("numba is not installed: nothing to compare (pip install numba)")
    t0 = time.perf_counter()
    import numba

    t_import = time.perf_counter() - t0
    print(f"numba {numba.__version__} (import {t_import:.2f} s), "
          f"NUMBA_CACHE_DIR={os.environ.get('NUMBA_CACHE_DIR', '-')}, repeat {args.repeat}, load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    ref = _load_reference(args.reference) if args.reference else None
    jit: dict = {}
    for i, e in enumerate(args.elements):
        weave(e, args.repeat, ref, jit if i == 0 else None)
    if args.wire_elements:
        wire(args.wire_elements, max(args.repeat, 20), jit)
    print("\nfirst numba call in this process (compile, or cache load): "
          + ", ".join(f"{k} {v:.2f} s" for k, v in jit.items()))
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")


if __name__ == "__main__":
    main()
