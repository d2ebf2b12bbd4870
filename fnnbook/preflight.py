"""The checks ``fnn-pipeline check`` (and the start of ``run``) adds to the parameter types: before any work.

Per task: its notebook's own value checks (its settings dataclass in :mod:`fnnbook.tasks`, the data files'
SHA-256 included), and the grid rule: a task that lists a grid task upstream gets every grid point's folder
in ``upstream_dirs`` (keyed by point name), so only an aggregate step, one that reads them all, may; a
notebook that reads the grid by its own name (``upstream_dirs["spiral"]``) is refused.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping
from typing import Any

from fnnbook.spec import PipelineError, PipelineSpec, Task

__all__ = ["check_grid_upstream", "check_task_values"]


def _code(task: Task) -> str:
    """The source of the notebook's code cells ("" if it cannot be read: read_parameters has said why)."""
    try:
        cells = json.loads(task.notebook.read_text(encoding="utf-8")).get("cells", [])
    except (OSError, ValueError, AttributeError):
        return ""
    return "\n".join("".join(c.get("source", "")) for c in cells if c.get("cell_type") == "code")


def check_grid_upstream(spec: PipelineSpec, task: Task, declared: Mapping[str, Any]) -> None:
    """Refuse a task that lists a grid upstream but reads it by the grid's name (it is not an aggregate step).

    Raises
    ------
    PipelineError
        Naming the task, the grid and its points.
    """
    listed = [g for g, points in spec.grids.items() if set(points) <= set(task.upstream)]
    if not listed:
        return
    default = declared.get("upstream_dirs")
    code = _code(task)
    for grid in listed:
        by_name = re.search(rf"upstream_dirs\s*(\[|\.get\()\s*[\"']{re.escape(grid)}[\"']", code)
        if by_name or (isinstance(default, Mapping) and grid in default):
            points = spec.grids[grid]
            raise PipelineError(
                f"task {task.name!r} lists the grid {grid!r} upstream but its notebook {task.notebook.name} reads "
                f"upstream_dirs[{grid!r}]; a grid's points come as upstream_dirs[{points[0]!r}], ... "
                f"({len(points)} points): only an aggregate step (a notebook that reads every entry of "
                "upstream_dirs) may list a grid upstream")


def check_task_values(task: Task, profile: str, params: Mapping[str, Any]) -> str:
    """Make the notebook's settings dataclass from the resolved parameters, which checks them (none for a notebook
    not of the book).

    Returns "" or, when only its data files are missing, why it cannot run.

    Raises
    ------
    PipelineError
        Naming task, profile and the bad value (or the data file whose SHA-256 is not the pinned one).
    """
    from fnnbook.params import INJECTED  # noqa: PLC0415
    from fnnbook.tasks import notebook_name, settings_class  # noqa: PLC0415
    from fnnlib.checks import MissingDataError  # noqa: PLC0415 (loads torch)
    from fnnlib.data.bottle import DataError  # noqa: PLC0415

    where = f"task {task.name!r}, profile {profile!r}"
    try:
        name = notebook_name(task.notebook)
        if name is None:
            return ""
        settings_class(name).from_mapping({k: v for k, v in params.items() if k not in INJECTED},
                                          data_dir=params.get("data_dir"))
    except MissingDataError as exc:
        return str(exc)
    except (ValueError, TypeError, DataError) as exc:
        raise PipelineError(f"{where}: {exc}") from exc
    return ""
