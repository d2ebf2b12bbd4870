"""Load and validate ``pipeline.yaml``, the contract between notebooks and runs.

The file names the tasks (one notebook each), their upstream tasks, the files
they must produce and their parameters per profile, and groups the tasks into
the book's parts.  :func:`load_spec` turns it into a :class:`PipelineSpec` or
raises :class:`PipelineError` naming what is wrong; nothing is executed.
"""

from __future__ import annotations

import dataclasses
import difflib
import itertools
import hashlib
import json
import os
import re
from collections.abc import Hashable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any

import yaml

__all__ = ["Part", "PipelineError", "PipelineSpec", "Task", "load_spec"]

NAME_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_-]*$")

_TOP_REQUIRED = ("claims_file", "output_root", "parts", "tasks")
_TOP_OPTIONAL = ("data_dir", "profiles", "shared")
_TASK_REQUIRED = ("title", "notebook", "products", "parameters")
_TASK_OPTIONAL = ("claims", "explains", "upstream", "grid", "profile_grid", "data")
_PART_KEYS = ("title", "tasks")


class PipelineError(Exception):
    """A pipeline file, notebook or parameter set is invalid; nothing has run."""


@dataclass(frozen=True)
class Task:
    """One pipeline task: a notebook executed with one profile's parameters.

    Attributes
    ----------
    name : str
        Key in ``tasks``; also the name of its output folder.
    title : str
        Human-readable title.
    notebook : Path
        Absolute path of the source notebook.
    claims : tuple of str
        Claim IDs (of the claims registry, ``claims.yaml``) the task's ``results.json`` must report.
    upstream : tuple of str
        Tasks whose outputs this task reads.
    products : tuple of str
        Files (relative to the task's output folder) a successful run leaves; a glob pattern
        (``neural_ode_seed*.pt``) stands for every file it matches and must match at least one.
    parameters : mapping of str to mapping
        Profile name -> parameter name -> value.
    explains : tuple of str
        Claim IDs whose *why* the task writes (``whys.json``, :mod:`fnnbook.why`).
    inherited : frozenset of str
        Profiles the task does not declare but takes from the profile they extend (``profiles:`` in
        ``pipeline.yaml``): there it runs as in that profile, with that profile's output folder.
    data : tuple of str
        The entries of the data directory the task reads (``bottle/``, ``release/quadrotor/``: a folder and
        all below it, symlinks followed); they enter its fingerprint. Empty: the whole data directory, for a
        task that reads ``data_dir``.
    """

    name: str
    title: str
    notebook: Path
    claims: tuple[str, ...]
    upstream: tuple[str, ...]
    products: tuple[str, ...]
    parameters: Mapping[str, Mapping[str, Any]]
    explains: tuple[str, ...] = ()
    inherited: frozenset[str] = frozenset()
    data: tuple[str, ...] = ()
    left_out: frozenset[str] = frozenset()


@dataclass(frozen=True)
class Part:
    """A titled group of tasks; one part of the book."""

    title: str
    tasks: tuple[str, ...]


