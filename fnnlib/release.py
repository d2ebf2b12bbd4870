r"""The paper authors' trained networks (their public release), checked and mapped onto fnnlib's models.

The release (github JIAjindou/Feedback-neural-network, commit 3951543) ships the networks behind the paper's
figures. It has no license: fnnlib reads the files from a data directory (``<data_dir>/release/``, same
relative paths as in the release), checks each one's SHA-256 against :data:`RELEASE_FILES`, and never
redistributes them.

Reading them safely
-------------------
The spiral and bottle ``.pt`` files are whole pickles of the release's own classes (``__main__.ODEFunc``,
``__main__.BackFunc``). They are never unpickled with code execution. :func:`read_pickled_module` first lists
every global the pickle names (:mod:`pickletools`, nothing is run) and refuses any outside
:data:`ALLOWED_GLOBALS`; it then loads with torch's ``weights_only`` unpickler, whose allow-list gets only inert
stand-ins for the release's module classes (they keep their pickled state, and run nothing). The quadrotor's
``.npy`` files are read with ``allow_pickle=False``; an object array is refused unread.

The layouts found (each backed by the evidence named)
-----------------------------------------------------
* Spiral (App. A.3): ``ODEFunc.net`` / ``BackFunc.net`` are ``nn.Sequential`` MLPs, autonomous
  (``forward(t, y)`` ignores ``t``), no input scaling, ReLU; their ``net.{i}`` keys are those of
  :func:`~fnnlib.models.mlp`. The release's spiral is ``y @ A + eps`` (row vector times ``A``), the transpose of
  Eq. (26) as printed: its case :math:`(\omega, \eta, \varepsilon)` is our ``Spiral(-omega, eta, eps)``
  (:func:`release_spiral`). With it, the loaded networks reproduce the losses in their file names.
* Bottle (App. A.4): the same ``ODEFunc`` form on the state ``[p, v]`` (6), 3 hidden layers of 100, ReLU: the
  order of :attr:`fnnlib.data.Throws.state`.
* Quadrotor residual (App. A.5.2): one float64 column of 3024 numbers (``Quadrotor_NODE.NN_model``): per layer
  ``W`` (out x in) reshaped **column-major** (CasADi) then ``b``; layers 6-36-36-36-3, tanh, no bias on the
  last. The release *subtracts* the network, ``v' = a_nom - NN(v, Theta)``, so our residual (added, Eq. (27)
  with :math:`f_{neural}`) is ``-NN``. The input ``x[3:9] = (v, Theta)`` is ours (z down,
  ``R = Rz Ry Rx``).
* Quadrotor MLP (App. A.5.4 baseline): a ``Drag_MLP`` state dict, the same 6-36-36-36-3 tanh layers with no
  last bias, regressed on the drag ``R D R^T v`` that the release's simulator subtracts: again ``-MLP``.
"""

from __future__ import annotations

import hashlib
import pickle
import pickletools
import re
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
import torch
from torch import Tensor, nn

from fnnlib.data.bottle import DataError
from fnnlib.models import NeuralFeedback, NeuralODE
from fnnlib.quadrotor.residual import AeroResidual
from fnnlib.systems import Spiral

__all__ = [
    "ALLOWED_GLOBALS", "BOTTLE_ODE_NAMES", "RELEASE_FILES", "RESIDUAL_RUNS", "MLP_RUNS", "SPIRAL_FEEDBACK_NAMES",
    "SPIRAL_LOSS_NAMES", "SPIRAL_ODE_NAMES", "MAX_PICKLE_BYTES", "PickledModule", "ReleaseError", "UnsafePickleError",
    "load_release_bottle_ode", "load_release_feedback_losses", "load_release_losses", "load_release_mlp",
    "load_release_quadrotor_networks", "load_release_residual", "load_release_spiral_feedback",
    "load_release_spiral_networks", "load_release_spiral_ode", "load_present_feedback_losses", "present_loss_names",
    "read_pickled_module", "release_files", "release_present", "release_spiral",
]

#: the largest release pickle read, on disk and unpacked (the release's largest ``.pt`` is 91 KB, 89 KB unpacked);
#: a file or archive over it is refused before it is read (a small zip bomb unpacks to gigabytes)
MAX_PICKLE_BYTES = 8 * 1024**2

