"""The one loader of an ensemble's members: int seeds, checked against the run record; truncate, swap, delete."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import torch

import fnnlib as F
from fnnlib.models import AeroResidual
from fnnlib.training import CheckpointError

RUN = {"seeds": [1, 0], "epochs": 3, "lr": None}  # the run record's parameters (lr from a preset)


def _members(folder: Path) -> Path:
    torch.manual_seed(0)
    for seed in RUN["seeds"]:
        F.save_checkpoint(folder / f"residual_seed{seed}.pt", AeroResidual((4,), "tanh").double(),
                          {"seed": seed, "epochs": 3, "lr": 0.01})
    return folder


def _load(folder: Path, run: dict = RUN) -> list:
    return F.load_seed_checkpoints(folder, "residual", expected_kind="AeroResidual", run=run)


def test_members_load_with_int_seeds_in_the_run_order(tmp_path: Path) -> None:
    assert [seed for seed, _, _ in _load(_members(tmp_path))] == [1, 0]


def test_a_truncated_member_is_refused_by_name(tmp_path: Path) -> None:
    path = _members(tmp_path) / "residual_seed0.pt"
    path.write_bytes(path.read_bytes()[:100])
    with pytest.raises(CheckpointError, match="residual_seed0.pt"):
        _load(tmp_path)


def test_a_swapped_member_is_refused_by_name(tmp_path: Path) -> None:
    _members(tmp_path)
    shutil.copy(tmp_path / "residual_seed0.pt", tmp_path / "residual_seed1.pt")  # seed 0 over seed 1
    with pytest.raises(CheckpointError, match="residual_seed1.pt records seed 0"):
        _load(tmp_path)


def test_a_deleted_member_is_refused(tmp_path: Path) -> None:
    (_members(tmp_path) / "residual_seed1.pt").unlink()
    with pytest.raises(CheckpointError, match=r"trained the seeds \[1, 0\].*holds \[0\]"):
        _load(tmp_path)


def test_a_member_of_another_recipe_is_refused(tmp_path: Path) -> None:
    with pytest.raises(CheckpointError, match="epochs = 3, the run record says 5"):
        _load(_members(tmp_path), {**RUN, "epochs": 5})


def test_the_run_must_name_distinct_seeds(tmp_path: Path) -> None:
    with pytest.raises(CheckpointError, match="trained the seeds"):
        _load(_members(tmp_path), {"seeds": [0, 0, 1]})
