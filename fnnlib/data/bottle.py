"""The thrown-bottle throws of Sec. 5.1 (App. A.4): loading, checking, and synthetic stand-ins.

The real throws were recorded for Jia et al., "EVOLVER" (IEEE T-RO 2024) and
published with the paper authors' code. They are not ours to redistribute:
fnnlib reads them from a data directory, checks each file's SHA-256 and
shape, and refuses anything else. Tests and the smoke profile use
:func:`synthetic_throws` instead.

Each file holds an array (throws, 1058, 9) with columns
``[acc xyz, pos xyz, vel xyz]`` sampled at 1 ms, z up.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import Tensor

#: file name -> (MATLAB variable, shape, SHA-256 of the published file)
BOTTLE_FILES: dict[str, tuple[str, tuple[int, int, int], str]] = {
    "Training_dataset.mat": ("Training_dataset", (21, 1058, 9),
                             "e0de32851f00c5193f31eee78965f217cee8dbcc27b614a1d3969c63b3eb95a9"),
    "Testing_dataset.mat": ("Testing_dataset", (9, 1058, 9),
                            "0961b345b4d550e9f8d142f154843da0a4e6b54cca9d64d0ce7b252681b10c38"),
}
TS = 1e-3  # sample step, s
ACC, POS, VEL = slice(0, 3), slice(3, 6), slice(6, 9)


class DataError(RuntimeError):
    """A data file is missing, corrupt, or not the expected one."""


@dataclass(frozen=True)
class Throws:
    """A set of throws.

    Attributes
    ----------
    data : Tensor, shape (n_throws, T, 9)
        Columns [acc xyz, pos xyz, vel xyz], float64.
    Ts : float
        Sample step in seconds.
    """

    data: Tensor
    Ts: float = TS

    @property
    def acc(self) -> Tensor:
        """Measured accelerations, (n_throws, T, 3)."""
        return self.data[..., ACC]

    @property
    def state(self) -> Tensor:
        """Position and velocity, the model state [p, v], (n_throws, T, 6)."""
        return torch.cat([self.data[..., POS], self.data[..., VEL]], dim=-1)

    @property
    def t(self) -> Tensor:
        """Sample times, (T,)."""
        return torch.arange(self.data.shape[1], dtype=torch.float64) * self.Ts


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def load_bottle(data_dir: str | Path, *, verify: bool = True) -> tuple[Throws, Throws]:
    """Load the 21 training and 9 test throws from ``<data_dir>/bottle/``.

    Parameters
    ----------
    data_dir : path
        The data directory (``bottle/`` below it holds the two ``.mat`` files).
    verify : bool
        Check each file's SHA-256 against the published files (default).

    Returns
    -------
    (train, test) : tuple of Throws

    Raises
    ------
    DataError
        A file is missing (the message says where the files come from and
        where to put them), fails its checksum, or has the wrong shape.
    """
    from scipy.io import loadmat

    folder = Path(data_dir) / "bottle"
    missing = [name for name in BOTTLE_FILES if not (folder / name).is_file()]
    if missing:
        raise DataError(
            f"missing {', '.join(missing)} in {folder}. These are the real throws of Sec. 5.1, published "
            "with the paper authors' code (Feedback_NN_irregular_object, Dataset_construction/); they are not "
            f"redistributed here. Copy both .mat files into {folder} or pass another data directory.")
    out = []
    for name, (var, shape, digest) in BOTTLE_FILES.items():
        path = folder / name
        if verify and _sha256(path) != digest:
            raise DataError(f"{path} fails its SHA-256 check: it is not the published file (corrupt or changed)")
        try:
            arr = loadmat(path)[var]
        except Exception as exc:  # scipy raises several types for damaged files
            raise DataError(f"{path} cannot be read as a MATLAB file holding {var!r}: {exc}") from exc
        if arr.shape != shape or not np.isfinite(arr).all():
            raise DataError(f"{path}: expected a finite array of shape {shape}, got {arr.shape}")
        out.append(Throws(torch.from_numpy(np.ascontiguousarray(arr, dtype=np.float64))))
    return out[0], out[1]


def synthetic_throws(n_throws: int, n_samples: int, *, k: tuple[float, float, float] = (-0.05, -0.05, -0.03),
                     g: float = 9.81, seed: int = 0, Ts: float = TS) -> Throws:
    """Throws of a quadratic-drag point mass, a stand-in for the real data (tests, smoke profile).

    Initial positions near the real ones, velocities of 3-5 m/s thrown up and
    forward; integrated accurately by :class:`~fnnlib.systems.projectile.ThrownObject`.
    """
    from fnnlib.systems.projectile import ThrownObject

    gen = torch.Generator().manual_seed(int(seed))
    p0 = torch.tensor([-1.2, -1.3, 1.5], dtype=torch.float64) + 0.3 * torch.randn(n_throws, 3, generator=gen,
                                                                                  dtype=torch.float64)
    v0 = torch.tensor([2.5, 2.8, 3.8], dtype=torch.float64) + 0.4 * torch.randn(n_throws, 3, generator=gen,
                                                                                dtype=torch.float64)
    obj = ThrownObject(k=k, g=g)
    t = torch.arange(int(n_samples), dtype=torch.float64) * Ts
    x = obj.simulate(torch.cat([p0, v0], dim=-1), t)  # (n, T, 6)
    acc = obj.rate(x)[..., 3:]
    return Throws(torch.cat([acc, x[..., :3], x[..., 3:]], dim=-1), Ts)


#: where the throws come from: the authors' recorded throws, or :func:`synthetic_throws`
THROW_SOURCES = ("real", "synthetic")


def bottle_throws(data: str, *, data_dir: str | Path, synthetic_sizes: tuple[int, int, int] | list[int],
                  seed: int) -> tuple[Throws, Throws]:
    """The training and test throws of Sec. 5.1: the real ones, or synthetic ones drawn like them.

    ``data`` is one of :data:`THROW_SOURCES`. ``"real"`` reads ``data_dir`` (:func:`load_bottle`, SHA-256
    and shapes checked before any work); ``"synthetic"`` draws ``synthetic_sizes`` = (training throws, test
    throws, samples per throw) with :func:`synthetic_throws`, the training throws with ``seed`` and the test
    throws with ``seed + 1``.
    """
    if data not in THROW_SOURCES:
        raise ValueError(f"data must be one of {THROW_SOURCES}, got {data!r}")
    if data == "real":
        return load_bottle(data_dir)
    n_tr, n_te, n_s = synthetic_sizes
    return synthetic_throws(n_tr, n_s, seed=seed), synthetic_throws(n_te, n_s, seed=seed + 1)

