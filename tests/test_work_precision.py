"""Work-precision study (rve.studies.work_precision) on synthetic per-run tables: every run's
error against the one reference on the stated (magnitude) and the range measure is the
closed-form difference, the
front is the non-dominated set, a skipped lever is listed, and the accuracy file it writes
is read back by the gather's reader (rve.tables.accuracy)."""
from __future__ import annotations

import json

import numpy as np
import pytest
import xarray as xr

from rve.studies.table_convergence import RANGE_FLOOR, combo_costs
from rve.studies.work_precision import (STATED_MEASURE, front_of, pareto_front, run_errors, stated, study_points,
                                       target_misses, work_precision_job)
from rve.tables.accuracy import annotate_accuracy, read_accuracy

STRAIN = np.linspace(0.0, 0.2, 5)
MODES = ["uniaxial", "shear"]


def _table(dR=0.0, dF=0.0, sweep=None):
    """R(eps) = 10 + 5 eps (+ dR), F(eps) = 40 eps - 2 (crosses zero; + dF at the last strain)."""
    R = np.broadcast_to(10.0 + 5.0 * STRAIN, (2, 5)).copy() + dR
    F = np.zeros((2, 5, 1, 3))
    F[:, :, 0, 0] = 40.0 * STRAIN - 2.0
    F[:, -1, 0, 0] += dF
    ds = xr.Dataset({"probe_resistance": (("mode", "strain", "probe"), R[..., None]),
                     "reaction_force": (("mode", "strain", "side", "component"), F)},
                    coords={"mode": MODES, "strain": STRAIN, "probe": ["probe1"], "side": ["x+"],
                            "component": ["x", "y", "z"]})
    if sweep is None:
        return ds
    dim, vals, tables = sweep
    return xr.concat([t.expand_dims({dim: [v]}) for v, t in zip(vals, tables)], dim=dim).transpose("mode", "strain",
                                                                                                  dim, ...)


def test_errors_against_the_reference_are_the_closed_form_errors():
    ref = _table()
    e = run_errors(_table(dR=0.05, dF=0.6), ref)
    # R: range over the path 1.0 (5 x 0.2), floor 0.05 x 11 = 0.55 -> 0.05 / 1.0
    assert e["range"]["probe_resistance"] == pytest.approx(0.05 / 1.0)
    assert e["magnitude"]["probe_resistance"] == pytest.approx(0.05 / 11.0)
    # F from -2 to 6: range 8, max |F| 6
    assert e["range"]["reaction_force"] == pytest.approx(0.6 / 8.0)
    assert e["magnitude"]["reaction_force"] == pytest.approx(0.6 / 6.0)
    assert e["range_by_mode"]["reaction_force"] == {"uniaxial": pytest.approx(0.075), "shear": pytest.approx(0.075)}
    assert e["magnitude_by_mode"]["reaction_force"] == {"uniaxial": pytest.approx(0.1), "shear": pytest.approx(0.1)}
    assert STATED_MEASURE == "magnitude" and stated(e) == e["magnitude"]
    assert RANGE_FLOOR * 11.0 < 1.0


def test_quantities_of_different_cells_or_probes_are_not_compared():
    """A per-cell force between cells of different size, and resistances of disjoint probe
    sets, get no error; such a run is not on the front (it omits targeted quantities)."""
    ref = _table().assign_coords(cell_length_x=4.0, cell_length_y=4.0)
    other = _table(dR=0.001, dF=0.001).assign_coords(cell_length_x=8.0, cell_length_y=8.0, probe=["field_x"])
    e = run_errors(other, ref)
    assert e["range"] == {} and set(e["not_compared"]) >= {"reaction_force", "probe_resistance"}
    same = run_errors(_table(dF=0.6).assign_coords(cell_length_x=4.0, cell_length_y=4.0), ref)
    assert same["range"]["reaction_force"] == pytest.approx(0.6 / 8.0) and "reaction_force" not in same["not_compared"]
    pts = study_points(ref, ("wp_default", _table(dR=0.2).assign_coords(cell_length_x=4.0, cell_length_y=4.0)),
                       {"boundary": ("wp_boundary", other)}, {})
    assert pts[1]["missing"] == ["reaction_force", "probe_resistance"] and not pts[1]["meets"]
    assert front_of(pts) == []   # no cost: nothing on the front; the incomplete run never is
    # the stated (magnitude) measure: 0.2 / max R 11
    assert pts[0]["missing"] == [] and target_misses(pts[0]["errors"]) == {"probe_resistance": (pytest.approx(0.2 / 11),
                                                                                               0.01)}


def test_pareto_front():
    pts = [(10.0, 0.5), (20.0, 0.2), (15.0, 0.6), (40.0, 0.2), (5.0, 2.0), (np.nan, 0.01)]
    assert pareto_front(pts) == [4, 0, 1]


def _bench(root, run, combo, cpu):
    p = root / run / combo / "strain" / "uniaxial_01.tsv"
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text("s\th:m:s\tmax_rss\tmax_vms\tmax_uss\tmax_pss\tio_in\tio_out\tmean_load\tcpu_time\n"
                 f"{cpu + 1}\t0:00:01\t100.0\t1\t1\t1\t0\t0\t90\t{cpu}\n")


