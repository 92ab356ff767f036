"""The scene protocol: set-up -> solve -> :class:`SceneResult`, or one :class:`SceneFailure`.

Contract
--------
Every in-process scene module (``rve.scenes.static_wire``, ``dynamic_wire``,
``fabric_relax``; listed in ``rve.scenes.registry``) exposes

* ``setup(cfg) -> problem``: the model (or system) of the validated config, with its
  boundary conditions, ready to solve; no solve, no files;
* ``solve(cfg, ...) -> SceneResult``: the whole computation in memory;
* ``run(cfg, out_dir) -> dict``: ``solve`` plus the scene's output files under
  ``out_dir``; returns the JSON-serialisable summary (``rve run`` writes summary.json).

A scene that cannot finish raises :class:`SceneFailure`: it says where (``phase``,
``time``, ``step``) and why, and carries the last good state (``state``, ``model``);
``run`` writes that state to ``out_dir`` first and records the file in ``saved``. ``rve
run`` turns it into one message and exit code 1 (docs/configuration.md).

``job_log(path)``: a context manager that sends the ``rve`` loggers (INFO) to ``path``
for the length of one Snakemake job body (``rve.scenes.*.jobs``).
"""
from __future__ import annotations

import contextlib
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np

__all__ = ["SceneResult", "SceneFailure", "job_log"]


@dataclass
class SceneResult:
    """What a scene's ``solve`` returns.

    ``state``: named arrays of the final state (``"x"`` positions/directors, ``"w"``
    rates and the field values where the scene has them, ...); ``model``: the model or
    system ``state`` belongs to (its ``layout`` gives the meaning of every dof);
    ``summary``: the scene's figures (what ``run`` returns, minus files)."""

    state: dict
    model: Any
    summary: dict


class SceneFailure(RuntimeError):
    """A scene gave up. ``why``: the cause; ``phase``/``time``/``step``: where; ``state``
    and ``model``: the last good state (None if there is none); ``details``: extra
    figures (e.g. the Newton residual history); ``saved``: the file holding the last
    good state once the scene's ``run`` wrote it. ``str()`` is the one-line message."""

    def __init__(self, scene: str, why: str, *, phase: Optional[str] = None, time: Optional[float] = None,
                 step: Any = None, state: Optional[dict] = None, model: Any = None,
                 details: Optional[dict] = None, saved: Optional[str] = None):
        self.scene = scene
        self.why = why
        self.phase = phase
        self.time = time
        self.step = step
        self.state = state
        self.model = model
        self.details = dict(details or {})
        self.saved = saved
        super().__init__(why)

    @property
    def where(self) -> str:
        """``phase 'time integration', t = 0.001 ms, step h = 1e-05 ms`` (the known parts)."""
        parts = []
        if self.phase:
            parts.append(f"phase {self.phase!r}")
        if self.time is not None:
            parts.append(f"t = {self.time:.9g} ms")
        if self.step is not None:
            parts.append(f"step {self.step}")
        return ", ".join(parts) or "unknown"

    @property
    def message(self) -> str:
        text = f"scene {self.scene} failed at {self.where}: {self.why}"
        if self.saved:
            text += f"; last good state saved to {self.saved}"
        return text

    def __str__(self) -> str:
        return self.message

    def save(self, path) -> Path:
        """Write the last good state to ``path`` (.npz, atomically): every array of
        ``state``, ``t`` (the time, if known), the numeric ``details`` (e.g. ``h``,
        ``residuals``) and the model's ``fields``; records ``path`` in ``saved``."""
        from ..io.atomic import atomic_path

        arrays = {k: np.asarray(v) for k, v in (self.state or {}).items()}
        if self.time is not None:
            arrays["t"] = np.asarray(self.time, float)
        for k, v in self.details.items():
            if k not in arrays and _numeric(v):
                arrays[k] = np.asarray(v, float)
        layout = getattr(self.model, "layout", None)
        if layout is not None:
            arrays["fields"] = np.array(layout.fields)
        path = Path(path)
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, **arrays)
        self.saved = str(path)
        return path


def _numeric(v) -> bool:
    try:
        a = np.asarray(v)
    except Exception:  # noqa: BLE001 - anything that is not array-like is skipped
        return False
    return a.dtype.kind in "biuf"


@contextlib.contextmanager
def job_log(log_path):
    """The ``rve`` loggers at INFO into ``log_path`` (overwritten) while the block runs."""
    handler = logging.FileHandler(log_path, mode="w")
    handler.setFormatter(logging.Formatter("%(asctime)s %(name)s %(levelname)s %(message)s"))
    root = logging.getLogger("rve")
    root.addHandler(handler)
    root.setLevel(logging.INFO)
    try:
        yield
    finally:
        root.removeHandler(handler)
        handler.close()