@dataclass(frozen=True)
class PipelineSpec:
    """A validated ``pipeline.yaml``.

    Attributes
    ----------
    path : Path
        The pipeline file.
    root : Path
        Its folder; notebooks execute with this as working directory.
    claims_file, output_root : Path
        Absolute paths (relative entries resolved against ``root``).
    data_dir : Path or None
        Absolute path of the data folder, if given.
    parts : tuple of Part
    tasks : mapping of str to Task
        In topological order (every task after its upstream tasks); a task
        with a ``grid`` appears as one task per grid point.
    grids : mapping of str to tuple of str
        Grid task name -> the names of its points.
    narrowed : tuple of str
        The grid points :meth:`for_profile` has left out of this spec (empty for the spec as loaded).
    extends : mapping of str to str
        Profile -> the profile it extends (``profiles: {why: {extends: paper}}``): a task that does not
        declare the profile runs there as in the extended one, and keeps its outputs in that one's folder,
        so ``run --profile why`` reuses the paper run's outputs and runs only what they lack.
    """

    path: Path
    root: Path
    claims_file: Path
    data_dir: Path | None
    output_root: Path
    parts: tuple[Part, ...]
    tasks: Mapping[str, Task] = field(repr=False)
    grids: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    extends: Mapping[str, str] = field(default_factory=dict)
    narrowed: tuple[str, ...] = ()

    def declares(self, profile: str) -> list[str]:
        """The tasks that declare ``profile`` themselves (what ``run --profile`` runs by default), in order; a grid
        point that the profile's ``profile_grid`` leaves out is not among them."""
        return [n for n, t in self.tasks.items()
                if profile in t.parameters and profile not in t.inherited and profile not in t.left_out]

    def for_profile(self, profile: str) -> PipelineSpec:
        """The pipeline as ``profile`` runs it: without the grid points its ``profile_grid`` leaves out, in the
        tasks, the grids and every upstream list (an aggregate step reads the points the profile runs).

        Every function that plans, runs, judges or shows one profile's tasks calls it first; it returns ``self``
        when the profile narrows no grid (and when this spec is that profile's already).
        """
        out = {n for n, t in self.tasks.items() if profile in t.left_out}
        if not out:
            return self
        tasks = {n: dataclasses.replace(t, upstream=tuple(u for u in t.upstream if u not in out))
                 for n, t in self.tasks.items() if n not in out}
        grids = {g: tuple(p for p in points if p not in out) for g, points in self.grids.items()}
        return dataclasses.replace(self, tasks=tasks, grids=grids, narrowed=tuple(n for n in self.tasks if n in out))

    def home(self, profile: str, task: str) -> str:
        """The profile whose folder holds ``task``'s outputs when it runs in ``profile``: the extended one
        for a task that inherits ``profile``, else ``profile`` itself."""
        t = self.tasks.get(task)
        return self.extends[profile] if t is not None and profile in t.inherited else profile

    def home_profile(self, profile: str) -> str:
        """The profile ``profile`` extends, or ``profile`` itself."""
        return self.extends.get(profile, profile)

    def extended_by(self, profile: str) -> list[str]:
        """The profiles that extend ``profile`` (their own tasks' outputs belong to its book)."""
        return sorted(p for p, base in self.extends.items() if base == profile)

    @property
    def profiles(self) -> tuple[str, ...]:
        """Every profile named by some task, sorted."""
        return tuple(sorted({p for t in self.tasks.values() for p in t.parameters}))

    def with_paths(
        self,
        *,
        output_root: str | os.PathLike[str] | None = None,
        data_dir: str | os.PathLike[str] | None = None,
    ) -> PipelineSpec:
        """Return a copy with ``output_root`` and/or ``data_dir`` replaced."""
        changes: dict[str, Path] = {}
        if output_root is not None:
            changes["output_root"] = Path(output_root).resolve()
        if data_dir is not None:
            changes["data_dir"] = Path(data_dir).resolve()
        return dataclasses.replace(self, **changes)

    def closure(self, names: Iterable[str] | None = None) -> list[str]:
        """Return ``names`` and all their upstream tasks, in topological order.

        ``None`` selects every task.

        Raises
        ------
        PipelineError
            If a name is not a task.
        """
        if names is None:
            return list(self.tasks)
        wanted: set[str] = set()
        stack = [point for name in names for point in self.grids.get(name, (name,))]
        for name in stack:
            if name in self.narrowed:
                raise PipelineError(f"grid point {name!r} is not run in this profile: its profile_grid leaves it "
                                    "out (pipeline.yaml)")
            if name not in self.tasks:
                raise PipelineError(f"no task named {name!r}{_suggest(name, self.tasks)}; "
                                    f"tasks: {', '.join(self.tasks)}")
        while stack:
            name = stack.pop()
            if name not in wanted:
                wanted.add(name)
                stack.extend(self.tasks[name].upstream)
        return [n for n in self.tasks if n in wanted]

    def output_dir(self, profile: str, task: str) -> Path:
        """Folder holding the last good outputs of ``task`` in ``profile`` (in the extended profile's folder
        for a task that inherits ``profile``, :meth:`home`)."""
        return self.output_root / self.home(profile, task) / task


