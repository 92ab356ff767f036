"""The rve CLI (with a fake scene, independent of the physics) and atomic output."""
import json
import sys
import types
from pathlib import Path
from typing import Literal

import pytest
from pydantic import Field

from rve import cli
from rve.config import load_config
from rve.config.fields import Length, SceneConfig, Section
from rve.io.atomic import atomic_path, atomic_write_json, atomic_write_text
import rve.scenes as scenes
from rve.scenes import SceneFailure
from rve.scenes.registry import SCENES, Scene

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = ROOT / "configs" / "scenes" / "static_wire.yaml"


# --------------------------------------------------------------------------- validate / schema
def test_validate_default_config(capsys):
    assert cli.main(["validate", str(DEFAULT)]) == 0
    out = capsys.readouterr().out
    assert "field_magnitude: 0.001  # kT" in out
    assert "youngs_modulus: 0.01  # MPa" in out


def test_validate_output_is_a_valid_config(capsys, tmp_path):
    assert cli.main(["validate", str(DEFAULT), "--set", "mesh.order=3"]) == 0
    printed = tmp_path / "resolved.yaml"
    printed.write_text(capsys.readouterr().out)
    assert load_config(printed) == load_config(DEFAULT, ["mesh.order=3"])


def test_validate_json_with_units_override(capsys):
    assert cli.main(["validate", str(DEFAULT), "--json", "--set", "load.field_magnitude=3 T"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["load"]["field_magnitude"] == pytest.approx(3e-3)


@pytest.mark.parametrize(
    "override, key",
    [("mesh.order=5", "mesh.order"), ("geometry.colour=red", "geometry.colour"),
     ("load.field_magnitude=1 m", "load.field_magnitude")],
)
def test_validate_bad_set_exits_2(capsys, override, key):
    assert cli.main(["validate", str(DEFAULT), "--set", override]) == 2
    captured = capsys.readouterr()
    assert key in captured.err
    assert "Traceback" not in captured.err
    assert captured.out == ""


def test_missing_config_file_exits_2(capsys, tmp_path):
    assert cli.main(["validate", str(tmp_path / "nope.yaml")]) == 2
    assert "cannot read config file" in capsys.readouterr().err


def test_schema(capsys):
    assert cli.main(["schema", "static_wire"]) == 0
    schema = json.loads(capsys.readouterr().out)
    assert schema["required"] == ["scene"]
    assert cli.main(["schema", "nope"]) == 2
    assert "unknown scene" in capsys.readouterr().err


def test_usage_error_returns_code(capsys):
    assert cli.main([]) == 2
    assert cli.main(["frobnicate"]) == 2


# --------------------------------------------------------------------------- run (fake scene)
class FakeGeometry(Section):
    size: Length = Field(1.0, gt=0)


class FakeConfig(SceneConfig):
    """A scene that only echoes its config (tests only)."""

    scene: Literal["fake"]
    geometry: FakeGeometry = Field(default_factory=FakeGeometry)


@pytest.fixture
def fake_scene(monkeypatch):
    calls = []
    module = types.ModuleType("rve_fake_scene_for_tests")

    def run(cfg, out_dir):
        import logging
        import numpy as np

        assert isinstance(out_dir, Path) and out_dir.is_dir()
        calls.append((cfg, out_dir))
        logging.getLogger("rve.newton").info("fake newton iteration")
        return {"size_mm": cfg.geometry.size, "twice": np.float64(2 * cfg.geometry.size),
                "iterations": np.int64(3)}

    module.run = run
    module.FakeConfig = FakeConfig
    monkeypatch.setitem(sys.modules, module.__name__, module)
    monkeypatch.setitem(SCENES, "fake", Scene("fake", f"{module.__name__}:FakeConfig", module.__name__))
    return calls


def test_run_writes_summary(fake_scene, tmp_path, capsys):
    config = tmp_path / "tiny.yaml"
    config.write_text("scene: fake\ngeometry:\n  size: '2 cm'\n")
    out = tmp_path / "out"
    assert cli.main(["run", str(config), "--out", str(out), "--set", "geometry.size=3 cm"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["size_mm"] == pytest.approx(30.0)
    assert summary["twice"] == pytest.approx(60.0)
    assert summary["iterations"] == 3
    assert summary["provenance"]["config"]["geometry"]["size"] == pytest.approx(30.0)
    assert summary["provenance"]["overrides"] == ["geometry.size=3 cm"]
    assert load_config(out / "config.json").geometry.size == pytest.approx(30.0)
    printed = json.loads(capsys.readouterr().out)
    assert printed["size_mm"] == pytest.approx(30.0)
    assert len(fake_scene) == 1
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no temp files left


def test_run_default_out_dir(fake_scene, tmp_path, monkeypatch):
    config = tmp_path / "tiny.yaml"
    config.write_text("scene: fake\n")
    monkeypatch.chdir(tmp_path)
    assert cli.main(["run", str(config)]) == 0
    assert (tmp_path / "results" / "runs" / "tiny" / "summary.json").is_file()


def test_run_invalid_config_does_not_run(fake_scene, tmp_path, capsys):
    config = tmp_path / "tiny.yaml"
    config.write_text("scene: fake\ngeometry:\n  size: -1\n")
    assert cli.main(["run", str(config), "--out", str(tmp_path / "o")]) == 2
    assert "geometry.size = -1 mm: must be > 0" in capsys.readouterr().err
    assert fake_scene == []
    assert not (tmp_path / "o" / "summary.json").exists()


@pytest.fixture
def restore_rve_log_level():
    import logging

    logger = logging.getLogger("rve")
    level = logger.level
    yield
    logger.setLevel(level)


def test_run_verbose_logs_newton(fake_scene, tmp_path, caplog, restore_rve_log_level):
    import logging

    config = tmp_path / "tiny.yaml"
    config.write_text("scene: fake\n")
    assert cli.main(["run", str(config), "--out", str(tmp_path / "o")]) == 0
    assert not [r for r in caplog.records if r.name == "rve.newton"]
    assert cli.main(["run", str(config), "--out", str(tmp_path / "o"), "-v"]) == 0
    assert logging.getLogger("rve.newton").isEnabledFor(logging.INFO)
    assert any(r.name == "rve.newton" and "fake newton" in r.getMessage() for r in caplog.records)


def test_run_scene_api(fake_scene, tmp_path):
    cfg = load_config({"scene": "fake"})
    summary = scenes.run_scene(cfg, tmp_path / "new" / "dir")
    assert summary["size_mm"] == 1.0
    assert (tmp_path / "new" / "dir").is_dir()


def test_static_wire_is_registered():
    assert scenes.SCENES["static_wire"].runner == "rve.scenes.static_wire"
    assert scenes.SCENES["static_wire"].model.__name__ == "StaticWireConfig"


def test_scene_failure_is_one_message_and_exit_1(fake_scene, tmp_path, capsys):
    module = sys.modules["rve_fake_scene_for_tests"]

    def run(cfg, out_dir):
        failure = SceneFailure("fake", "Newton did not converge", phase="static", time=0.5, step=3,
                               state={"x": [1.0, 2.0]})
        failure.save(out_dir / "last.npz")
        raise failure

    module.run = run
    config = tmp_path / "tiny.yaml"
    config.write_text("scene: fake\n")
    assert cli.main(["run", str(config), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "phase 'static', t = 0.5 ms, step 3: Newton did not converge" in err[0]
    assert "last good state saved to" in err[0] and (tmp_path / "o" / "last.npz").is_file()
    assert not (tmp_path / "o" / "summary.json").exists()


def test_run_pipeline_scene_prints_the_snakemake_command(capsys, monkeypatch):
    monkeypatch.chdir(ROOT)
    assert cli.main(["run", "configs/rve/plain_weave.yaml"]) == 0
    cap = capsys.readouterr()
    assert cap.out.strip() == "snakemake -j2 results/rve/plain_weave/table.nc"
    assert len(cap.err.strip().splitlines()) == 1 and "pipeline scene" in cap.err
    assert cli.main(["run", "configs/rve/knit.yaml"]) == 0
    assert capsys.readouterr().out.strip() == "snakemake -j2 results/rve/knit/table.nc"
    # overrides: a run of its own, added with --config (plain_weave is taken: a hashed name)
    assert cli.main(["run", "configs/rve/plain_weave.yaml", "--set", "mesh.elements=12"]) == 0
    out = capsys.readouterr().out.strip()
    assert out.startswith("snakemake -j2 results/rve/plain_weave_")
    assert "--config 'rve={runs: {plain_weave_" in out
    assert '{scene_config: "configs/rve/plain_weave.yaml", overrides: ["mesh.elements=12"]}' in out


def test_pipeline_config_is_refused_in_one_line(capsys):
    for path in ("configs/pipeline.yaml", "configs/tests/pipeline_ci.yaml"):
        for cmd in ("validate", "run"):
            assert cli.main([cmd, str(ROOT / path)]) == 2
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and "a pipeline config" in err[0] and "not a scene config" in err[0]


# --------------------------------------------------------------------------- atomic IO
def test_atomic_write_text_and_json(tmp_path):
    p = atomic_write_text(tmp_path / "a" / "b" / "x.txt", "hello")
    assert p.read_text() == "hello"
    atomic_write_text(p, "again")
    assert p.read_text() == "again"
    import numpy as np

    j = atomic_write_json(tmp_path / "s.json", {"a": np.arange(3), "b": np.float32(1.5), "c": tmp_path})
    assert json.loads(j.read_text()) == {"a": [0, 1, 2], "b": 1.5, "c": str(tmp_path)}
    assert sorted(x.name for x in tmp_path.iterdir()) == ["a", "s.json"]


def test_atomic_path_keeps_old_file_on_failure(tmp_path):
    target = tmp_path / "table.nc"
    target.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            assert tmp.parent == tmp_path / tmp.parent.name  # same directory tree
            assert tmp.name == "table.nc"  # suffix kept for format detection
            tmp.write_text("partial")
            raise RuntimeError("writer crashed")
    assert target.read_text() == "old"
    assert [x.name for x in tmp_path.iterdir()] == ["table.nc"]


def test_atomic_path_replaces_on_success(tmp_path):
    target = tmp_path / "sub" / "plot.png"
    with atomic_path(target) as tmp:
        assert not target.exists()
        tmp.write_bytes(b"\x89PNG")
        assert not target.exists()  # only moved in at the end of the block
    assert target.read_bytes() == b"\x89PNG"
    assert [x.name for x in target.parent.iterdir()] == ["plot.png"]


def test_atomic_path_requires_a_file(tmp_path):
    with pytest.raises(FileNotFoundError):
        with atomic_path(tmp_path / "x.txt"):
            pass
    assert list(tmp_path.iterdir()) == []
