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
    for rel in CONFIGS:
        (dest / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / rel, dest / rel)
    return dest