class _UniqueKeyLoader(yaml.SafeLoader):
    """PyYAML's safe loader, but a key written twice in one mapping is refused (PyYAML keeps the last silently).

    Keys merged in with ``<<: *anchor`` may still be overridden by the mapping's own keys (YAML's merge rule).
    """

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: dict[Any, int] = {}
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key = self.construct_object(key_node, deep=True)
            if not isinstance(key, Hashable):
                continue  # the safe loader itself refuses it
            line = key_node.start_mark.line + 1
            if key in seen:
                raise PipelineError(f"line {line}: key {key!r} is written twice in one mapping (first on line "
                                    f"{seen[key]}); keep one")
            seen[key] = line
        return super().construct_mapping(node, deep=deep)


def _load_yaml(file: Path) -> Any:
    """The YAML document in ``file``, refusing duplicate keys."""
    try:
        return yaml.load(file.read_text(encoding="utf-8"), Loader=_UniqueKeyLoader)  # noqa: S506 (a SafeLoader)
    except PipelineError as exc:
        raise PipelineError(f"{file}, {exc}") from None
    except yaml.YAMLError as exc:
        raise PipelineError(f"{file} is not valid YAML: {exc}") from exc


def _suggest(name: str, choices: Iterable[str]) -> str:
    close = difflib.get_close_matches(name, list(choices), n=3)
    return f" (did you mean {' or '.join(repr(c) for c in close)}?)" if close else ""


def _check_keys(where: str, data: Mapping[str, Any], required: tuple[str, ...],
                optional: tuple[str, ...] = ()) -> None:
    allowed = required + optional
    for key in data:
        if key not in allowed:
            raise PipelineError(f"{where}: unknown key {key!r}{_suggest(str(key), allowed)}; "
                                f"allowed keys: {', '.join(allowed)}")
    for key in required:
        if key not in data:
            raise PipelineError(f"{where}: missing key {key!r}")


def _str_list(where: str, value: Any) -> tuple[str, ...]:
    if value is None:
        return ()
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise PipelineError(f"{where} must be a list of strings, got {value!r}")
    if len(set(value)) != len(value):
        raise PipelineError(f"{where} lists a name twice: {value!r}")
    return tuple(value)


def _mapping(where: str, value: Any) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise PipelineError(f"{where} must be a mapping, got {type(value).__name__}")
    for key in value:
        if not isinstance(key, str):
            raise PipelineError(f"{where}: key {key!r} is not a string")
    return value


def _path(root: Path, where: str, value: Any) -> Path:
    if not isinstance(value, str) or not value:
        raise PipelineError(f"{where} must be a non-empty path string, got {value!r}")
    return (root / value).resolve()


def _load_task(root: Path, name: str, data: Any) -> Task:
    where = f"task {name!r}"
    if not NAME_RE.match(name):
        raise PipelineError(f"{where}: a task name must start with a letter and hold only "
                            "letters, digits, '_' and '-'")
    data = _mapping(where, data)
    _check_keys(where, data, _TASK_REQUIRED, _TASK_OPTIONAL)
    if not isinstance(data["title"], str):
        raise PipelineError(f"{where}: title must be a string")
    notebook = _path(root, f"{where}: notebook", data["notebook"])
    if notebook.suffix != ".ipynb":
        raise PipelineError(f"{where}: notebook {data['notebook']!r} is not an .ipynb file")
    if not notebook.is_file():
        raise PipelineError(f"{where}: notebook {data['notebook']!r} does not exist "
                            f"(looked for {notebook})")
    products = _str_list(f"{where}: products", data["products"])
    for product in products:
        pure = PurePosixPath(product)
        if pure.is_absolute() or ".." in pure.parts or not pure.parts:
            raise PipelineError(f"{where}: product {product!r} must be a relative path "
                                "inside the task's output folder")
    reads = _str_list(f"{where}: data", data.get("data"))
    for entry in reads:
        pure = PurePosixPath(entry)
        if pure.is_absolute() or ".." in pure.parts or not pure.parts:
            raise PipelineError(f"{where}: data entry {entry!r} must be a relative path inside the data directory")
    parameters = _mapping(f"{where}: parameters", data["parameters"])
    if not parameters:
        raise PipelineError(f"{where}: parameters must name at least one profile")
    profiles: dict[str, Mapping[str, Any]] = {}
    for profile, values in parameters.items():
        if not NAME_RE.match(profile):
            raise PipelineError(f"{where}: profile name {profile!r} must start with a letter and "
                                "hold only letters, digits, '_' and '-'")
        profiles[profile] = dict(_mapping(f"{where}: parameters.{profile}", values or {}))
    return Task(
        name=name,
        title=data["title"],
        notebook=notebook,
        claims=_str_list(f"{where}: claims", data.get("claims")),
        explains=_str_list(f"{where}: explains", data.get("explains")),
        upstream=_str_list(f"{where}: upstream", data.get("upstream")),
        products=products,
        parameters=profiles,
        data=reads,
    )


