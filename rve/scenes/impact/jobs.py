"""The Snakemake job bodies of the impact (workflow/rules/impact.smk).

Contract
--------
* ``impact_job(config_path, out_dir, summary_path, log_path, overrides=(), relaxed=None,
  relax_only=False) -> dict``: one run of the scene, its summary written atomically;
* ``sweep_curve(summary_paths, currents, out_png, out_json) -> dict``: the current-density
  sweep's figure and table from its runs' summaries.
"""
from __future__ import annotations

import json
from pathlib import Path

from ...config.loader import load_config
from ...io.atomic import atomic_path, atomic_write_text
from ...io.provenance import to_jsonable
from ..protocol import job_log
from .scene import config_digest, load_or_relax, run

__all__ = ["impact_job", "sweep_curve"]


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
