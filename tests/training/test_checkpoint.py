"""Checkpoints: exact round trip; corrupt, mismatched or missing files are refused with a clear error."""

from __future__ import annotations

import random

import pytest
import torch
from torch import nn

from fnnlib import NeuralODE
from fnnlib.training import (
    CheckpointError,
    load_checkpoint,
    load_seed_checkpoints,
    save_checkpoint,
    seed_checkpoint_name,
)

META = {"seed": 3, "final_loss": 0.0123, "method": "dopri5", "losses": [1.0, 0.5], "settings": {"lr": 1e-3}}


@pytest.fixture
def saved(tmp_path):
    torch.manual_seed(0)
    model = NeuralODE(2, (8, 8), "tanh")
    path = save_checkpoint(tmp_path / "sub" / "model.pt", model, META)
    return model, path


def test_round_trip(saved):
    model, path = saved
    assert path.is_file()
    assert not [p for p in path.parent.iterdir() if p.name.endswith(".tmp")]  # atomic write leaves no temp file
    loaded, meta = load_checkpoint(path, expected_config=model.config, expected_kind="NeuralODE")
    assert meta == META
    assert loaded.config == model.config
    x = torch.randn(16, 2)
    assert torch.equal(loaded(0.0, x), model(0.0, x))
    for (k1, v1), (k2, v2) in zip(model.state_dict().items(), loaded.state_dict().items()):
        assert k1 == k2 and torch.equal(v1, v2)


def test_round_trip_with_input_and_partial_expected_config(tmp_path):
    model = NeuralODE(3, (4,), "relu", n_input=1)
    path = save_checkpoint(tmp_path / "m.pt", model)
    loaded, meta = load_checkpoint(path, expected_config={"n_state": 3})
    assert meta == {}
    x, u = torch.randn(5, 3), torch.randn(5, 1)
    assert torch.equal(loaded.vector_field(x, u), model.vector_field(x, u))


def test_round_trip_keeps_float64(tmp_path):
    # a float64 model must come back float64 with bit-identical weights, not rounded to float32
    model = NeuralODE(3, (4,), "relu", n_input=1).double()
    path = save_checkpoint(tmp_path / "m.pt", model)
    loaded, _ = load_checkpoint(path)
    assert next(loaded.parameters()).dtype == torch.float64
    x, u = torch.randn(5, 3, dtype=torch.float64), torch.randn(5, 1, dtype=torch.float64)
    assert torch.equal(loaded.vector_field(x, u), model.vector_field(x, u))


def test_truncated_file(saved):
    _, path = saved
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(CheckpointError, match=r"model.pt is corrupt or not a torch file"):
        load_checkpoint(path)


def test_random_bytes(tmp_path):
    path = tmp_path / "junk.pt"
    path.write_bytes(random.Random(0).randbytes(4096))
    with pytest.raises(CheckpointError, match=r"junk.pt is corrupt or not a torch file"):
        load_checkpoint(path)


def test_flipped_weight_fails_the_checksum(saved):
    _, path = saved
    payload = torch.load(path, weights_only=True)
    w = payload["state_dict"]["net.0.weight"]
    w.view(torch.uint8)[0] ^= 1  # one bit of one weight; sha256 left as it was
    torch.save(payload, path)
    with pytest.raises(CheckpointError, match="fails its checksum: the weights are corrupt"):
        load_checkpoint(path)


def test_changed_weight_value_fails_the_checksum(saved):
    _, path = saved
    payload = torch.load(path, weights_only=True)
    payload["state_dict"]["net.2.bias"][1] += 1.0
    torch.save(payload, path)
    with pytest.raises(CheckpointError, match="fails its checksum"):
        load_checkpoint(path)


def test_expected_config_mismatch(saved):
    _, path = saved
    with pytest.raises(CheckpointError,
                       match=r"does not match the requested model \(hidden: file has \[8, 8\], expected \[50, 50\]\)"):
        load_checkpoint(path, expected_config={"hidden": [50, 50], "n_state": 2})


def test_expected_kind_mismatch(saved):
    _, path = saved
    with pytest.raises(CheckpointError, match="holds a NeuralODE, expected a FeedbackNet"):
        load_checkpoint(path, expected_kind="FeedbackNet")


def test_missing_file(tmp_path):
    with pytest.raises(CheckpointError, match=r"nope.pt does not exist \(run the task that trains it first\)"):
        load_checkpoint(tmp_path / "nope.pt")


def test_not_an_fnnlib_checkpoint(tmp_path):
    path = tmp_path / "other.pt"
    torch.save({"weights": torch.zeros(3)}, path)
    with pytest.raises(CheckpointError, match="is not an fnnlib checkpoint"):
        load_checkpoint(path)


