"""The Snakemake job bodies of the induced deformation (workflow/rules/induced_deformation.smk).

Contract: ``orientation_job(config_path, orientation, out_dir, summary_path, log_path,
overrides=()) -> dict``: one field orientation of the scene, its summary written atomically.
"""
from __future__ import annotations

import json
from pathlib import Path

from ...config.loader import load_config
from ...io.atomic import atomic_path, atomic_write_text
from ..protocol import job_log
from ..registry import run_scene

__all__ = ["orientation_job", "current_sweep_curve"]


def orientation_job(config_path, orientation: str, out_dir, summary_path, log_path, overrides=()) -> dict:
    """One Snakemake job (workflow/rules/induced_deformation.smk): the scene of ``config_path``
    with ``field.orientation = orientation`` (+ ``overrides``), outputs under ``out_dir``,
    the summary written (atomically) to ``summary_path``, the log to ``log_path``."""
    with job_log(log_path):
        cfg = load_config(config_path, [f"field.orientation={orientation}", *overrides])
        summary = run_scene(cfg, out_dir)
        atomic_write_text(Path(summary_path), json.dumps(summary, indent=2, default=str))
        return summary


def current_sweep_curve(run_dirs, currents, out_png, out_json) -> dict:
    """The warp-current sweep (module docstring): one run directory per |J_bar| (A/mm^2)."""
    import matplotlib
    import numpy as np
    import xarray as xr

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows, series = [], []
    for d, J in zip(run_dirs, currents):
        s = json.loads((Path(d) / "summary.json").read_text())
        with xr.open_dataset(Path(d) / "induced_deformation.nc") as ds:
            warp = [i for i, n in enumerate(ds["fibril"].values) if str(n).startswith("warp")]
            pos = np.asarray(ds["position"].values, float)[:, warp]          # (time, warp, node, xyz)
            defl = (pos - pos[:1]).mean(axis=(1, 2))                          # mean warp displacement
            t = np.asarray(ds["time"].values, float)
            ts = np.asarray(ds["step_time"].values, float)
            Tmax = np.asarray(ds["max_temperature"].values, float) if "max_temperature" in ds else None
        rows.append({"J_A_per_mm2": float(J), "mean_displacement_mm": s["mean_displacement_mm"],
                     "peak_mean_deflection_z_mm": float(np.max(defl[:, 2])),
                     "max_temperature_K": float(s["max_temperature_K"]),
                     "terminal_current_A": float(s["terminal_current_A"]),
                     "time_control": s.get("time_control", "fixed"), "steps_accepted": s["steps_accepted"],
                     "balance_errors": s.get("balance_errors", {})})
        series.append((float(J), t, defl, ts, Tmax))
    fig, ax = plt.subplots(1, 4, figsize=(15, 3.6), dpi=110)
    for J, t, defl, ts, Tmax in series:
        ax[0].plot(t, defl[:, 2], label=f"|J| = {J:g} A/mm$^2$")
        ax[1].plot(t, defl[:, 1], label=f"{J:g}")
        if Tmax is not None:
            ax[2].plot(ts, Tmax, label=f"{J:g}")
    for a, lab in zip(ax[:3], ("mean warp deflection z (mm)", "mean warp deflection y (mm)", "max T (K)")):
        a.set_xlabel("t (ms)")
        a.set_ylabel(lab)
    ax[0].legend(fontsize=8)
    J = [r["J_A_per_mm2"] for r in rows]
    # the warp bounces: its peak lift, not the value at t_end, is the measure of the force
    ax[3].plot(J, [r["peak_mean_deflection_z_mm"] for r in rows], "o-", label="peak mean deflection z (mm)")
    ax3 = ax[3].twinx()
    ax3.plot(J, [r["max_temperature_K"] for r in rows], "s--", color="C3", label="max T at t_end (K)")
    ax[3].set_xlabel("|J_bar| warp (A/mm^2)")
    ax[3].set_ylabel("peak mean deflection z (mm)")
    ax3.set_ylabel("max T at t_end (K)")
    for a in ax:
        a.grid(alpha=0.3)
    fig.suptitle("Induced deformation: warp-current sweep", fontsize=10)
    fig.tight_layout()
    with atomic_path(Path(out_png)) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    atomic_write_text(Path(out_json), json.dumps(rows, indent=2, default=float))
    return {"rows": rows}
