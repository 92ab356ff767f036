"""Every YAML under configs/: scene configs pass `rve validate` and `rve schema <scene>`;
pipeline configs are refused in one line (docs/configuration.md, "Pipeline configs")."""
import json
from pathlib import Path

import pytest
import yaml

from rve import cli
from rve.config import PIPELINE_KEYS
from rve.scenes.registry import SCENES

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "configs").rglob("*.yaml"))
PIPELINE = {"configs/pipeline.yaml", "configs/tests/pipeline_ci.yaml", "configs/pipeline_periodic.yaml",
            "configs/tests/pipeline_periodic.yaml"}


def test_the_list_is_complete():
    assert PIPELINE <= set(CONFIGS)
    assert {"configs/scenes/static_wire.yaml", "configs/scenes/dynamic_wire.yaml",
            "configs/scenes/plain_weave_relax.yaml", "configs/rve/plain_weave.yaml", "configs/rve/knit.yaml"} \
        <= set(CONFIGS)


@pytest.mark.parametrize("path", CONFIGS)
def test_shipped_config(path, capsys):
    raw = yaml.safe_load((ROOT / path).read_text())
    if path in PIPELINE:
        assert "scene" not in raw and set(raw) <= set(PIPELINE_KEYS)
        assert cli.main(["validate", str(ROOT / path)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "a pipeline config" in err[0] and "not a scene config" in err[0], err
        return
    scene = raw["scene"]
    assert scene in SCENES
    assert cli.main(["validate", str(ROOT / path)]) == 0, capsys.readouterr().err
    assert "valid" in capsys.readouterr().out
    assert cli.main(["validate", "--json", str(ROOT / path)]) == 0
    assert json.loads(capsys.readouterr().out)["scene"] == scene
    assert cli.main(["schema", scene]) == 0
    schema = json.loads(capsys.readouterr().out)
    assert schema["properties"]["scene"]["const"] == scene or scene in json.dumps(schema["properties"]["scene"])
    assert set(raw) <= set(schema["properties"])


def test_pipeline_runs_reference_valid_rve_configs(capsys):
    """The RVE runs of both pipeline configs name scene configs that validate (inline keys
    and overrides applied)."""
    from rve.homogenisation.sweeps import combo_ids, load_run_config

    for path in sorted(PIPELINE):
        rve = yaml.safe_load((ROOT / path).read_text())["rve"]
        runs = rve.get("runs") or {}   # an overlay config (configs/pipeline_periodic.yaml) may name none
        # a work-precision study may name runs of levers the config does not know yet: the
        # study skips those (rve.homogenisation.layout.work_precision_runs); only an unknown key
        # is such a reason
        waiting = {r for st in (rve.get("work_precision") or {}).values()
                   for r in [st["reference"], *st["levers"].values()]}
        for name, spec in runs.items():
            spec = dict(spec)
            if name in waiting:
                from rve.homogenisation.layout import _config_refusal

                why = _config_refusal(spec if not spec.get("scene_config") else
                                      {**spec, "scene_config": str(ROOT / spec["scene_config"])}, name)
                assert why is None or "unknown key" in why, (path, name, why)
                continue
            if spec.get("scene_config"):
                spec["scene_config"] = str(ROOT / spec["scene_config"])
            for combo in combo_ids(spec):
                assert load_run_config(spec, combo).scene == "rve", (path, name, combo)
