"""Fixture writing a tiny pipeline (notebooks, claims.yaml, pipeline.yaml) under tmp_path."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml

from .nbfactory import CHILD_BODY, CHILD_PARAMS, CLAIMS_YAML, LEAF_BODY, LEAF_PARAMS, leaf_task, write_notebook


@pytest.fixture
def make_pipeline(tmp_path: Path) -> Callable[..., Path]:
    """Factory: write notebooks + claims.yaml + pipeline.yaml under tmp_path, return the yaml path."""
    write_notebook(tmp_path / "notebooks" / "leaf.ipynb", LEAF_PARAMS, LEAF_BODY)
    write_notebook(tmp_path / "notebooks" / "child.ipynb", CHILD_PARAMS, CHILD_BODY)
    (tmp_path / "claims.yaml").write_text(CLAIMS_YAML)

    def make(tasks: dict[str, Any] | None = None, parts: list[dict[str, Any]] | None = None,
             **top: Any) -> Path:
        tasks = {"leaf": leaf_task()} if tasks is None else tasks
        doc = {"claims_file": "claims.yaml", "data_dir": "data", "output_root": "outputs",
               "parts": parts if parts is not None else [{"title": "Part one", "tasks": list(tasks)}],
               "tasks": tasks, **top}
        path = tmp_path / "pipeline.yaml"
        path.write_text(yaml.safe_dump(doc, sort_keys=False))
        return path

    return make