#: path below ``<data_dir>/release/`` -> SHA-256 of the published file (the data directory's README table)
RELEASE_FILES: Mapping[str, str] = MappingProxyType({
    "irregular_object/trained_model/Neural_ODE_ite1000_loss0.047562.pt":
        "fb0494f64ec159f1be17a0744c076910f1d14a24d0dcdc666f920c017a6fbec2",
    "irregular_object/trained_model/Neural_ODE_ite1000_loss0.048128.pt":
        "b184cbb8f7b30dd2ba2cbdbd9912ac6a93f1c678a1504aa76c55cdf9615e4732",
    "quadrotor/learning_MLP/learned_models/Nov17_15-52-54_2024_minibatch_torchADAM/model_param_epoch500.pth":
        "3bb23f211318d9801f6771c31e69ac69b68c010835c172c64e668b8b25a3e92d",
    "quadrotor/learning_MLP/learned_models/Nov17_16-00-48_2024_minibatch_torchADAM/model_param_epoch500.pth":
        "071f43cddfc2e69e41348b4dce5c0cedde344b91a89ae20e4c1b78155702b579",
    "quadrotor/learning_NODE/learned_models/Nov14_17-20-59_2024_minibatch_adam/model_param_epoch50.npy":
        "883009ab22eecb313c2083b9aabb8244992e4a1573c4eac80b42a1ef29575d48",
    "quadrotor/learning_NODE/learned_models/Nov14_17-21-18_2024_minibatch_adam/model_param_epoch50.npy":
        "3039a945524df761ceded283b4f57ce8ade69c662b61cbe2af9ca45a30c184f7",
    "quadrotor/learning_NODE/learned_models/Nov14_17-21-23_2024_minibatch_adam/model_param_epoch50.npy":
        "e47527da6d7d87ec6d1f170a28542846a6db757e26a11367d0abdc6faa54ae78",
    "quadrotor/learning_NODE/learned_models/Nov14_17-21-27_2024_minibatch_adam/model_param_epoch50.npy":
        "e68b64c33c2c2d6251a0327c45985175d79cd5696c6cd8f2d9b1ad237ad3aaed",
    "quadrotor/learning_NODE/learned_models/Nov14_17-21-33_2024_minibatch_adam/model_param_epoch50.npy":
        "71de955f15d87ad7b38ea7a855746a2c9414b0cad6372d2d34838f5ac87877e2",
    "quadrotor/learning_NODE/log/Nov14_17-20-59_2024_minibatch_adam/loss_record.npy":
        "bf4e83f98f67799fe0c4df902d2d709d11811b999e50486557141840cbb26648",
    "quadrotor/learning_NODE/log/Nov14_17-21-18_2024_minibatch_adam/loss_record.npy":
        "68b4962cc03fec2794c23bd4226c0515a661e28b8ea0557f9edede82630670d3",
    "quadrotor/learning_NODE/log/Nov14_17-21-23_2024_minibatch_adam/loss_record.npy":
        "3a582673027ce7957d7810c68c015ba72a2056366aa25a8660c5340c4cc75851",
    "quadrotor/learning_NODE/log/Nov14_17-21-27_2024_minibatch_adam/loss_record.npy":
        "8a50ef9adf8c5284cbbd80d2660399dbc9948d56ca2503db199eca019a94e54a",
    "quadrotor/learning_NODE/log/Nov14_17-21-33_2024_minibatch_adam/loss_record.npy":
        "afedaa8e071c7d51a9f1ace50ce8c5c1d9c6dea8eb4036196882e81f236d1011",
    "spiral_curve/iteration_ite135.txt":
        "7b33cb40261bd001d77b3b1bbf944fb71a6b66bebf2355965302f3fa5386effb",
    "spiral_curve/trained_model/iteration_ite1074.txt":
        "c65a7e68d115de0741981e6b42a6ddd4549f710201730c4e23c628e26c173d7c",
    "spiral_curve/trained_model/iteration_ite180.txt":
        "020794f7eafbe24cc791adbf488f1e59a309160788d015262a60f290e625c140",
    "spiral_curve/trained_model/iteration_ite477_conver.txt":
        "7c2a2cb1bcda16a4ffc60eaff731e58d3704c182cc4eb03191918a5c9789fa0d",
    "spiral_curve/trained_model/iteration_ite492_conver.txt":
        "8bedae9b0094de64e2409572ed00374fbad30a000a310ba473667ebbc125fef8",
    "spiral_curve/trained_model/iteration_ite511.txt":
        "385ae38eba0c5d2d6c08f1c9cd8b303d18c6093db99516eef434975a7afb8db7",
    "spiral_curve/trained_model/FeedbackNN_demo.pt":
        "1edf7a58a2e4fe830b5ce69da430551fc20534145ec5e84809448612f8a743ff",
    "spiral_curve/trained_model/FeedbackNN_ite1074_loss0.483191.pt":
        "2af7994b155195610f16dca462daa232e5d81e8c77c109ebbd30dae4199214ae",
    "spiral_curve/trained_model/FeedbackNN_ite135_loss0.494884.pt":
        "d5762d3ceacb398a8fc127d222e457cd9549106d79b060b1a74bf5525510581f",
    "spiral_curve/trained_model/FeedbackNN_ite180_loss0.497830.pt":
        "601ab540037802ef18f7626b9764e28aaf72b73d4e48f20f8bc9835781a0068b",
    "spiral_curve/trained_model/FeedbackNN_ite477_loss0.494530_conver.pt":
        "811440288acb669c19c306a231c3763169616252697a432ce24e0730e876462f",
    "spiral_curve/trained_model/FeedbackNN_ite492_loss0.496539_conver.pt":
        "414650936069bfcf176af881106c95cc5014578c09cc79656e45bfba1e87541d",
    "spiral_curve/trained_model/FeedbackNN_ite511_loss0.495402.pt":
        "7a877a65206f76663fb077bebad461175379abd42a39ab1098ffd03b230c0e79",
    "spiral_curve/trained_model/Neural_ODE_domran.pt":
        "0a75e006c53d6ee35b795f08ddf9f73fbe1bae4392b851bbcc0288d3250a0c86",
    "spiral_curve/trained_model/Neural_ODE_ite0400_loss0.301785.pt":
        "f2209b27d154e83b48d2ecb5dd7fc5514ed5e61b8cdc2f870b49fb083dd61921",
    "spiral_curve/trained_model/Neural_ODE_ite1000_loss0.008033.pt":
        "8c522e7fe228b36f4d33294881c8d7933016964685317008b61e15bb1dd88ec7",
    "spiral_curve/trained_model/Neural_ODE_ite1000_loss0.028490.pt":
        "81ed3d5e1623e764e6be7603d46d24fe77a4444888267b2f440dbda4cb6f0c2d",
    "spiral_curve/trained_model/Neural_ODE_ite400_loss0.2.pt":
        "55fa8ab303aefc8dab203af5c8c9d1a1d36c91806e341fe0b8a18cf061b30b61",
})

