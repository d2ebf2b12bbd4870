"""The frozen dataclass every notebook's settings derive from: each field's paper value and check together.

A field is declared with :func:`setting` (its paper value and its check, ``check(name, value)`` raising
``ValueError`` that names the setting); :meth:`TaskSettings.check_relations` checks the values that depend on
each other, and :meth:`TaskSettings.check_data` the data files a setting needs. Construction runs all three
(``__post_init__``), so a settings object that exists has passed its checks.
"""

from __future__ import annotations

import copy
import difflib
from collections.abc import Callable, Mapping
from dataclasses import MISSING, Field, InitVar, dataclass, field, fields
from pathlib import Path
from typing import Any, ClassVar

__all__ = ["Check", "TaskSettings", "setting"]

Check = Callable[[str, Any], Any]


def _plain(value: Any) -> Any:
    """Tuples (the presets' read-only sequences) as lists, the type a notebook parameter has."""
    if isinstance(value, (tuple, list)):
        return [_plain(v) for v in value]
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    return value


def setting(default: Any, check: Check) -> Any:
    """A setting of a notebook: its paper value ``default`` (a sequence becomes a list) and its ``check``."""
    value = _plain(default)
    if isinstance(value, (list, dict)):
        return field(default_factory=lambda: copy.deepcopy(value), metadata={"check": check})
    return field(default=value, metadata={"check": check})


def _default(f: Field[Any]) -> Any:
    return f.default_factory() if f.default is MISSING else f.default  # type: ignore[misc]


@dataclass(frozen=True, kw_only=True)
class TaskSettings:
    """The settings of one notebook of the book, checked when made.

    A subclass names its notebook (``class SpiralSettings(TaskSettings, notebook="spiral")``) and declares one
    field per setting with :func:`setting`. ``data_dir`` (not a setting: where the run reads its data) is
    passed to :meth:`check_data` when given.

    Raises
    ------
    ValueError
        A value its check refuses, naming the setting (:class:`~fnnlib.feedback.GainError` for an unstable gain).
    fnnlib.checks.MissingDataError
        Data files the settings need are not in ``data_dir``.
    fnnlib.data.bottle.DataError
        A data file is there but is not the published one (its SHA-256).
    """

    notebook: ClassVar[str] = ""
    registry: ClassVar[dict[str, type[TaskSettings]]] = {}
    data_dir: InitVar[str | None] = None

    def __init_subclass__(cls, notebook: str = "", **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if notebook:
            cls.notebook = notebook
            TaskSettings.registry[notebook] = cls

    def __post_init__(self, data_dir: str | None) -> None:
        for f in fields(self):
            f.metadata["check"](f.name, getattr(self, f.name))
        self.check_relations()
        if data_dir is not None:
            self.check_data(Path(data_dir))

    def check_relations(self) -> None:
        """Check the values that depend on each other (run after each value passed its own check)."""

    def check_data(self, data_dir: Path) -> None:
        """Check the data files the settings read in ``data_dir`` (none by default)."""

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """The settings' names, in the order the notebook's ``parameters`` cell lists them."""
        return tuple(f.name for f in fields(cls))

    @classmethod
    def defaults(cls) -> dict[str, Any]:
        """Every setting's paper value, as plain values (lists, not tuples)."""
        return {f.name: _default(f) for f in fields(cls)}

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], *, data_dir: str | None = None) -> TaskSettings:
        """The settings with ``values`` changed from the paper values; an unknown name is refused.

        Raises
        ------
        ValueError
            A name that is not a setting of this notebook (with close matches), or a value its checks refuse.
        """
        names = cls.names()
        for name in values:
            if name not in names:
                close = difflib.get_close_matches(name, names, n=3)
                hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
                raise ValueError(f"notebook {cls.notebook!r} has no setting {name!r}{hint}")
        return cls(**values, data_dir=data_dir)

    @classmethod
    def from_namespace(cls, namespace: Mapping[str, Any]) -> TaskSettings:
        """The settings a notebook holds as variables (``globals()`` after its ``parameters`` cell and the values
        papermill injected), checked; a setting it does not hold keeps its paper value."""
        values = {name: namespace[name] for name in cls.names() if name in namespace}
        return cls(**values, data_dir=namespace.get("data_dir"))

    def as_dict(self) -> dict[str, Any]:
        """Name -> value of every setting."""
        return {f.name: getattr(self, f.name) for f in fields(self)}
