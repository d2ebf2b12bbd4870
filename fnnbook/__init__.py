"""Run the reproduction's notebooks as a checked, incremental pipeline.

>>> spec = load_spec("pipeline.yaml")            # doctest: +SKIP
>>> report = run(spec, "smoke", ["spiral"])       # doctest: +SKIP
"""

from __future__ import annotations

import importlib
from typing import Any

#: public name -> the submodule that defines it. Imported on first use (PEP 562), so a notebook that only
#: needs ``fnnbook.rules`` does not load the runner, papermill and dask (~1.7 s of CPU per kernel).
_HOME = {
    "check_task_parameters": "params", "read_parameters": "params", "resolve_parameters": "params",
    "run": "pipeline",
    "Plan": "runner", "RunReport": "outcome", "TaskOutcome": "outcome", "Status": "outcome", "Decision": "outcome", "check": "runner", "is_up_to_date": "runner",
    "Part": "spec", "PipelineError": "spec", "PipelineSpec": "spec", "Task": "spec", "load_spec": "spec",
}


def __getattr__(name: str) -> Any:
    if name not in _HOME:
        raise AttributeError(f"module 'fnnbook' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"fnnbook.{_HOME[name]}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_HOME])


__all__ = [
    "Part",
    "PipelineError",
    "PipelineSpec",
    "Plan",
    "RunReport",
    "Decision",
    "Status",
    "Task",
    "TaskOutcome",
    "check",
    "check_task_parameters",
    "is_up_to_date",
    "load_spec",
    "read_parameters",
    "resolve_parameters",
    "run",
]
