"""fnnlib.io.atomic_write, and the byte-reproducible files written through it."""

from __future__ import annotations

import pytest
import torch

import fnnlib as F
from fnnlib.training import load_checkpoint, save_checkpoint
from fnnlib.io import atomic_write


def test_atomic_write_replaces_whole_file(tmp_path):
    path = tmp_path / "sub" / "a.txt"
    with atomic_write(path, "w") as fh:
        fh.write("new")
    assert path.read_text() == "new"
    assert [p.name for p in path.parent.iterdir()] == ["a.txt"]


def test_atomic_write_failure_keeps_old_file_and_leaves_no_temp(tmp_path):
    path = tmp_path / "a.bin"
    path.write_bytes(b"old")
    with pytest.raises(RuntimeError, match="boom"):
        with atomic_write(path) as fh:
            fh.write(b"half")
            raise RuntimeError("boom")
    assert path.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["a.bin"]


def test_atomic_write_refuses_other_modes(tmp_path):
    with pytest.raises(ValueError, match="mode"):
        with atomic_write(tmp_path / "a", "a"):
            pass


def test_checkpoint_same_model_same_bytes(tmp_path):
    torch.manual_seed(0)
    model = F.NeuralODE(2, hidden=[4], activation="tanh")
    a = save_checkpoint(tmp_path / "a.pt", model, {"seed": 0})
    b = save_checkpoint(tmp_path / "other" / "b.pt", model, {"seed": 0})
    assert a.read_bytes() == b.read_bytes()
    loaded, meta = load_checkpoint(b)
    assert meta == {"seed": 0}
    assert all(torch.equal(loaded.state_dict()[k], v) for k, v in model.state_dict().items())
