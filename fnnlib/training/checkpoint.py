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
from fnnlib.models import MODELS, NeuralODEEnsemble

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
                        f"fnnlib.training.register_model({kind}) (it needs a `config` property); known models: {sorted(MODELS)}")
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


def seed_checkpoint_name(seed: int, stem: str = "neural_ode") -> str:
    """The file name of one seed's checkpoint, ``{stem}_seed{seed}.pt`` (read by :func:`load_seed_checkpoints`)."""
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"a seed is a non-negative int, got {seed!r}")
    return f"{stem}_seed{seed}.pt"


def load_seed_checkpoints(directory: str | os.PathLike[str], stem: str = "neural_ode",
                          expected_kind: str | None = "NeuralODE", *,
                          run: Mapping[str, Any] | None = None) -> list[tuple[int, nn.Module, dict[str, Any]]]:
    """Load every seed's checkpoint ``{stem}_seed{s}.pt`` in ``directory``; return ``[(seed, model, meta), ...]``.

    The one loader of an ensemble's members; a seed is an ``int``. The list is in ascending seed order (in the
    order of ``run["seeds"]`` when given). Each file is read by :func:`load_checkpoint` (checksum, kind), its
    ``meta["seed"]`` must name the seed of its file name (so the members hold distinct seeds), and when the
    files record the run's ``meta["seeds"]`` they must agree and name exactly the files present (so a missing
    or stale seed file is refused).

    ``run``: the parameters the training task ran with (its run record, e.g. ``upstream_parameters``). Its
    ``seeds`` must be exactly the files present, and each value a member's meta records too (``epochs``,
    ``lr``, ...: its recipe) must be the run's, so a file swapped in from another run is refused by name.

    Raises
    ------
    CheckpointError
        If ``directory`` holds no such file, or any file is corrupt, of another kind, or inconsistent.
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise CheckpointError(f"checkpoint directory {directory} does not exist (run the task that trains it first)")
    prefix = f"{stem}_seed"
    found: dict[int, Path] = {}
    for path in directory.glob(f"{prefix}*.pt"):
        digits = path.name[len(prefix):-len(".pt")]
        if digits.isdigit() and path.name == seed_checkpoint_name(int(digits), stem):
            found[int(digits)] = path
    if not found:
        raise CheckpointError(f"no per-seed checkpoints {stem}_seed<s>.pt in {directory} "
                              f"(run the task that trains them first)")
    loaded = []
    run_seeds: list[int] | None = None
    for seed in sorted(found):
        model, meta = load_checkpoint(found[seed], expected_kind=expected_kind)
        if meta.get("seed") != seed:
            raise CheckpointError(f"checkpoint {found[seed]} records seed {meta.get('seed')!r}, its name says {seed}")
        if "seeds" in meta:
            if run_seeds is None:
                run_seeds = list(meta["seeds"])
            elif list(meta["seeds"]) != run_seeds:
                raise CheckpointError(f"checkpoint {found[seed]} comes from another run (seeds {meta['seeds']}, "
                                      f"the others {run_seeds})")
        loaded.append((seed, model, meta))
    if run_seeds is not None and sorted(run_seeds) != sorted(found):
        raise CheckpointError(f"{directory} holds the seeds {sorted(found)} but the run trained {run_seeds}: "
                              f"a seed's checkpoint is missing or stale")
    return loaded if run is None else _as_run(loaded, run, found)


def _as_run(loaded: list[tuple[int, nn.Module, dict[str, Any]]], run: Mapping[str, Any],
            found: Mapping[int, Path]) -> list[tuple[int, nn.Module, dict[str, Any]]]:
    """The members checked against the run's record (seeds, recipe), in the run's seed order."""
    seeds = run.get("seeds")
    if seeds is not None:
        if len(set(seeds)) != len(seeds) or sorted(seeds) != sorted(found):
            raise CheckpointError(f"the run trained the seeds {list(seeds)}, {next(iter(found.values())).parent} "
                                  f"holds {sorted(found)}: a member's checkpoint is missing or stale")
        order = {s: i for i, s in enumerate(seeds)}
        loaded = sorted(loaded, key=lambda m: order[m[0]])
    for seed, _, meta in loaded:
        for key, value in meta.items():
            if key not in ("seed", "seeds") and run.get(key) is not None and run[key] != value:
                raise CheckpointError(f"checkpoint {found[seed]} was trained with {key} = {value!r}, "
                                      f"the run record says {run[key]!r}: it comes from another run")
    return loaded


def load_seed_ensemble(directory: str | os.PathLike[str], stem: str = "neural_ode", *,
                       run: Mapping[str, Any] | None = None, dtype: torch.dtype | None = None) -> NeuralODEEnsemble:
    """Every seed's neural ODE of Eq. (2) in ``directory`` side by side: one :class:`NeuralODEEnsemble` whose
    member e is the network of seed ``ensemble.seeds[e]``.

    The members are read by :func:`load_seed_checkpoints` (same checks, same seed order, ``run`` as there) and
    converted to ``dtype`` where given (float64 for runs that must not overflow; the weights are the same numbers).
    """
    loaded = load_seed_checkpoints(directory, stem, "NeuralODE", run=run)
    members = [m if dtype is None else m.to(dtype) for _, m, _ in loaded]
    return NeuralODEEnsemble.from_members(members, [s for s, _, _ in loaded])