def test_report_on_synthetic_runs(tmp_path):
    ref = _table()
    default = _table(dR=0.15, dF=0.08)
    elements = _table(sweep=("mesh_elements", [4.0, 12.0], [_table(dR=0.1, dF=0.4), _table(dR=0.005, dF=0.01)]))
    bench = tmp_path / "bench"
    _bench(bench, "wp_default", "base", 10.0)
    _bench(bench, "wp_elements", "mesh_elements-4", 4.0)
    _bench(bench, "wp_elements", "mesh_elements-12", 30.0)
    costs = {r: combo_costs(bench, r) for r in ("wp_default", "wp_elements", "wp_ref")}
    out = {k: tmp_path / f"wp.{k}" for k in ("md", "csv", "png", "json")}
    skipped = {"boundary": "run wp_boundary: boundary: unknown key (allowed: scene, fabric, ...)"}
    acc = work_precision_job(ref, ("wp_default", default), {"elements": ("wp_elements", elements)}, costs, skipped,
                             out, None, {"study": "wp", "reference": "wp_ref"},
                             {"mesh_elements": 6.0, "contact_penalty": 50.0, "mesh_order": 1, "contact_n_gp": 4})
    assert acc["front"] == ["elements: mesh_elements-4", "default: base", "elements: mesh_elements-12"]  # by CPU
    # the magnitude measure: dR / max R (11), dF / max |F| (6)
    assert acc["measure"] == "magnitude"
    assert acc["stated_relative_error"]["probe_resistance"] == pytest.approx(0.15 / 11)
    assert acc["stated_relative_error"]["reaction_force"] == pytest.approx(0.08 / 6)
    assert acc["range_relative_error"]["probe_resistance"] == pytest.approx(0.15)
    runs = {(r["lever"], r["combo"]): r for r in acc["runs"]}
    assert runs[("elements", "mesh_elements-4")]["range_error"]["probe_resistance"] == pytest.approx(0.1)
    assert runs[("elements", "mesh_elements-12")]["cpu_s"] == pytest.approx(30.0)
    text = out["md"].read_text()
    assert "boundary: run wp_boundary: boundary: unknown key" in text and "| elements | mesh_elements = 4 |" in text
    # front: 4 el (cheapest), the default (cheaper than 12 el); 12 el is the most accurate: all three
    rows = [[c.strip() for c in line.split("|")[1:-1]] for line in text.splitlines() if line.startswith("| ")][1:]
    assert sorted(r[1] for r in rows if r[-2] == "yes") == ["base", "mesh_elements = 12", "mesh_elements = 4"]
    # meets: 12 el is within every target (R 0.045 %, F 0.17 %), the default's R 1.36 % is not (4 el: F 6.7 %)
    assert {r[1]: r[-1] for r in rows} == {"base": "no", "mesh_elements = 4": "no", "mesh_elements = 12": "yes"}
    assert "Probe resistance 1.36 % > 1 % (1.36 x)".lower() in text.lower()
    assert out["png"].stat().st_size > 0 and "range_error" in out["csv"].read_text()
    # the gather's reader takes the file; the annotation is the default's stated error
    read = read_accuracy(out["json"])
    table = _table()
    table.attrs["config"] = json.dumps({"scene": {"mesh": {"order": 1}, "contact": {"n_gp": 4}}})
    done = annotate_accuracy(table, read, 6, 50.0, source="wp.json")
    assert sorted(done) == ["probe_resistance", "reaction_force"]
    assert table["probe_resistance"].attrs["estimated_relative_error"] == pytest.approx(0.15 / 11)
    assert table["reaction_force"].attrs["estimated_relative_error_shear"] == pytest.approx(0.08 / 6)
    assert "estimated_relative_error_mesh" not in table["probe_resistance"].attrs
    # another p is not the study's default: not annotated
    other = _table()
    other.attrs["config"] = json.dumps({"scene": {"mesh": {"order": 2}, "contact": {"n_gp": 4}}})
    assert annotate_accuracy(other, read, 6, 50.0) == []
    # a periodic study's file does not annotate a pinned table of the same mesh and penalty
    periodic = json.loads(out["json"].read_text())
    periodic["default"].update(boundary="periodic", cell_repeat=1)
    pinned = _table()
    pinned.attrs["config"] = json.dumps({"scene": {"mesh": {"order": 1}, "contact": {"n_gp": 4}}})
    assert annotate_accuracy(pinned, periodic, 6, 50.0) == []
    pinned.attrs["config"] = json.dumps({"scene": {"mesh": {"order": 1}, "contact": {"n_gp": 4}, "boundary": "periodic",
                                                   "cell": {"repeat": 2}}})
    assert annotate_accuracy(pinned, periodic, 6, 50.0) == []
    # a study of another contact geometry or enforcement does not annotate a chord penalty table
    for key, value in (("contact_geometry", "smooth"), ("contact_enforcement", "augmented_lagrangian")):
        smooth = json.loads(out["json"].read_text())
        smooth["default"][key] = value
        chord = _table()
        chord.attrs["config"] = json.dumps({"scene": {"mesh": {"order": 1}, "contact": {"n_gp": 4}}})
        assert annotate_accuracy(chord, smooth, 6, 50.0) == []
        chord.attrs["config"] = json.dumps({"scene": {"mesh": {"order": 1}, "contact": {
            "n_gp": 4, key.removeprefix("contact_"): value}}})
        assert annotate_accuracy(chord, smooth, 6, 50.0) != []
