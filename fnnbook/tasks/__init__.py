"""Each notebook's settings, in one home: a module per notebook of the book with one frozen dataclass.

``fnnbook.tasks.spiral`` holds :class:`~fnnbook.tasks.spiral.SpiralSettings`, the settings of
``notebooks/01_spiral``: one field per setting with its paper value (a value several notebooks share refers to
:mod:`fnnlib.paper.spiral_presets`, :mod:`fnnlib.quadrotor.presets` or a training recipe, where it is written once) and
its check, and the checks between values in its ``check_relations``; groups of settings the spiral notebooks
share are classes of :mod:`fnnbook.tasks._spiral`. Making one checks it (:class:`~fnnbook.tasks._base.TaskSettings`).

The notebook imports its module right after its ``parameters`` cell and builds its settings from its variables
(``SpiralSettings.from_namespace(globals())``), so a notebook run by hand is checked as the pipeline checks it.
Its ``parameters`` cell lists the paper values, written there from the dataclass
(:func:`fnnbook.params.parameters_cell`, by ``make notebooks``). The runner (:mod:`fnnbook.params`,
:mod:`fnnbook.preflight`) takes the paper values from the dataclass, checks every profile's values with it before
any task runs, and injects them all; a notebook's module enters its fingerprint as code it imports
(:mod:`fnnbook.fingerprint`), so a changed value or check reruns it.

This package imports nothing heavy; a notebook's module imports the library (torch) when it is loaded.
"""

from __future__ import annotations

import importlib
import json
import pkgutil
import re
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from fnnbook.tasks._base import TaskSettings

__all__ = ["NOTEBOOKS", "notebook_name", "settings_class"]

#: the notebooks of the book, by the name of their settings module
NOTEBOOKS: tuple[str, ...] = tuple(sorted(m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_")))

_IMPORT = re.compile(r"^from\s+fnnbook\.tasks\.([A-Za-z0-9_]+)\s+import\b", re.MULTILINE)


def _known(notebook: str) -> str:
    """``notebook`` (``"spiral"``; a leading ``"03_"`` or a ``.ipynb`` suffix is ignored), if the book has it."""
    name = re.sub(r"^\d+_", "", Path(notebook).stem)
    if name not in NOTEBOOKS:
        raise ValueError(f"no notebook of the book is named {notebook!r}; the notebooks are {', '.join(NOTEBOOKS)}")
    return name


def settings_class(notebook: str) -> type[TaskSettings]:
    """The settings dataclass of one notebook of the book (``"spiral"``, ``"01_spiral"`` or ``"01_spiral.ipynb"``).

    Raises ``ValueError`` for a name that is not a notebook of the book.
    """
    from fnnbook.tasks._base import TaskSettings  # noqa: PLC0415

    name = _known(notebook)
    importlib.import_module(f"{__name__}.{name}")
    return TaskSettings.registry[name]


def notebook_name(path: str | Path) -> str | None:
    """The notebook of the book a notebook file (``.ipynb``) is, by the settings module it imports; None for a
    notebook that imports none (one of your own, run by the pipeline: no checks but its parameters' types).

    Raises ``ValueError`` if the module it imports is not one of the book's.
    """
    try:
        cells = json.loads(Path(path).read_text(encoding="utf-8")).get("cells", [])
    except (OSError, ValueError, AttributeError):
        return None  # fnnbook.params.read_parameters says what is wrong with the file
    source = "\n".join("".join(c.get("source", "")) for c in cells if c.get("cell_type") == "code")
    found = _IMPORT.search(source)
    return None if found is None else _known(found.group(1))
