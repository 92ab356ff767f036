"""The Snakemake job bodies of the impact (workflow/rules/impact.smk).

Contract
--------
* ``impact_job(config_path, out_dir, summary_path, log_path, overrides=(), relaxed=None,
  relax_only=False) -> dict``: one run of the scene, its summary written atomically;
* ``sweep_curve(summary_paths, currents, out_png, out_json) -> dict``: the current-density
  sweep's figure and table from its runs' summaries.
* ``velocity_curve(run_dirs, speeds, out_png, out_json) -> dict``: the impact-speed sweep's
  figure (the projectile's speed lost over time, and the speed kept, tilt rate and peak
  temperature against the impact speed) and table, from each run's ``summary.json`` and
  ``impact.nc``.
"""
from __future__ import annotations

import json
from pathlib import Path

from ...config.loader import load_config
from ...io.atomic import atomic_path, atomic_write_text
from ...io.provenance import to_jsonable
from ..protocol import job_log
from .scene import config_digest, load_or_relax, run

__all__ = ["impact_job", "sweep_curve", "velocity_curve"]


def impact_job(config_path, out_dir, summary_path, log_path, overrides=(), relaxed=None, relax_only=False) -> dict:
    """One Snakemake job (workflow/rules/impact.smk): the scene of ``config_path`` (+
    ``overrides``), outputs under ``out_dir``, the summary written atomically to
    ``summary_path``, the log to ``log_path``; ``relaxed`` the relaxed-state file to use
    (made if missing); ``relax_only``: only the relaxation (the summary is its record)."""
    with job_log(log_path):
        ov = list(overrides)
        if relaxed is not None:
            ov.append(f"relaxation.state_file={relaxed}")
        cfg = load_config(config_path, ov)
        if relax_only:
            _, info = load_or_relax(cfg, Path(relaxed) if relaxed else Path(out_dir) / "relaxed_state.npz")
            summary = {"relaxation": info, "digest": config_digest(cfg)}
        else:
            summary = run(cfg, Path(out_dir))
        atomic_write_text(Path(summary_path), json.dumps(to_jsonable(summary), indent=2, default=str))
        return summary


def sweep_curve(summary_paths, currents, out_png, out_json) -> dict:
    """The designer's curve of a current-density sweep: final projectile speed, tilt rate and
    peak temperature against |J_bar| (one summary.json per current)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = []
    for p, J in zip(summary_paths, currents):
        s = json.loads(Path(p).read_text())
        rows.append({"J_A_per_mm2": float(J), "speed_mm_per_ms": -float(s["projectile_velocity_mm_per_ms"][2]),
                     "omega_x_rad_per_ms": float(s["projectile_angular_velocity_x_rad_per_ms"]),
                     "max_temperature_K": float(s["max_temperature_K"])})
    J = [r["J_A_per_mm2"] for r in rows]
    fig, ax = plt.subplots(1, 3, figsize=(12, 3.6), dpi=110)
    for a, key, lab in zip(ax, ("speed_mm_per_ms", "omega_x_rad_per_ms", "max_temperature_K"),
                           ("final speed (m/s)", "omega_x at t_end (rad/ms)", "max T (K)")):
        a.plot(J, [r[key] for r in rows], "o-")
        a.set_xlabel("|J_bar| warp (A/mm^2)")
        a.set_ylabel(lab)
        a.grid(alpha=0.3)
    fig.suptitle("Impact: current-density sweep", fontsize=10)
    fig.tight_layout()
    with atomic_path(Path(out_png)) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    atomic_write_text(Path(out_json), json.dumps(rows, indent=2))
    return {"rows": rows}


def velocity_curve(run_dirs, speeds, out_png, out_json) -> dict:
    """The impact-speed sweep (module docstring): one run directory per speed (mm/ms)."""
    import matplotlib
    import numpy as np
    import xarray as xr

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows, series = [], []
    for d, v0 in zip(run_dirs, speeds):
        s = json.loads((Path(d) / "summary.json").read_text())
        with xr.open_dataset(Path(d) / "impact.nc") as ds:
            t = np.asarray(ds["step_time"].values, float)
            vz = -np.asarray(ds["projectile_com_velocity"].values, float)[:, 2]
        v_end = -float(s["projectile_velocity_mm_per_ms"][2])
        rows.append({"speed_mm_per_ms": float(v0), "final_speed_mm_per_ms": v_end,
                     "speed_kept": v_end / float(v0) if float(v0) else float("nan"),
                     "omega_x_rad_per_ms": float(s["projectile_angular_velocity_x_rad_per_ms"]),
                     "max_temperature_K": float(s["max_temperature_K"]),
                     "balance_errors": s.get("balance_errors", {})})
        series.append((float(v0), t, vz))
    fig, ax = plt.subplots(1, 4, figsize=(15, 3.6), dpi=110)
    for v0, t, vz in series:
        ax[0].plot(t, v0 - vz, label=f"{v0:g} mm/ms")
    ax[0].set_xlabel("t (ms)")
    ax[0].set_ylabel("speed lost v0 - v(t) (mm/ms)")
    ax[0].legend(fontsize=8)
    v = [r["speed_mm_per_ms"] for r in rows]
    for a, key, lab in zip(ax[1:], ("speed_kept", "omega_x_rad_per_ms", "max_temperature_K"),
                           ("speed kept at t_end (fraction)", "omega_x at t_end (rad/ms)", "max T (K)")):
        a.plot(v, [r[key] for r in rows], "o-")
        a.set_xlabel("impact speed (mm/ms)")
        a.set_ylabel(lab)
    for a in ax:
        a.grid(alpha=0.3)
    fig.suptitle("Impact: projectile-speed sweep", fontsize=10)
    fig.tight_layout()
    with atomic_path(Path(out_png)) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    atomic_write_text(Path(out_json), json.dumps(to_jsonable(rows), indent=2))
    return {"rows": rows}