def test_wrong_version(saved):
    _, path = saved
    payload = torch.load(path, weights_only=True)
    payload["version"] = 99
    torch.save(payload, path)
    with pytest.raises(CheckpointError, match="has checkpoint version 99, this fnnlib reads 1"):
        load_checkpoint(path)


def test_config_that_does_not_fit_the_weights(saved):
    _, path = saved
    payload = torch.load(path, weights_only=True)
    payload["config"]["hidden"] = [8, 9]  # checksum covers the weights only; the shapes then disagree
    torch.save(payload, path)
    with pytest.raises(CheckpointError, match="weights do not fit its config"):
        load_checkpoint(path)


def test_unknown_model_type_refuses_to_save(tmp_path):
    with pytest.raises(TypeError, match=r"cannot checkpoint a Linear: register its class first with "
                                        r"fnnlib.training.register_model\(Linear\).*known models: \[.*'NeuralFeedback', 'NeuralODE'.*\]"):
        save_checkpoint(tmp_path / "lin.pt", nn.Linear(2, 2))
    assert not (tmp_path / "lin.pt").exists()


def _save_seeds(directory, seeds, run_seeds=None):
    models = {}
    for s in seeds:
        torch.manual_seed(s)
        models[s] = NeuralODE(2, (4,), "relu")
        save_checkpoint(directory / seed_checkpoint_name(s), models[s],
                        {"seed": s, "seeds": list(run_seeds if run_seeds is not None else seeds)})
    return models


def test_seed_checkpoints_round_trip_in_seed_order(tmp_path):
    models = _save_seeds(tmp_path, [10, 2, 0], run_seeds=[10, 2, 0])
    (tmp_path / "neural_ode.pt").write_bytes(b"")           # other files beside them are ignored
    (tmp_path / "neural_ode_seedx.pt").write_bytes(b"")
    loaded = load_seed_checkpoints(tmp_path)
    assert [s for s, _, _ in loaded] == [0, 2, 10]
    x = torch.randn(7, 2)
    for s, model, meta in loaded:
        assert meta == {"seed": s, "seeds": [10, 2, 0]}
        assert torch.equal(model(0.0, x), models[s](0.0, x))
    assert not torch.equal(loaded[0][1](0.0, x), loaded[1][1](0.0, x))  # different seeds, different networks


def test_seed_checkpoint_name():
    assert seed_checkpoint_name(3) == "neural_ode_seed3.pt"
    assert seed_checkpoint_name(0, "fb") == "fb_seed0.pt"
    with pytest.raises(ValueError, match="non-negative int"):
        seed_checkpoint_name(-1)


def test_seed_checkpoints_none(tmp_path):
    save_checkpoint(tmp_path / "neural_ode.pt", NeuralODE(2, (4,), "relu"), {"seed": 0})
    with pytest.raises(CheckpointError, match=r"no per-seed checkpoints neural_ode_seed<s>.pt in"):
        load_seed_checkpoints(tmp_path)
    with pytest.raises(CheckpointError, match="does not exist"):
        load_seed_checkpoints(tmp_path / "nope")


def test_seed_checkpoints_corrupt_one(tmp_path):
    _save_seeds(tmp_path, [0, 1])
    path = tmp_path / "neural_ode_seed1.pt"
    path.write_bytes(path.read_bytes()[:100])
    with pytest.raises(CheckpointError, match=r"neural_ode_seed1.pt is corrupt"):
        load_seed_checkpoints(tmp_path)


def test_seed_checkpoints_wrong_kind_or_seed(tmp_path):
    _save_seeds(tmp_path, [0])
    with pytest.raises(CheckpointError, match="holds a NeuralODE, expected a FeedbackNet"):
        load_seed_checkpoints(tmp_path, expected_kind="FeedbackNet")
    save_checkpoint(tmp_path / "neural_ode_seed1.pt", NeuralODE(2, (4,), "relu"), {"seed": 0, "seeds": [0]})
    with pytest.raises(CheckpointError, match="records seed 0, its name says 1"):
        load_seed_checkpoints(tmp_path)


def test_seed_checkpoints_missing_or_stale_seed(tmp_path):
    _save_seeds(tmp_path, [0, 2], run_seeds=[0, 1, 2])
    with pytest.raises(CheckpointError, match=r"holds the seeds \[0, 2\] but the run trained \[0, 1, 2\]"):
        load_seed_checkpoints(tmp_path)
    _save_seeds(tmp_path, [1], run_seeds=[0, 1])
    with pytest.raises(CheckpointError, match="comes from another run"):
        load_seed_checkpoints(tmp_path)