def _point_value(value: Any) -> str:
    """A grid value as part of a folder name, one-to-one: a non-negative integer as its digits, anything else
    as a readable prefix and a short hash of its canonical JSON (``-1.0`` and ``1.0``, ``[9, -1]`` and
    ``[9, 1]``, ``"a b"`` and ``"a_b"`` all differ)."""
    if isinstance(value, int) and not isinstance(value, bool) and value >= 0:
        return str(value)
    canonical = json.dumps(value, sort_keys=True, separators=(",", ":"), default=str)
    readable = re.sub(r"[^A-Za-z0-9.]+", "_", canonical).strip("_.")[:24].strip("_.") or "x"
    return f"{readable}_{hashlib.sha256(canonical.encode()).hexdigest()[:8]}"


def _point_name(task: str, point: Mapping[str, Any]) -> str:
    """``spiral__seed_3``, ``spiral__x0_9.0_1.0_<hash>``: the task and each grid value (:func:`_point_value`)."""
    return "__".join([task, *(f"{k}_{_point_value(v)}" for k, v in point.items())])


def _json(value: Any) -> str:
    return json.dumps(value, sort_keys=True)


def _narrowing(task: Task, grid: Mapping[str, list[Any]], raw: Any) -> dict[str, dict[str, set[str]]]:
    """``profile_grid`` checked: profile -> parameter -> the canonical JSON of the values that profile runs, each
    profile one the task declares, each parameter one of the grid's, each value one of its grid values."""
    where = f"task {task.name!r}: profile_grid"
    narrowing: dict[str, dict[str, set[str]]] = {}
    for profile, sub in _mapping(where, raw).items():
        if profile not in task.parameters:
            raise PipelineError(f"{where}.{profile}: the task declares no profile {profile!r}"
                                f"{_suggest(profile, task.parameters)}; profiles: {', '.join(task.parameters)}")
        sub = _mapping(f"{where}.{profile}", sub)
        if not sub:
            raise PipelineError(f"{where}.{profile} must name at least one parameter of the grid")
        narrowing[profile] = {}
        for name, values in sub.items():
            if name not in grid:
                raise PipelineError(f"{where}.{profile}: {name!r} is not a parameter of the grid"
                                    f"{_suggest(name, grid)}; grid: {', '.join(grid)}")
            if not isinstance(values, list) or not values:
                raise PipelineError(f"{where}.{profile}.{name} must be a non-empty list of values, got {values!r}")
            keys = [_json(v) for v in values]
            if len(set(keys)) != len(keys):
                raise PipelineError(f"{where}.{profile}.{name} lists a value twice: {values!r}")
            unknown = [v for v, k in zip(values, keys) if k not in {_json(g) for g in grid[name]}]
            if unknown:
                raise PipelineError(f"{where}.{profile}.{name}: {unknown[0]!r} is not a value of the grid "
                                    f"({grid[name]!r}); a profile runs a part of the grid, not other points")
            narrowing[profile][name] = set(keys)
    return narrowing