_SPIRAL = "spiral_curve/trained_model"
_BOTTLE = "irregular_object/trained_model"
_RESIDUAL = "quadrotor/learning_NODE/learned_models"
_MLP = "quadrotor/learning_MLP/learned_models"
_LOSSES = "quadrotor/learning_NODE/log"


def _names(folder: str, prefix: str = "") -> tuple[str, ...]:
    """File (or run-folder) names directly below ``folder`` in the pinned table."""
    rest = (key[len(folder) + 1:] for key in RELEASE_FILES if key.startswith(folder + "/"))
    return tuple(sorted({r.split("/")[0] for r in rest if r.startswith(prefix)}))


SPIRAL_ODE_NAMES = _names(_SPIRAL, "Neural_ODE")
"""The spiral neural ODEs: nominal ones (``ite..._loss...``, Fig. 4(c)) and the domain-randomised one (Fig. 5(a))."""
SPIRAL_FEEDBACK_NAMES = _names(_SPIRAL, "FeedbackNN")
"""The spiral neural feedbacks (Sec. 4, Fig. 5(b))."""
SPIRAL_LOSS_NAMES = (*_names(_SPIRAL, "iteration_"), "../iteration_ite135.txt")
"""The loss curves of the release's neural-feedback trainings (Fig. 5(c)): ``iteration_ite<K>[_conver].txt``, one
per training run, the run that wrote ``FeedbackNN_ite<K>_...pt``; the ite135 curve sits one folder up."""
BOTTLE_ODE_NAMES = _names(_BOTTLE)
"""The bottle neural ODEs (Sec. 5.1, Fig. 6)."""
RESIDUAL_RUNS = _names(_RESIDUAL)
"""The 5 runs (random initialisations) of the quadrotor residual (App. A.5.2, Q1)."""
MLP_RUNS = _names(_MLP)
"""The 2 runs of the quadrotor MLP baseline (App. A.5.4)."""

#: activation class in the release's pickles -> name in :data:`fnnlib.models.ACTIVATIONS`
_ACTIVATIONS = MappingProxyType({"torch.nn.modules.activation.ReLU": "relu", "torch.nn.modules.activation.Tanh": "tanh"})
_SEQUENTIAL, _LINEAR = "torch.nn.modules.container.Sequential", "torch.nn.modules.linear.Linear"
_MODULE_CLASSES = ("__main__.ODEFunc", "__main__.BackFunc", _SEQUENTIAL, _LINEAR, *_ACTIVATIONS)

ALLOWED_GLOBALS = frozenset({
    "collections OrderedDict", "__builtin__ set", "builtins set", "torch FloatStorage",
    "torch._utils _rebuild_tensor_v2", "torch._utils _rebuild_parameter",
    *(" ".join(name.rsplit(".", 1)) for name in _MODULE_CLASSES),
})
"""Every global (``"module name"``, as a pickle writes it) the release's ``.pt`` / ``.pth`` files may name."""

# opcodes that build a callable from somewhere other than a GLOBAL the scan can read (absent from the release)
_OPAQUE_OPCODES = frozenset({"STACK_GLOBAL", "INST", "OBJ", "EXT1", "EXT2", "EXT4"})


class ReleaseError(DataError):
    """A release file is missing, not the published one, or not of the layout its loader expects."""


class UnsafePickleError(ReleaseError):
    """A pickle names something outside the allow-list; it was refused before anything in it ran."""


# ---------------------------------------------------------------- the files
def _release_file(data_dir: str | Path, key: str) -> Path:
    """``<data_dir>/release/<key>``, present and with its pinned SHA-256, else :class:`ReleaseError`."""
    path = Path(data_dir) / "release" / key
    if not path.is_file():
        raise ReleaseError(
            f"missing {path}. The authors' trained networks come from their public release "
            f"(github JIAjindou/Feedback-neural-network, path {key}); they are not redistributed here. "
            "Copy the release's files into <data_dir>/release/ (same relative paths) or pass another data directory.")
    with path.open("rb") as fh:
        digest = hashlib.file_digest(fh, "sha256").hexdigest()
    if digest != RELEASE_FILES[key]:
        raise ReleaseError(f"{path} fails its SHA-256 check: it is not the published file (corrupt or changed)")
    return path


