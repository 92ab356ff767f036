"""Shared by the Snakemake tests: the workflow and the configs it reads, copied into a
temporary folder so a test's results and `.snakemake/` state stay there."""
from __future__ import annotations

import shutil
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CI_CONFIG = "configs/tests/pipeline_ci.yaml"
CONFIGS = ("configs/pipeline.yaml", CI_CONFIG, "configs/scenes/static_wire.yaml")


def workflow_copy(dest: Path) -> Path:
    """Snakefile, workflow/ and the configs the CI DAGs read, copied into ``dest``."""
    shutil.copy2(ROOT / "Snakefile", dest / "Snakefile")
    shutil.copytree(ROOT / "workflow", dest / "workflow")
    # the whole configs/ tree: the default pipeline config names scene configs that the DAG
    # reads at parse time (e.g. the picture targets of configs/rve/plain_weave.yaml)
    shutil.copytree(ROOT / "configs", dest / "configs", dirs_exist_ok=True)
    for rel in CONFIGS:
        assert (dest / rel).exists(), rel
    return dest