def _expand_grid(task: Task, grid: Any, profile_grid: Any = None) -> list[Task]:
    """One task per point of ``grid`` (parameter -> list of values; the product of the lists); ``profile_grid``
    (profile -> parameter -> a part of its values) leaves the other points out of that profile
    (:attr:`Task.left_out`)."""
    where = f"task {task.name!r}: grid"
    grid = _mapping(where, grid)
    if not grid:
        raise PipelineError(f"{where} must name at least one parameter")
    for name, values in grid.items():
        if not isinstance(values, list) or not values:
            raise PipelineError(f"{where}.{name} must be a non-empty list of values, got {values!r}")
        if len({_json(v) for v in values}) != len(values):
            raise PipelineError(f"{where}.{name} lists a value twice: {values!r}")
    narrowing = _narrowing(task, grid, profile_grid) if profile_grid is not None else {}
    points = [dict(zip(grid, combo)) for combo in itertools.product(*grid.values())]
    names = [_point_name(task.name, point) for point in points]
    if len(set(names)) != len(names):  # cannot happen short of a hash collision: refused, not dropped
        raise PipelineError(f"{where}: two points get the same name: "
                            f"{sorted(n for n in names if names.count(n) > 1)[0]}")
    return [dataclasses.replace(task, name=name,
                                parameters={prof: {**values, **point} for prof, values in task.parameters.items()},
                                left_out=frozenset(prof for prof, sub in narrowing.items()
                                                   if any(_json(point[k]) not in keep for k, keep in sub.items())))
            for name, point in zip(names, points)]


def _topological(tasks: Mapping[str, Task]) -> list[str]:
    """Order tasks so that each follows its upstream tasks (file order otherwise)."""
    order: list[str] = []
    state: dict[str, str] = {}  # "visiting" | "done"

    def visit(name: str, path: list[str]) -> None:
        if state.get(name) == "done":
            return
        if state.get(name) == "visiting":
            cycle = path[path.index(name):] + [name]
            raise PipelineError(f"upstream tasks form a cycle: {' -> '.join(cycle)}")
        state[name] = "visiting"
        for up in tasks[name].upstream:
            visit(up, path + [name])
        state[name] = "done"
        order.append(name)

    for name in tasks:
        visit(name, [])
    return order