def release_files(data_dir: str | Path | None, under: str = "") -> dict[str, str]:
    """Each pinned release file (below ``under``, e.g. ``"spiral_curve/"``) -> ``"ok"`` (there, its SHA-256 the
    published one), ``"missing"`` or ``"changed"`` (there, another SHA-256: corrupt or not the published file)."""
    state: dict[str, str] = {}
    for key, digest in RELEASE_FILES.items():
        if not key.startswith(under):
            continue
        path = Path(data_dir) / "release" / key if data_dir is not None else None
        if path is None or not path.is_file():
            state[key] = "missing"
            continue
        with path.open("rb") as fh:
            state[key] = "ok" if hashlib.file_digest(fh, "sha256").hexdigest() == digest else "changed"
    return state


def release_present(data_dir: str | Path | None, under: str = "") -> bool:
    """Whether every pinned release file below ``under`` is in ``<data_dir>/release/`` with its published SHA-256.

    The why notebooks evaluate the authors' networks only then; otherwise they judge ours only and say so (an
    empty or partly fetched ``release/`` folder is no release).
    """
    files = release_files(data_dir, under)
    return bool(files) and all(v == "ok" for v in files.values())


def _loss_key(name: str) -> str:
    return "spiral_curve/iteration_ite135.txt" if name.startswith("../") else f"{_SPIRAL}/{name}"


def present_loss_names(data_dir: str | Path | None) -> tuple[str, ...]:
    """The names of :data:`SPIRAL_LOSS_NAMES` whose curve is in ``<data_dir>/release/`` with its published SHA-256.

    A data directory may hold only some of the release's curves (the one at ``spiral_curve/iteration_ite135.txt``
    is the one the paper's Fig. 5(c) draws); a why reads those present and says how many.
    """
    return tuple(n for n in SPIRAL_LOSS_NAMES if release_present(data_dir, _loss_key(n)))


def _key(folder: str, name: str, choices: Sequence[str], what: str) -> str:
    if name not in choices:
        raise ValueError(f"unknown {what} {name!r}; the release has {list(choices)}")
    matches = [k for k in RELEASE_FILES if k == f"{folder}/{name}" or k.startswith(f"{folder}/{name}/")]
    if len(matches) != 1:
        raise ValueError(f"{what} {name!r} names {len(matches)} files of the release, not one")
    return matches[0]


# ---------------------------------------------------------------- the restricted unpickler
class _StandIn:
    """Takes the place of one of the release's module classes while unpickling: keeps the state, runs nothing."""

    release_class: ClassVar[str] = ""

    def __setstate__(self, state: Any) -> None:
        self.state = state


_STAND_INS = tuple((type(name.rsplit(".", 1)[1], (_StandIn,), {"release_class": name}), name)
                   for name in _MODULE_CLASSES)


@dataclass(frozen=True)
class PickledModule:
    """A module read from a release pickle: its class name, own parameters and children (no code of it ran).

    Attributes
    ----------
    cls : str
        The pickled class, e.g. ``"__main__.ODEFunc"`` or ``"torch.nn.modules.linear.Linear"``.
    parameters : mapping str -> Tensor
        The module's own parameters (a ``bias=False`` layer has no ``"bias"``).
    children : mapping str -> PickledModule
        Sub-modules, in their pickled order.
    """

    cls: str
    parameters: Mapping[str, Tensor]
    children: Mapping[str, PickledModule]


def _scan_globals(path: Path) -> bytes:
    """The archive's ``data.pkl``, after checking every global it names is allowed (nothing is unpickled).

    A file, or an archive unpacked, over :data:`MAX_PICKLE_BYTES` is refused before anything in it is read.
    """
    size = path.stat().st_size
    if size > MAX_PICKLE_BYTES:
        raise ReleaseError(f"{path} is {size} bytes, over the {MAX_PICKLE_BYTES} a release network takes; "
                           "refused unread")
    if not zipfile.is_zipfile(path):
        raise ReleaseError(f"{path} is not a torch zip archive (the release's format); refused unread")
    with zipfile.ZipFile(path) as zf:
        unpacked = sum(info.file_size for info in zf.infolist())
        if unpacked > MAX_PICKLE_BYTES:
            raise ReleaseError(f"{path} unpacks to {unpacked} bytes, over the {MAX_PICKLE_BYTES} a release network "
                               "takes (a zip bomb?); refused unread")
        members = [n for n in zf.namelist() if n == "data.pkl" or n.endswith("/data.pkl")]
        if len(members) != 1:
            raise ReleaseError(f"{path}: expected one data.pkl in the archive, found {len(members)}")
        data = zf.read(members[0])
    try:
        for op, arg, _ in pickletools.genops(data):
            if op.name in _OPAQUE_OPCODES:
                raise UnsafePickleError(f"{path}: the pickle uses opcode {op.name}, which the release's files never "
                                        "use (it can reach a callable the scan cannot name); refused before unpickling")
            if op.name == "GLOBAL" and arg not in ALLOWED_GLOBALS:
                raise UnsafePickleError(f"{path} names the global {arg.replace(' ', '.')!r}, which is not among those "
                                        "the release's networks use; refused before unpickling")
    except ValueError as exc:  # pickletools: a truncated or malformed stream
        raise ReleaseError(f"{path}: its pickle is malformed ({exc})") from exc
    return data


