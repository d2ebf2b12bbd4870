"""What a run would execute (:class:`Plan`), below the runner's modules that read it.

:mod:`fnnbook.runner` makes a plan (:func:`fnnbook.runner.check`); :mod:`fnnbook.fingerprint`,
:mod:`fnnbook.execution` and :mod:`fnnbook.executor` read it. It imports none of them.
"""

from __future__ import annotations

import dataclasses
import os
import uuid
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

__all__ = ["Plan", "run_name"]


@dataclass(frozen=True)
class Plan:
    """What a run would execute: checked parameters and input fingerprints.

    Attributes
    ----------
    profile : str
    order : tuple of str
        Selected tasks and their upstream tasks, upstream first.
    selected : tuple of str
        The tasks asked for (all when none were named).
    parameters : mapping of str to dict
        Task -> parameters papermill injects.
    fingerprints : mapping of str to str
        Task -> sha256 over its inputs (:mod:`fnnbook.fingerprint`); no absolute path enters it.
    inputs : mapping of str to dict
        Task -> each part of its fingerprint (notebook, parameters, the modules it imports, the environment,
        the data it reads, its upstream fingerprints), kept in the run record to name a rerun's trigger.
    missing_data : mapping of str to str
        Task -> why it cannot run here (its data files are missing); such a
        task and its dependants are "not run", the rest runs.
    run : str
        This run's name: its staging folder ``.staging/<run>/`` is its own.
    """

    profile: str
    order: tuple[str, ...]
    selected: tuple[str, ...]
    parameters: Mapping[str, dict[str, Any]]
    fingerprints: Mapping[str, str]
    missing_data: Mapping[str, str] = dataclasses.field(default_factory=dict)
    run: str = dataclasses.field(default_factory=lambda: run_name())
    inputs: Mapping[str, dict[str, Any]] = dataclasses.field(default_factory=dict)


def run_name() -> str:
    """A name no other run has: this process's id and a random part."""
    return f"{os.getpid()}-{uuid.uuid4().hex[:8]}"
