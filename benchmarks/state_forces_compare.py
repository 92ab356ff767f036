"""The face forces of two runs of one periodic cell compared state by state, from their
stored strain states alone (no probes, no gathered table): what a mesh pair's force error is
while the finer run's table is still being built.

    python benchmarks/state_forces_compare.py results/rve/RUN/base/states results/rve/REF/base/states

For every mode and step that both runs have stored (``{mode}_{step:02d}.nc``, and the
relaxed state as step 0 of every mode) it prints the
face forces (N; the membrane force per width P e_j times the edge length, which is the same
in both runs of one cell, so their relative errors are the membrane forces') of the ``x+``
and ``y+`` faces, in-plane components, of both runs and their difference on the two
measures of docs/table_accuracy.md: over the reference's range along the path stored so far
(floored at 5 % of the component's largest magnitude, ``RANGE_FLOOR``) and over the
reference's magnitude at that strain. Components below ``NEGLIGIBLE`` of the largest are
left out, as the table studies do. The last lines give the largest of each measure per mode.
"""
from __future__ import annotations

import argparse
import re
from pathlib import Path

import numpy as np

from rve.homogenisation.checkpoint import load_state
from rve.studies.table_convergence import NEGLIGIBLE, RANGE_FLOOR

FACES = ("x+", "y+")
STATE = re.compile(r"^(?P<mode>[a-z_]+)_(?P<step>\d{2})\.nc$")


def _forces(path: Path) -> tuple:
    """``(strain, {(face, component): face force N})`` of one stored periodic state."""
    st = load_state(path)
    return float(st.strain), {(f, c): float(st.reaction_force[f][c]) for f in FACES for c in (0, 1)
                              if f in st.reaction_force}


def _steps(states: Path) -> dict:
    out = {}
    for p in sorted(states.glob("*.nc")):
        m = STATE.match(p.name)
        if m:
            out[(m["mode"], int(m["step"]))] = p
    return out


def compare(run: Path, ref: Path) -> dict:
    """{mode: rows}: per common step (strain, label, run, reference) and the two errors."""
    a, b = _steps(run), _steps(ref)
    for steps, states in ((a, run), (b, ref)):   # the relaxed state is strain 0 of every mode
        if (states / "relaxed.nc").exists():
            steps.update({(mode, 0): states / "relaxed.nc" for mode in {m for m, _ in list(steps)}})
    common = sorted(set(a) & set(b))
    by_mode: dict = {}
    for key in common:
        (sa, fa), (sb, fb) = _forces(a[key]), _forces(b[key])
        if abs(sa - sb) > 1e-12:
            raise ValueError(f"{key}: strains differ ({sa} against {sb})")
        by_mode.setdefault(key[0], []).append((key[1], sa, fa, fb))
    out = {}
    for mode, rows in by_mode.items():
        labels = sorted(set().union(*[set(r[3]) for r in rows]))
        ref_vals = {lab: np.array([r[3][lab] for r in rows]) for lab in labels}
        scale = max(float(np.abs(v).max()) for v in ref_vals.values())
        kept = [lab for lab in labels if np.abs(ref_vals[lab]).max() >= NEGLIGIBLE * scale]
        table = []
        for lab in kept:
            rv = ref_vals[lab]
            span = max(float(rv.max() - rv.min()), RANGE_FLOOR * float(np.abs(rv).max()))
            for (step, eps, fa, fb) in rows:
                d = abs(fa[lab] - fb[lab])
                table.append((step, eps, lab, fa[lab], fb[lab], d / span, d / max(abs(fb[lab]), 1e-300)))
        out[mode] = table
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path, help="the states folder of the run to assess")
    ap.add_argument("reference", type=Path, help="the states folder of the finer run")
    args = ap.parse_args(argv)
    result = compare(args.run, args.reference)
    if not result:
        print("no common strain states")
        return 1
    print(f"{'mode':10s} {'step':>4s} {'strain':>7s} {'face/comp':>9s} {'run N':>13s} {'reference N':>13s} "
          f"{'range err':>9s} {'magn err':>9s}")
    for mode, rows in result.items():
        for step, eps, lab, fa, fb, er, em in rows:
            print(f"{mode:10s} {step:4d} {eps:7.4f} {lab[0] + ' ' + 'xy'[lab[1]]:>9s} {fa:13.6e} {fb:13.6e} "
                  f"{er:9.2%} {em:9.2%}")
    for mode, rows in result.items():
        steps = sorted({r[0] for r in rows})
        print(f"{mode}: steps {steps[0]}..{steps[-1]} ({len(steps)} in common): largest error over the "
              f"range {max(r[5] for r in rows):.2%}, over the magnitude {max(r[6] for r in rows):.2%}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
