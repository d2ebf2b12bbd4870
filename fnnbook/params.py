"""A notebook's ``parameters`` cell, and the checks on what a task passes to it.

Each notebook has one code cell tagged ``parameters`` that holds plain
literal assignments (``seed = 0``, ``hidden = [50, 50]``).  Those are the
names a task may set, and their values fix the types it may pass.  A
notebook of the book has its settings in one home, the frozen dataclass of
its module in :mod:`fnnbook.tasks`: the runner takes the names and paper
values from there (:func:`task_defaults`), and its cell lists the same
values, written from the dataclass by :func:`parameters_cell` (``make
notebooks``).  The runner also injects ``profile`` and ``out_dir``
(always), ``data_dir`` and ``upstream_dirs`` (where declared).
"""

from __future__ import annotations

import ast
import difflib
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from fnnbook.spec import PipelineError, PipelineSpec, Task
from fnnbook.tasks import notebook_name, settings_class

__all__ = ["FINGERPRINT_FILE", "INJECTED", "SETTINGS_MARK", "check_task_parameters", "parameters_cell",
           "read_parameters", "resolve_parameters", "task_defaults", "upstream_parameters"]

INJECTED = ("profile", "out_dir", "data_dir", "upstream_dirs")
#: the record the runner writes beside a task's products: its fingerprint and the parameters it ran with
FINGERPRINT_FILE = ".fingerprint.json"
_REQUIRED_DECLARED = ("profile", "out_dir")


def read_parameters(notebook: str | os.PathLike[str]) -> dict[str, Any]:
    """Return the defaults declared in a notebook's ``parameters`` cell.

    Parameters
    ----------
    notebook : path-like
        An ``.ipynb`` file (nbformat 4).

    Returns
    -------
    dict
        Name -> default value, in the cell's order.

    Raises
    ------
    PipelineError
        If the notebook has no (or several) cells tagged ``parameters``, or
        the cell holds anything but assignments of literals to plain names.
    """
    path = Path(notebook)
    try:
        nb = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise PipelineError(f"notebook {path} cannot be read as JSON: {exc}") from exc
    if not isinstance(nb, dict) or nb.get("nbformat") != 4 or not isinstance(nb.get("cells"), list):
        raise PipelineError(f"notebook {path} is not an nbformat-4 notebook")
    cells = [c for c in nb["cells"]
             if c.get("cell_type") == "code" and "parameters" in c.get("metadata", {}).get("tags", [])]
    if not cells:
        raise PipelineError(f"notebook {path.name}: no code cell is tagged 'parameters' "
                            "(add the tag to the cell holding the defaults)")
    if len(cells) > 1:
        raise PipelineError(f"notebook {path.name}: {len(cells)} cells are tagged 'parameters'; "
                            "keep exactly one")
    source = cells[0].get("source", "")
    if isinstance(source, list):
        source = "".join(source)
    try:
        tree = ast.parse(source)
    except SyntaxError as exc:
        raise PipelineError(f"notebook {path.name}: the parameters cell is not plain Python "
                            f"(line {exc.lineno}: {exc.msg})") from exc
    defaults: dict[str, Any] = {}
    for stmt in tree.body:
        if isinstance(stmt, ast.Assign) and len(stmt.targets) == 1 and isinstance(stmt.targets[0], ast.Name):
            name, value = stmt.targets[0].id, stmt.value
        elif isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name) and stmt.value is not None:
            name, value = stmt.target.id, stmt.value
        else:
            raise PipelineError(f"notebook {path.name}: the parameters cell may hold only "
                                f"`name = literal` lines; line {stmt.lineno} is "
                                f"`{ast.get_source_segment(source, stmt)}`")
        try:
            literal = ast.literal_eval(value)
        except ValueError as exc:
            raise PipelineError(f"notebook {path.name}: parameter {name!r} (line {stmt.lineno}) "
                                f"is not a literal: `{ast.get_source_segment(source, value)}`") from exc
        if name in defaults:
            raise PipelineError(f"notebook {path.name}: parameter {name!r} is assigned twice")
        defaults[name] = literal
    return defaults


def _book(task: Task) -> str | None:
    """The name of the book's notebook a task runs (None for a notebook of your own)."""
    try:
        return notebook_name(task.notebook)
    except ValueError as exc:
        raise PipelineError(f"task {task.name!r}: {exc}") from exc


