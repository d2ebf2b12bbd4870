"""The one loader of an ensemble's members: int seeds, checked against the run record; truncate, swap, delete."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import torch

import fnnlib as F
from fnnlib.models import stack_members
from fnnlib.seeding import seed_everything
from fnnlib.training import load_seed_checkpoints, load_seed_ensemble, save_checkpoint, seed_checkpoint_name
from fnnlib.quadrotor.residual import AeroResidual
from fnnlib.training import CheckpointError

RUN = {"seeds": [1, 0], "epochs": 3, "lr": None}  # the run record's parameters (lr from a preset)


def _members(folder: Path) -> Path:
    torch.manual_seed(0)
    for seed in RUN["seeds"]:
        save_checkpoint(folder / f"residual_seed{seed}.pt", AeroResidual((4,), "tanh").double(),
                          {"seed": seed, "epochs": 3, "lr": 0.01})
    return folder


def _load(folder: Path, run: dict = RUN) -> list:
    return load_seed_checkpoints(folder, "residual", expected_kind="AeroResidual", run=run)


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


def test_the_seed_ensemble_holds_each_seeds_network_in_the_checkpoints_order(tmp_path: Path) -> None:
    """``load_seed_ensemble``: member e of the ensemble is seed ``seeds[e]``'s network, in the dtype asked for."""
    for seed in (3, 1):
        seed_everything(seed)
        save_checkpoint(tmp_path / seed_checkpoint_name(seed), F.NeuralODE(2, [8], "tanh"), {"seed": seed})
    ens = load_seed_ensemble(tmp_path, dtype=torch.float64)
    loaded = load_seed_checkpoints(tmp_path)
    assert list(ens.seeds) == [s for s, _, _ in loaded] == [1, 3]
    x = torch.randn(5, 2, dtype=torch.float64)
    out = ens.split(ens(0.0, stack_members(x, 2)))
    assert out.dtype == torch.float64
    for e, (_, net, _) in enumerate(loaded):
        torch.testing.assert_close(out[e], net.double()(0.0, x))
    (tmp_path / "res").mkdir()
    with pytest.raises(CheckpointError, match="NeuralODE"):  # the members must be neural ODEs
        load_seed_ensemble(_members(tmp_path / "res"), "residual")
