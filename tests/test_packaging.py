"""Packaging and self-containment: one version, typed, licensed, citable, ranges in pyproject and pins in the
lock, and nothing outside the repository named by its files."""

from __future__ import annotations

import re
import subprocess
import tomllib
from importlib.metadata import version
from pathlib import Path

import pytest
import yaml

import fnnlib

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
LOCK = (ROOT / "environment-lock.txt").read_text(encoding="utf-8")


def _name(requirement: str) -> str:
    return re.split(r"[<>=!~\[; ]", requirement, maxsplit=1)[0].lower().replace("_", "-")


def test_the_version_is_written_once() -> None:
    assert fnnlib.__version__ == version("fnnlib") == PYPROJECT["project"]["version"]
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    assert cff["version"] == PYPROJECT["project"]["version"] and cff["license"] == "MIT"
    assert cff["preferred-citation"]["title"] == "Feedback Favors the Generalization of Neural ODEs"
    assert [a["family-names"] for a in cff["preferred-citation"]["authors"]] == [
        "Jia", "Yang", "Wang", "Guo", "Yang", "Yu", "Guo"]


def test_typed_and_licensed() -> None:
    assert (ROOT / "fnnlib" / "py.typed").is_file()
    assert "py.typed" in PYPROJECT["tool"]["setuptools"]["package-data"]["fnnlib"]
    assert PYPROJECT["project"]["license"] == {"text": "MIT"}
    assert (ROOT / "LICENSE").read_text(encoding="utf-8").startswith("MIT License")
    assert (ROOT / "CHANGELOG.md").is_file()


def test_dependencies_are_ranges_and_the_lock_pins_each() -> None:
    project = PYPROJECT["project"]
    requirements = project["dependencies"] + [r for extra in project["optional-dependencies"].values()
                                              for r in extra]
    assert not [r for r in requirements if "==" in r], "exact pins belong in environment-lock.txt"
    pinned = {m.group(1).lower() for m in re.finditer(r"^([A-Za-z0-9_.-]+)==\S+ \\$", LOCK, re.M)}
    assert not {_name(r) for r in requirements} - pinned
    assert re.search(r"^torch==2\.13\.0\+cpu \\$", LOCK, re.M)  # the CPU wheel, within torch>=2.13,<3


def test_no_tracked_file_names_the_workspace_outside_the_repository() -> None:
    try:
        found = subprocess.run(["git", "grep", "-l", "-F", "../" "shared"], cwd=ROOT, capture_output=True,
                               text=True, check=False)
    except OSError:
        pytest.skip("no git here")  # the check needs the list of tracked files
    if found.returncode not in (0, 1):
        pytest.skip("not a git checkout")
    assert found.stdout.split() == [".ci/run"]  # CI alone passes the workspace's data directory on