def task_defaults(task: Task, declared: Mapping[str, Any]) -> dict[str, Any]:
    """The names a task may set and their defaults: for a notebook of the book, the injected names its cell
    declares and every setting of its dataclass with its paper value (:mod:`fnnbook.tasks`); for another
    notebook, its ``parameters`` cell (``declared``, from :func:`read_parameters`).

    Raises
    ------
    PipelineError
        If the notebook imports a settings module that is not one of the book's.
    """
    name = _book(task)
    if name is None:
        return dict(declared)
    injected = {k: v for k, v in declared.items() if k in INJECTED}
    return {**injected, **settings_class(name).defaults()}  # loads the library (torch): not in the workers


def _type_ok(default: Any, value: Any) -> bool:
    """Whether ``value`` may replace ``default`` (see :func:`check_task_parameters`)."""
    if default is None:
        return True
    if isinstance(default, bool) or isinstance(value, bool):
        return isinstance(default, bool) and isinstance(value, bool)
    if isinstance(default, float):
        return isinstance(value, (int, float))
    if isinstance(default, (list, tuple)):
        if not isinstance(value, (list, tuple)):
            return False
        kinds = [d for d in default if d is not None]
        if not kinds:
            return True
        # a homogeneous default list fixes its elements' type: [16, 16] refuses [16, "a"] and [16, 16.7]
        return all(any(_type_ok(d, v) for d in kinds) for v in value)
    if isinstance(default, Mapping):
        return isinstance(value, Mapping)
    return isinstance(value, type(default))


def _type_name(value: Any) -> str:
    return "None" if value is None else type(value).__name__


def check_task_parameters(task: Task, profile: str, declared: Mapping[str, Any]) -> None:
    """Check one task's parameters for one profile against its notebook's defaults.

    Names and defaults: :func:`task_defaults` (a notebook of the book: its settings dataclass). Types: a
    ``None`` default accepts anything; a float default accepts int
    or float; a bool is accepted only where the default is a bool; a list
    (or tuple) default accepts a list whose every element passes this rule
    against some element of the default (an empty default accepts any
    list); otherwise the type must match.

    Parameters
    ----------
    task : Task
    profile : str
    declared : mapping
        The notebook's defaults, from :func:`read_parameters`.

    Raises
    ------
    PipelineError
        Naming task, profile and parameter, for a missing profile, an
        injected name set by the task, an unknown name (with close matches)
        or a wrong type; also when the notebook lacks ``profile``/``out_dir``
        or, for a task with upstream tasks, ``upstream_dirs``.
    """
    nb = task.notebook.name
    for name in _REQUIRED_DECLARED:
        if name not in declared:
            raise PipelineError(f"task {task.name!r}: notebook {nb} must declare {name!r} in its "
                                "parameters cell (the runner injects it)")
    if task.upstream and "upstream_dirs" not in declared:
        raise PipelineError(f"task {task.name!r} has upstream tasks ({', '.join(task.upstream)}) "
                            f"but notebook {nb} does not declare 'upstream_dirs' in its parameters cell")
    if profile not in task.parameters:
        raise PipelineError(f"task {task.name!r} has no parameters for profile {profile!r} "
                            f"(it has: {', '.join(task.parameters)})")
    defaults = task_defaults(task, declared)
    choices = [n for n in defaults if n not in INJECTED]
    for name, value in task.parameters[profile].items():
        where = f"task {task.name!r}, profile {profile!r}, parameter {name!r}"
        if name in INJECTED:
            raise PipelineError(f"{where}: {name!r} is injected by the runner; "
                                "remove it from pipeline.yaml")
        if name not in defaults:
            close = difflib.get_close_matches(name, choices, n=3)
            hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
            book = _book(task)
            home = f"the parameters cell of {nb}" if book is None else f"{nb}'s settings (fnnbook.tasks.{book})"
            raise PipelineError(f"{where}: not declared in {home}{hint}")
        default = defaults[name]
        if not _type_ok(default, value):
            raise PipelineError(f"{where}: got {_type_name(value)} {value!r}, but the notebook's "
                                f"default is {_type_name(default)} {default!r}")
    for name in INJECTED:
        if name in declared and declared[name] is not None:
            expected: Any = {} if name == "upstream_dirs" else ""
            if not _type_ok(declared[name], expected):
                raise PipelineError(f"task {task.name!r}: notebook {nb} declares {name!r} with a "
                                    f"{_type_name(declared[name])} default; the runner injects "
                                    f"a {_type_name(expected)}")