def _torch_restricted_load(path: Path) -> Any:
    """torch's ``weights_only`` unpickler, its allow-list extended only by the inert stand-ins."""
    try:
        with torch.serialization.safe_globals(list(_STAND_INS)):
            return torch.load(path, weights_only=True, map_location="cpu")
    except pickle.UnpicklingError as exc:
        found = re.search(r"GLOBAL ([\w.]+)", str(exc))
        named = f" (it names {found.group(1)!r})" if found else ""
        raise UnsafePickleError(f"{path}: refused by the weights-only unpickler{named}; nothing in it ran") from exc
    except (RuntimeError, TypeError, KeyError, EOFError, zipfile.BadZipFile) as exc:
        raise ReleaseError(f"{path} cannot be read as a torch file: {exc}") from exc


def _to_module(obj: Any, path: Path) -> PickledModule:
    if not isinstance(obj, _StandIn) or not isinstance(getattr(obj, "state", None), dict):
        raise ReleaseError(f"{path}: expected a pickled module, found {type(obj).__name__}")
    state = obj.state
    if state.get("_buffers"):
        raise ReleaseError(f"{path}: {obj.release_class} holds buffers {list(state['_buffers'])}; no release network does")
    params = {k: v for k, v in (state.get("_parameters") or {}).items() if v is not None}
    if not all(isinstance(v, Tensor) and v.is_floating_point() and bool(torch.isfinite(v).all())
               for v in params.values()):
        raise ReleaseError(f"{path}: {obj.release_class} has a parameter that is not a finite float tensor")
    children = {k: _to_module(v, path) for k, v in (state.get("_modules") or {}).items()}
    return PickledModule(obj.release_class, MappingProxyType({k: v.detach() for k, v in params.items()}),
                         MappingProxyType(children))


def read_pickled_module(path: str | Path) -> PickledModule | dict[str, Tensor]:
    """Read a release ``.pt`` / ``.pth`` file without running code from it.

    Two locks: every global the pickle names must be in :data:`ALLOWED_GLOBALS` (read by :mod:`pickletools`
    before anything is unpickled), and the load itself is torch's ``weights_only`` unpickler, whose allow-list
    gains only inert stand-ins for the release's module classes.

    Returns
    -------
    PickledModule
        For a whole pickled module (the spiral and bottle networks).
    dict str -> Tensor
        For a pickled state dict (the quadrotor MLPs).

    Raises
    ------
    UnsafePickleError
        The pickle names a global outside the allow-list (e.g. ``posix.system``, ``builtins.eval``).
    ReleaseError
        Not a torch zip archive, malformed, or holding something other than a module or a state dict.
    """
    path = Path(path)
    _scan_globals(path)
    obj = _torch_restricted_load(path)
    if isinstance(obj, dict) and all(isinstance(k, str) and isinstance(v, Tensor) for k, v in obj.items()):
        return {k: v.detach() for k, v in obj.items()}
    return _to_module(obj, path)


# ---------------------------------------------------------------- spiral and bottle: nn.Sequential MLPs
def _sequential_state(root: PickledModule, cls: str, path: Path) -> tuple[list[int], str, dict[str, Tensor]]:
    """``root.net`` (Linear, activation, ..., Linear) as (hidden widths, activation, our ``net.{i}`` state dict)."""
    net = root.children.get("net")
    if root.cls != cls or net is None or net.cls != _SEQUENTIAL:
        raise ReleaseError(f"{path}: expected a pickled {cls} with an nn.Sequential `net`, found {root.cls}")
    layers = list(net.children.values())
    acts = {m.cls for m in layers[1::2]}
    if (len(layers) % 2 == 0 or any(m.cls != _LINEAR for m in layers[::2]) or len(acts) != 1
            or not acts <= set(_ACTIVATIONS) or list(net.children) != [str(i) for i in range(len(layers))]):
        raise ReleaseError(f"{path}: `net` is not an MLP (Linear, activation, ..., Linear): "
                           f"{[m.cls.rsplit('.', 1)[1] for m in layers]}")
    state = {f"net.{i}.{p}": v for i, m in enumerate(layers) for p, v in m.parameters.items()}
    hidden = [int(m.parameters["weight"].shape[0]) for m in layers[:-2:2]]
    return hidden, _ACTIVATIONS[acts.pop()], state


def _load_into(model: nn.Module, state: dict[str, Tensor], path: Path) -> nn.Module:
    model = model.to(next(iter(state.values())).dtype)
    try:
        model.load_state_dict(state)
    except RuntimeError as exc:  # missing keys or shapes that do not fit
        raise ReleaseError(f"{path}: its layers do not fit {type(model).__name__}: {exc}") from exc
    return model.eval()


def _mirror_y(net: nn.Sequential) -> None:
    r"""Replace the MLP ``g`` by ``S g(S x)``, ``S = diag(1, -1)``: exact, folded into the first and last layers."""
    with torch.no_grad():
        net[0].weight[:, 1].neg_()
        net[-1].weight[1].neg_()
        net[-1].bias[1].neg_()


