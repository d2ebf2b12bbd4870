"""Checkpoints that refuse corrupt or mismatched files with a clear error."""

from __future__ import annotations

import hashlib
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch
from torch import nn

from fnnlib.io import atomic_write
from fnnlib.models import MODELS

FORMAT = "fnnlib.checkpoint"
VERSION = 1


class CheckpointError(RuntimeError):
    """A checkpoint file is missing, corrupt, or does not match what was asked for."""


def _digest(state: Mapping[str, torch.Tensor]) -> str:
    h = hashlib.sha256()
    for name in sorted(state):
        tensor = state[name].detach().cpu().contiguous()
        h.update(name.encode())
        h.update(str(tuple(tensor.shape)).encode())
        h.update(str(tensor.dtype).encode())
        h.update(tensor.view(torch.uint8).numpy().tobytes() if tensor.numel() else b"")
    return h.hexdigest()


def register_model(cls: type[nn.Module]) -> type[nn.Module]:
    """Make your own module class checkpointable (usable as a class decorator).

    The class needs a ``config`` property returning its constructor keyword arguments as plain values,
    so that ``cls(**model.config)`` rebuilds it; :func:`load_checkpoint` then finds it by its name in
    :data:`fnnlib.models.MODELS`. Register the class before loading a checkpoint of it.
    """
    if not (isinstance(cls, type) and issubclass(cls, nn.Module)):
        raise TypeError(f"register_model takes an nn.Module subclass, got {cls!r}")
    if not isinstance(getattr(cls, "config", None), property):
        raise TypeError(f"{cls.__name__} needs a `config` property (its constructor arguments as plain values)")
    known = MODELS.get(cls.__name__)
    if known is not None and known is not cls:
        raise ValueError(f"another model class is already registered as {cls.__name__!r}")
    MODELS[cls.__name__] = cls
    return cls


def save_checkpoint(path: str | os.PathLike[str], model: nn.Module, meta: Mapping[str, Any] | None = None) -> Path:
    """Save ``model`` (a class in ``fnnlib.models.MODELS``) with its config and a checksum.

    ``meta`` holds plain values only (numbers, strings, lists, dicts): training
    settings, the seed, the final loss. Writes atomically. Your own module class
    is saved once registered with :func:`register_model`.
    """
    kind = type(model).__name__
    if MODELS.get(kind) is not type(model):
        raise TypeError(f"cannot checkpoint a {kind}: register its class first with "
                        f"fnnlib.register_model({kind}) (it needs a `config` property); known models: {sorted(MODELS)}")
    state = {k: v.detach().cpu() for k, v in model.state_dict().items()}
    payload = {"format": FORMAT, "version": VERSION, "kind": kind, "config": model.config,
               "state_dict": state, "sha256": _digest(state), "meta": dict(meta or {})}
    path = Path(path)
    with atomic_write(path) as fh:  # a file object: the archive inside is named "archive", not after a temp file
        torch.save(payload, fh)
    return path


def load_checkpoint(path: str | os.PathLike[str], *, expected_config: Mapping[str, Any] | None = None,
                    expected_kind: str | None = None) -> tuple[nn.Module, dict[str, Any]]:
    """Load a model saved by :func:`save_checkpoint`; return ``(model, meta)``.

    Raises
    ------
    CheckpointError
        If the file is missing, unreadable, not an fnnlib checkpoint, its
        checksum fails, or its kind/config differ from the expected ones.
    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"checkpoint {path} does not exist (run the task that trains it first)")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types for a damaged file
        raise CheckpointError(f"checkpoint {path} is corrupt or not a torch file: {exc}") from exc
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise CheckpointError(f"{path} is not an fnnlib checkpoint")
    if payload.get("version") != VERSION:
        raise CheckpointError(f"{path} has checkpoint version {payload.get('version')}, this fnnlib reads {VERSION}")
    kind, config, state = payload.get("kind"), payload.get("config"), payload.get("state_dict")
    if kind not in MODELS or not isinstance(config, dict) or not isinstance(state, dict):
        raise CheckpointError(f"checkpoint {path} is malformed (kind={kind!r})")
    if expected_kind is not None and kind != expected_kind:
        raise CheckpointError(f"checkpoint {path} holds a {kind}, expected a {expected_kind}")
    if _digest(state) != payload.get("sha256"):
        raise CheckpointError(f"checkpoint {path} fails its checksum: the weights are corrupt")
    if expected_config is not None:
        diff = {k: (config.get(k), v) for k, v in expected_config.items() if config.get(k) != v}
        if diff:
            detail = ", ".join(f"{k}: file has {a!r}, expected {b!r}" for k, (a, b) in diff.items())
            raise CheckpointError(f"checkpoint {path} does not match the requested model ({detail})")
    dtype = next((v.dtype for v in state.values() if v.is_floating_point()), torch.float32)
    model = MODELS[kind](**config).to(dtype)  # rebuild in the saved precision, not torch's default
    try:
        model.load_state_dict(state)
    except RuntimeError as exc:
        raise CheckpointError(f"checkpoint {path} weights do not fit its config: {exc}") from exc
    return model, dict(payload.get("meta") or {})
