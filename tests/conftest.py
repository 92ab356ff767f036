"""Shared test configuration.

The ``slow`` marker (registered in pyproject.toml) marks tests that run a Snakemake
pipeline or a long study; ``pytest -m "not slow"`` skips them (under 3 minutes on 2
cores), the README's plain ``pytest`` runs everything. A test that uses one of the
pipeline fixtures below is marked automatically, so a new test of a pipeline product
cannot forget it.
"""
from __future__ import annotations

import pytest

#: fixtures that run a whole Snakemake pipeline (tests/test_rve_pipeline.py,
#: tests/test_static_wire_study.py)
PIPELINE_FIXTURES = {"test_rve_pipeline": {"ci_run", "table"}, "test_static_wire_study": {"ci_run", "ci_dataset"}}


def pytest_collection_modifyitems(config, items):
    for item in items:
        module = getattr(item, "module", None)
        names = PIPELINE_FIXTURES.get(module.__name__.rpartition(".")[2] if module else "", set())
        if names & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.slow)
