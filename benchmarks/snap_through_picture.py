"""The picture of docs/snap_through.md: the transverse (weft) yarns' cross-sections at the
crossing y = -1 mm before and after the snap of each mesh, and the path's weft-stack width
and membrane force (docs/img/snap_through.png).

    python benchmarks/snap_through_picture.py [OUT.png]
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from snap_through import JUMP, RUN12, RUN18, setup, stack_shape, state  # noqa: E402
from _harness import ROOT  # noqa: E402


def weft_sections(fab, mesh, xn, y_cut):
    """[(fibril, x, z)] where each weft fibril's centroid crosses y = y_cut (linear on nodes)."""
    out = []
    for y in fab.yarns:
        if y.direction != "weft":
            continue
        for f in y.fibrils:
            r = xn[mesh.fibril_nodes(f), :3]
            k = np.flatnonzero((r[:-1, 1] - y_cut) * (r[1:, 1] - y_cut) <= 0)
            if k.size == 0:
                continue
            k = int(k[0])
            s = (y_cut - r[k, 1]) / (r[k + 1, 1] - r[k, 1])
            p = (1 - s) * r[k] + s * r[k + 1]
            out.append((f, p[0], p[2]))
    return out


def main():
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    out = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "docs" / "img" / "snap_through.png"
    fig = Figure(figsize=(13, 9.2))
    FigureCanvasAgg(fig)
    gs = fig.add_gridspec(3, 2, height_ratios=[1, 1, 1.05], hspace=0.45, wspace=0.15)
    y_cut = -1.0
    for row, label in enumerate(("12", "18")):
        cfg, fab, mesh = setup(JUMP[label][0])
        states = RUN12 if label == "12" else RUN18
        j = JUMP[label][1]
        for col, step in enumerate((j - 1, j)):
            st = state(states, step)
            xn = st.x.reshape(mesh.n_nodes, -1)
            ax = fig.add_subplot(gs[row, col])
            # the warp fibrils of the yarn at y = -1 (their centrelines, seen along y)
            for y in fab.yarns:
                if y.direction == "warp" and abs(y.position - y_cut) < 1e-9:
                    for f in y.fibrils:
                        r = xn[mesh.fibril_nodes(f), :3]
                        ax.plot(r[:, 0], r[:, 2], color="0.65", lw=0.8, zorder=1)
            R = float(mesh.radius[0])
            for f, xx, zz in weft_sections(fab, mesh, xn, y_cut):
                yarn = int(fab.fibril_yarn[f])
                c = "tab:blue" if fab.yarns[yarn].name == "weft0" else "tab:red"
                ax.add_patch(Circle((xx, zz), R, fc=c, ec="k", alpha=0.55, lw=0.6, zorder=3))
                ax.text(xx, zz, fab.names[f][-2:], ha="center", va="center", fontsize=6.5, zorder=4)
            sh = stack_shape(fab, mesh, st)
            ax.set_title(f"{label} elements, uniaxial {st.strain:.1%} ({'before' if col == 0 else 'after'} the snap): "
                         f"weft stacks h {sh['weft'][0]:.3f}, w {sh['weft'][1]:.3f} mm", fontsize=9)
            ax.set_aspect("equal")
            ax.set_xlim(-2.3 * (1 + st.strain), 2.3 * (1 + st.strain))
            ax.set_ylim(-0.95, 0.95)
            ax.set_xlabel("x [mm] (stretch direction)", fontsize=8)
            ax.set_ylabel("z [mm]", fontsize=8)
            ax.tick_params(labelsize=7)
    # the path: weft stack width and x+ x force against strain
    ax1 = fig.add_subplot(gs[2, 0])
    ax2 = fig.add_subplot(gs[2, 1])
    for label, states, mk in (("12", RUN12, "o-"), ("18", RUN18, "s--")):
        cfg, fab, mesh = setup(JUMP[label][0])
        eps, w, fx, fy = [], [], [], []
        for step in range(0, 11):
            st = state(states, step)
            eps.append(100 * st.strain)
            w.append(stack_shape(fab, mesh, st)["weft"][1])
            fx.append(st.reaction_force["x+"][0] / 4.0)
            fy.append(st.reaction_force["y+"][1] / 4.0)
        ax1.plot(eps, w, mk, label=f"{label} elements", ms=4)
        ax2.plot(eps, fx, mk, label=f"{label} el, P11 (along the stretch)", ms=4)
        ax2.plot(eps, fy, mk, label=f"{label} el, P22 (transverse, F22 = 1 held)", ms=4, alpha=0.6)
    for ax in (ax1, ax2):
        ax.axvspan(5.625, 6.25, color="tab:orange", alpha=0.25, lw=0)
        ax.axvspan(7.5, 8.75, color="tab:green", alpha=0.25, lw=0)
        ax.set_xlabel("uniaxial strain [%]  (shaded: the limit-point intervals, 18 el orange, 12 el green)", fontsize=8)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=7)
    ax1.set_ylabel("weft stack width at the crossings [mm]", fontsize=8)
    ax2.set_ylabel("membrane force [N/mm]", fontsize=8)
    fig.suptitle("Snap-through of the periodic 2x2 plain weave, uniaxial: the transverse (weft) 3-4-3 stacks "
                 "collapse to a flatter packing (section y = -1 mm; grey: warp centrelines)", fontsize=10)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    print(out)


if __name__ == "__main__":
    main()