def _spiral_net(data_dir: str | Path, name: str, cls: str, choices: Sequence[str], mirror: bool,
                make: type[nn.Module]) -> nn.Module:
    path = _release_file(data_dir, _key(_SPIRAL, name, choices, "spiral network"))
    root = read_pickled_module(path)
    if not isinstance(root, PickledModule):
        raise ReleaseError(f"{path}: expected a pickled {cls}, found a state dict")
    hidden, activation, state = _sequential_state(root, cls, path)
    model = _load_into(make(2, hidden, activation), state, path)
    if mirror:
        _mirror_y(model.net)
    return model


def release_spiral(omega: float, eta: float, eps: float) -> Spiral:
    r"""The release's spiral case :math:`(\omega, \eta, \varepsilon)` as an fnnlib :class:`~fnnlib.systems.Spiral`.

    The release integrates ``y @ A + eps`` with ``A`` the matrix of Eq. (26) (row vector times ``A``), i.e.
    :math:`\dot x = A^\top x + \varepsilon\mathbf 1`: the spiral of Eq. (26) with :math:`\omega` negated (it turns
    the other way). Its nominal task ``(2, 0.1, 0)`` is ``Spiral(-2, 0.1, 0)``.
    """
    return Spiral(omega=-float(omega), eta=float(eta), eps=float(eps))


def load_release_spiral_ode(data_dir: str | Path, name: str, *, mirror: bool = False) -> NeuralODE:
    r"""A release spiral neural ODE :math:`f_{neural}(x)` (Eq. (3), App. A.3.2) as a :class:`~fnnlib.models.NeuralODE`.

    The ``ite..._loss...`` files are trained on the nominal task (Fig. 4(c), S1), ``Neural_ODE_domran.pt`` by
    domain randomisation (Fig. 5(a), D1). A 2-50-2 ReLU MLP: one hidden layer (our preset reads the paper's
    "3 layers with 50 hidden units" as two hidden layers), float32, autonomous. ``name``: one of :data:`SPIRAL_ODE_NAMES`.

    The network fits the release's spiral, :func:`release_spiral` (Eq. (26) with :math:`\omega` negated). With
    ``mirror=True`` it is reflected, ``S f(S x)`` with ``S = diag(1, -1)``, exactly: the release's nominal
    task then becomes Eq. (26)'s own nominal ``Spiral(2, 0.1, 0)`` from the same ``x(0) = (9, 0)``; a case
    with a bias :math:`\varepsilon` maps to the bias ``(eps, -eps)``.

    Raises :class:`ReleaseError` (missing, checksum, layout) or :class:`UnsafePickleError`.
    """
    return _spiral_net(data_dir, name, "__main__.ODEFunc", SPIRAL_ODE_NAMES, mirror,
                       lambda n, hidden, act: NeuralODE(n, hidden, act))


def load_release_spiral_feedback(data_dir: str | Path, name: str, *, mirror: bool = False) -> NeuralFeedback:
    r"""A release spiral neural feedback :math:`h_{neural}(x - \hat x)` (Sec. 4, Eq. (12), App. A.3.3).

    ``BackFunc``: a 2-50-50-2 ReLU MLP of the observation error ``e = x - x_hat``, added to the neural ODE's
    rate, ``f_hat = f_neural(x) + h(e)`` (Fig. 5(b)); that is :class:`~fnnlib.models.NeuralFeedback`. It was
    trained against one nominal neural ODE over 20 release cases (:func:`release_spiral`); the release's
    notes pair ``FeedbackNN_ite1074`` with ``Neural_ODE_ite0400_loss0.301785.pt`` and ``ite180``, ``ite511``,
    ``ite477``, ``ite492`` with ``Neural_ODE_ite400_loss0.2.pt``. ``mirror`` as in
    :func:`load_release_spiral_ode` (``S h(S e)``). ``name``: one of :data:`SPIRAL_FEEDBACK_NAMES`.
    """
    return _spiral_net(data_dir, name, "__main__.BackFunc", SPIRAL_FEEDBACK_NAMES, mirror,
                       lambda n, hidden, act: NeuralFeedback(n, hidden, act))


def load_release_spiral_networks(data_dir: str | Path | None, ode: str, feedback: str,
                                  dr_ode: str) -> tuple[NeuralODE, NeuralFeedback, NeuralODE] | None:
    """The authors' networks of Sec. 4: the nominal neural ODE ``ode``, the neural feedback ``feedback`` trained
    against it (Alg. 1) and the domain-randomized neural ODE ``dr_ode``; ``None`` unless all three are in
    ``data_dir`` with their published SHA-256 (:func:`release_present`)."""
    if not all(release_present(data_dir, f"{_SPIRAL}/{n}") for n in (ode, feedback, dr_ode)):
        return None
    return (load_release_spiral_ode(data_dir, ode), load_release_spiral_feedback(data_dir, feedback),
            load_release_spiral_ode(data_dir, dr_ode))