def resolve_parameters(
    spec: PipelineSpec,
    task: Task,
    profile: str,
    declared: Mapping[str, Any],
    *,
    out_dir: str | os.PathLike[str],
) -> dict[str, Any]:
    """Return the parameters papermill injects into ``task``'s notebook.

    Every default of the notebook (:func:`task_defaults`: a notebook of the
    book's every paper value, from its settings dataclass), updated by the task's
    profile overrides (so the executed notebook shows every value the run
    used), plus ``profile``, ``out_dir``, and where
    the notebook declares them ``data_dir`` (a string) and ``upstream_dirs``
    (task name -> last good output folder of each upstream task).  Call
    :func:`check_task_parameters` first.

    Raises
    ------
    PipelineError
        If the notebook declares ``data_dir`` and the pipeline has none, or
        it does not exist.
    """
    params: dict[str, Any] = {k: v for k, v in task_defaults(task, declared).items() if k not in INJECTED}
    params.update(task.parameters[profile])
    params["profile"] = spec.home(profile, task.name)  # a task inherited from the paper profile runs as there
    params["out_dir"] = str(out_dir)
    if "data_dir" in declared:
        if spec.data_dir is None:
            raise PipelineError(f"task {task.name!r}: notebook declares 'data_dir' but the pipeline "
                                "has no data_dir (set it in pipeline.yaml or pass --data-dir)")
        if not spec.data_dir.is_dir():
            raise PipelineError(f"task {task.name!r}: data_dir {spec.data_dir} does not exist")
        params["data_dir"] = str(spec.data_dir)
    if "upstream_dirs" in declared:
        params["upstream_dirs"] = {up: str(spec.output_dir(profile, up)) for up in task.upstream}
    return params


def upstream_parameters(upstream_dir: str | os.PathLike[str]) -> dict[str, Any]:
    """The parameters an upstream task's last good run used, from the record the runner keeps beside its outputs.

    A downstream notebook that must do what its upstream did (fly the same flight, read the same data) takes
    the values from here rather than declaring them again.

    Raises
    ------
    PipelineError
        If ``upstream_dir`` has no readable run record (the task was not run by ``fnn-pipeline``).
    """
    path = Path(upstream_dir) / FINGERPRINT_FILE
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
        return dict(record["parameters"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise PipelineError(f"{path}: no run record with the upstream task's parameters ({exc}); run the "
                            "upstream task with fnn-pipeline first") from exc


# ---------------------------------------------------------------- the cell, written from the dataclass
#: the comment line of a ``parameters`` cell below which the settings are written from the dataclass
SETTINGS_MARK = "# the settings and their paper values, from fnnbook.tasks.{name} (written by `make notebooks`)"


def _literal(value: Any) -> str:
    """A plain value as Python source: strings in double quotes."""
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(_literal(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_literal(k)}: {_literal(v)}" for k, v in value.items()) + "}"
    return repr(value)


def _assignment(name: str, value: Any, width: int = 115) -> list[str]:
    """``name = value``, a long list wrapped after its commas, its later lines under its first element."""
    line = f"{name} = {_literal(value)}"
    if len(line) <= width or not isinstance(value, list):
        return [line]
    lines, indent = [f"{name} = ["], " " * (len(name) + 4)
    for i, v in enumerate(value):
        item = _literal(v) + ("]" if i == len(value) - 1 else ",")
        if len(lines[-1]) + 1 + len(item) > width and not lines[-1].endswith("["):
            lines.append(indent + item)
        else:
            lines[-1] += ("" if lines[-1].endswith("[") else " ") + item
    return lines


def parameters_cell(notebook: str, cell: str) -> str:
    """A notebook's ``parameters`` cell with its settings written from its dataclass, one line a setting.

    ``cell`` is the cell as it is: its lines above :data:`SETTINGS_MARK` (the names the runner injects:
    ``profile``, ``out_dir``, ``data_dir``, ``upstream_dirs``) are kept; the mark and the paper values follow.
    """
    settings = settings_class(notebook)
    mark = SETTINGS_MARK.format(name=settings.notebook)
    kept = cell.split(mark)[0].rstrip("\n").splitlines()
    if mark not in cell:  # a cell not yet written: keep its assignments of the injected names
        kept = []
        for stmt in ast.parse(cell).body:
            target = stmt.targets[0] if isinstance(stmt, ast.Assign) else getattr(stmt, "target", None)
            if isinstance(target, ast.Name) and target.id in INJECTED:
                kept.append(ast.get_source_segment(cell, stmt) or "")
    lines = [*kept, mark]
    for setting, value in settings.defaults().items():
        lines += _assignment(setting, value)
    return "\n".join(lines) + "\n"