def load_spec(path: str | os.PathLike[str]) -> PipelineSpec:
    """Read and validate a pipeline file.

    Parameters
    ----------
    path : path-like
        The ``pipeline.yaml``; relative paths inside it are relative to its folder.

    Returns
    -------
    PipelineSpec

    Raises
    ------
    PipelineError
        On unknown, missing or duplicate keys, a missing notebook, an unknown upstream
        task, a cycle, or a task listed in no part (or in two).
    """
    file = Path(path).resolve()
    if not file.is_file():
        raise PipelineError(f"pipeline file {file} does not exist")
    data = _load_yaml(file)
    where = str(file.name)
    data = _mapping(where, data)
    _check_keys(where, data, _TOP_REQUIRED, _TOP_OPTIONAL)
    # `shared` only holds blocks that tasks merge with YAML anchors (`<<: *name`); yaml has merged them already
    _mapping(f"{where}: shared", data.get("shared") or {})
    root = file.parent

    raw_tasks = _mapping(f"{where}: tasks", data["tasks"])
    if not raw_tasks:
        raise PipelineError(f"{where}: tasks is empty")
    tasks: dict[str, Task] = {}
    grids: dict[str, tuple[str, ...]] = {}
    for name, value in raw_tasks.items():
        task = _load_task(root, name, value)
        if isinstance(value, Mapping) and "profile_grid" in value and "grid" not in value:
            raise PipelineError(f"task {name!r}: profile_grid narrows a grid, and the task has none")
        if isinstance(value, Mapping) and "grid" in value:
            points = _expand_grid(task, value["grid"], value.get("profile_grid"))
            grids[name] = tuple(p.name for p in points)
            tasks.update((p.name, p) for p in points)
        else:
            tasks[name] = task
    clash = sorted(set(raw_tasks) & {p for points in grids.values() for p in points})
    if clash:
        raise PipelineError(f"{where}: a grid point is named like a task: {', '.join(clash)}")
    # an upstream grid means all its points (an aggregate step reads them all through upstream_dirs)
    tasks = {n: dataclasses.replace(t, upstream=tuple(p for u in t.upstream for p in grids.get(u, (u,))))
             for n, t in tasks.items()}
    for task in tasks.values():
        for up in task.upstream:
            if up == task.name:
                raise PipelineError(f"task {task.name!r} lists itself as upstream")
            if up not in tasks:
                raise PipelineError(f"task {task.name!r}: upstream task {up!r} does not exist"
                                    f"{_suggest(up, tasks)}")
    order = _topological(tasks)

    if not isinstance(data["parts"], list) or not data["parts"]:
        raise PipelineError(f"{where}: parts must be a non-empty list")
    parts: list[Part] = []
    placed: dict[str, str] = {}
    for i, raw in enumerate(data["parts"]):
        pwhere = f"{where}: parts[{i}]"
        raw = _mapping(pwhere, raw)
        _check_keys(pwhere, raw, _PART_KEYS)
        if not isinstance(raw["title"], str):
            raise PipelineError(f"{pwhere}: title must be a string")
        names = _str_list(f"{pwhere}: tasks", raw["tasks"])
        for name in names:
            if name not in tasks and name not in grids:
                raise PipelineError(f"{pwhere} ({raw['title']!r}) lists task {name!r}, which "
                                    f"does not exist{_suggest(name, tasks)}")
            if name in placed:
                raise PipelineError(f"task {name!r} is listed in two parts: "
                                    f"{placed[name]!r} and {raw['title']!r}")
            placed[name] = raw["title"]
        parts.append(Part(title=raw["title"], tasks=names))
    in_grid = {p: g for g, points in grids.items() for p in points}
    missing = [n for n in order if n not in placed and in_grid.get(n) not in placed]
    if missing:
        raise PipelineError(f"{where}: tasks in no part: {', '.join(missing)} "
                            "(every task must be listed under parts)")

    extends = _load_profiles(where, data.get("profiles") or {}, tasks)
    for task in tasks.values():
        tied = sorted(p for p in task.left_out if p in extends or p in extends.values())
        if tied:
            raise PipelineError(f"task {in_grid[task.name]!r}: profile_grid narrows profile {tied[0]!r}, which "
                                "extends another or is extended: it shares that profile's outputs, so it runs the "
                                "whole grid")
    tasks = {n: _inherit(t, extends) for n, t in tasks.items()}
    data_dir = data.get("data_dir")
    return PipelineSpec(
        path=file,
        root=root,
        claims_file=_path(root, f"{where}: claims_file", data["claims_file"]),
        data_dir=None if data_dir is None else _path(root, f"{where}: data_dir", data_dir),
        output_root=_path(root, f"{where}: output_root", data["output_root"]),
        parts=tuple(parts),
        tasks={n: tasks[n] for n in order},
        grids=grids,
        extends=extends,
    )


def _load_profiles(where: str, raw: Any, tasks: Mapping[str, Task]) -> dict[str, str]:
    """``profiles: {why: {extends: paper}}`` -> ``{"why": "paper"}``, checked: the extended profile exists, is
    declared by every task that does not declare the extending one, and extends nothing itself."""
    raw = _mapping(f"{where}: profiles", raw)
    extends: dict[str, str] = {}
    for name, value in raw.items():
        pwhere = f"{where}: profiles.{name}"
        value = _mapping(pwhere, value or {})
        _check_keys(pwhere, value, ("extends",))
        base = value["extends"]
        declared = {p for t in tasks.values() for p in t.parameters}
        if not isinstance(base, str) or base not in declared:
            raise PipelineError(f"{pwhere}: extends {base!r}, which no task declares{_suggest(str(base), declared)}")
        if base == name:
            raise PipelineError(f"{pwhere} extends itself")
        extends[name] = base
    for name, base in extends.items():
        if base in extends:
            raise PipelineError(f"{where}: profiles.{name} extends {base!r}, which extends a profile itself")
        lacking = [n for n, t in tasks.items() if name not in t.parameters and base not in t.parameters]
        if lacking:
            raise PipelineError(f"{where}: profile {name!r} extends {base!r}, but task {lacking[0]!r} declares "
                                "neither")
    return extends


def _inherit(task: Task, extends: Mapping[str, str]) -> Task:
    """Give ``task`` the extending profiles it does not declare, with the extended profile's parameters."""
    taken = {p: task.parameters[base] for p, base in extends.items() if p not in task.parameters}
    if not taken:
        return task
    return dataclasses.replace(task, parameters={**task.parameters, **taken}, inherited=frozenset(taken))