def load_release_bottle_ode(data_dir: str | Path, name: str) -> NeuralODE:
    r"""A release bottle neural ODE (Sec. 5.1, App. A.4; Fig. 6, O1) as a :class:`~fnnlib.models.NeuralODE`.

    ``ODEFunc``: 6-100-100-100-6 ReLU on the state ``[p, v]`` (the order of
    :attr:`~fnnlib.data.Throws.state`), no input scaling, float32, autonomous; it learns all of ``(p', v')``.
    ``name``: one of :data:`BOTTLE_ODE_NAMES`.
    """
    path = _release_file(data_dir, _key(_BOTTLE, name, BOTTLE_ODE_NAMES, "bottle network"))
    root = read_pickled_module(path)
    if not isinstance(root, PickledModule):
        raise ReleaseError(f"{path}: expected a pickled __main__.ODEFunc, found a state dict")
    hidden, activation, state = _sequential_state(root, "__main__.ODEFunc", path)
    return _load_into(NeuralODE(6, hidden, activation), state, path)


# ---------------------------------------------------------------- quadrotor: parameter arrays
#: (in, out, bias) of each layer of the release's residual, ``Quadrotor_NODE.NN_model`` and ``Drag_MLP``
_RESIDUAL_LAYERS = ((6, 36, True), (36, 36, True), (36, 36, True), (36, 3, False))
_RESIDUAL_SIZE = sum(i * o + o * b for i, o, b in _RESIDUAL_LAYERS)  # 3024
_MLP_KEYS = ("input_layer", "hidden_layer1", "hidden_layer2", "output_layer")


def _read_npy(path: Path, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """A float64 array from ``path`` with ``allow_pickle=False``; an object array (a pickle) is refused unread."""
    try:
        arr = np.load(path, allow_pickle=False)
    except ValueError as exc:
        if "allow_pickle" in str(exc):
            raise ReleaseError(f"{path} holds pickled (object) data; refused unread: the release's arrays are "
                               "plain float64") from exc
        raise ReleaseError(f"{path} cannot be read as a .npy array: {exc}") from exc
    if not isinstance(arr, np.ndarray) or arr.dtype != np.float64 or (shape is not None and arr.shape != shape):
        got = (getattr(arr, "dtype", None), getattr(arr, "shape", None))
        raise ReleaseError(f"{path}: expected a float64 array of shape {shape}, got dtype/shape {got}")
    if not np.isfinite(arr).all():
        raise ReleaseError(f"{path}: holds NaN or inf")
    return arr


def _unpack_column(p: np.ndarray) -> list[tuple[Tensor, Tensor | None]]:
    """Split the release's parameter column into (W, b) per layer: W reshaped column-major, as CasADi does."""
    layers, i = [], 0
    for n_in, n_out, bias in _RESIDUAL_LAYERS:
        W = p[i:i + n_in * n_out].reshape((n_out, n_in), order="F")  # CasADi's reshape is column-major
        i += n_in * n_out
        b = p[i:i + n_out] if bias else None
        i += n_out * bias
        layers.append((torch.from_numpy(np.ascontiguousarray(W)), None if b is None else torch.from_numpy(b.copy())))
    return layers


def _residual_from(layers: list[tuple[Tensor, Tensor | None]]) -> AeroResidual:
    """Our residual from the release's layers: same front, last layer negated (the release subtracts it), no bias."""
    net = AeroResidual(tuple(W.shape[0] for W, _ in layers[:-1]), "tanh").to(layers[0][0].dtype)
    linears = [m for m in net.net if isinstance(m, nn.Linear)]
    with torch.no_grad():
        for lin, (W, b) in zip(linears, layers):
            lin.weight.copy_(W)
            lin.bias.copy_(b if b is not None else torch.zeros_like(lin.bias))
        # v' = a_nom - NN(v, Theta) in the release; ours adds f_neural   (Eq. 27 with the residual)
        linears[-1].weight.neg_()
    return net.eval()


def load_release_residual(data_dir: str | Path, run: str) -> AeroResidual:
    r"""A release quadrotor residual :math:`f_{neural}(v, \Theta)` (App. A.5.2, trained by Alg. 3) as an
    :class:`~fnnlib.quadrotor.residual.AeroResidual`.

    ``model_param_epoch50.npy``: a float64 column (3024, 1), layers 6-36-36-36-3, tanh, per layer ``W``
    column-major then ``b``, no last bias. Returned in float64 with the sign of Eq. (27)'s added residual
    (``-NN``). ``run``: one of :data:`RESIDUAL_RUNS` (5 random initialisations).
    """
    path = _release_file(data_dir, _key(_RESIDUAL, run, RESIDUAL_RUNS, "residual run"))
    return _residual_from(_unpack_column(_read_npy(path, (_RESIDUAL_SIZE, 1))[:, 0]))


def load_release_mlp(data_dir: str | Path, run: str) -> AeroResidual:
    """A release quadrotor MLP baseline (App. A.5.4, single-step drag regression) as an
    :class:`~fnnlib.quadrotor.residual.AeroResidual` (what the MLP baseline of the flight test uses).

    ``model_param_epoch500.pth``: a ``Drag_MLP`` state dict (``input_layer``, ``hidden_layer1``,
    ``hidden_layer2``, ``output_layer`` without bias), tanh, float32, regressed on the drag ``R D R^T v``
    that the release subtracts: returned as ``-MLP``. ``run``: one of :data:`MLP_RUNS`.
    """
    path = _release_file(data_dir, _key(_MLP, run, MLP_RUNS, "MLP run"))
    sd = read_pickled_module(path)
    want = {f"{k}.{p}" for k in _MLP_KEYS for p in ("weight", "bias")} - {"output_layer.bias"}
    if not isinstance(sd, dict) or set(sd) != want:
        raise ReleaseError(f"{path}: expected a Drag_MLP state dict with keys {sorted(want)}")
    layers = [(sd[f"{k}.weight"], sd.get(f"{k}.bias")) for k in _MLP_KEYS]
    shapes = [(int(W.shape[1]), int(W.shape[0]), b is not None) for W, b in layers]
    if shapes != list(_RESIDUAL_LAYERS) or any(b is not None and b.shape != (W.shape[0],) for W, b in layers):
        raise ReleaseError(f"{path}: layer shapes {shapes} are not the release's {list(_RESIDUAL_LAYERS)}")
    return _residual_from(layers)


def load_release_quadrotor_networks(data_dir: str | Path,
                                    units: int) -> tuple[list[tuple[str, AeroResidual]], list[tuple[str, AeroResidual]]]:
    """The authors' networks for ``units`` flight units (Sec. 5.2.2): unit k flies the release's residual run k
    (:data:`RESIDUAL_RUNS`, random initialisations of Alg. 3) and MLP k mod 2 (the release has two,
    :data:`MLP_RUNS`); ``[(run, network)]`` each, in float64."""
    if units > len(RESIDUAL_RUNS):
        raise ValueError(f"{units} units, the release has {len(RESIDUAL_RUNS)} residual runs")
    theirs = [(r, load_release_residual(data_dir, r).double()) for r in RESIDUAL_RUNS[:units]]
    mlp_run = [MLP_RUNS[k % len(MLP_RUNS)] for k in range(units)]
    return theirs, [(r, load_release_mlp(data_dir, r).double()) for r in mlp_run]


def load_release_losses(data_dir: str | Path, run: str) -> np.ndarray:
    """The per-epoch training loss of a residual run (``loss_record.npy``), float64, shape (epochs,).

    The loss of App. A.1's learning problem (Alg. 3), the mean over the epoch's mini-batches, one value per
    epoch (50). ``run``: one of :data:`RESIDUAL_RUNS`.
    """
    if run not in RESIDUAL_RUNS:
        raise ValueError(f"unknown residual run {run!r}; the release has {list(RESIDUAL_RUNS)}")
    path = _release_file(data_dir, f"{_LOSSES}/{run}/loss_record.npy")
    arr = _read_npy(path)
    if arr.ndim != 2 or arr.shape[1] != 1 or arr.shape[0] < 1:
        raise ReleaseError(f"{path}: expected one loss per epoch, shape (epochs, 1), got {arr.shape}")
    return arr[:, 0].copy()


def load_release_feedback_losses(data_dir: str | Path, name: str) -> np.ndarray:
    """The logged loss of one of the release's neural-feedback trainings (Fig. 5(c)), float64, shape (K,).

    The file is a printed array of the maximum iterations (2000), zero after the iteration where the training
    stopped; ``K`` is that iteration (the ``ite<K>`` of its name). The loss logged there is the mean absolute
    change-rate error over the randomized cases (the release's ``Total_loss``), and the training stops once it
    falls below 0.5 (read in the release's ``spiral_curve/d_FeedbackNN_converge.py``; not copied). ``name``: one
    of :data:`SPIRAL_LOSS_NAMES`.
    """
    if name not in SPIRAL_LOSS_NAMES:
        raise ValueError(f"unknown loss curve {name!r}; the release has {list(SPIRAL_LOSS_NAMES)}")
    path = _release_file(data_dir, _loss_key(name))
    text = path.read_text(encoding="ascii").strip()
    if not (text.startswith("[") and text.endswith("]")):
        raise ReleaseError(f"{path}: expected a printed array '[...]'")
    try:
        values = np.array([float(v) for v in text[1:-1].split()], dtype=np.float64)
    except ValueError as exc:
        raise ReleaseError(f"{path}: not an array of numbers ({exc})") from exc
    m = re.search(r"ite(\d+)", name)
    K = int(m.group(1)) if m else 0
    if not 4 <= K <= values.size or not np.isfinite(values).all() or (values[:K] <= 0).any() or \
            (values[K:] != 0).any():
        raise ReleaseError(f"{path}: expected {K} positive losses then zeros, got {values.size} values")
    return values[:K].copy()


def load_present_feedback_losses(data_dir: str | Path | None) -> dict[str, np.ndarray]:
    """Every loss curve of the release's neural-feedback trainings (Fig. 5(c)) that is in ``data_dir`` with its
    published SHA-256, by name (:func:`load_release_feedback_losses`); empty without the release."""
    return {name: load_release_feedback_losses(data_dir, name) for name in present_loss_names(data_dir)}
