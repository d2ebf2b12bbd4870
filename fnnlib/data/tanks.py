r"""The cascaded tanks benchmark: its data file, a synthetic stand-in, and the published results beside it.

The benchmark (M. Schoukens, P. Mattsson, T. Wigren, J.-P. Noël, "Cascaded tanks benchmark combining soft
and hard nonlinearities", Workshop on Nonlinear System Identification Benchmarks, 2016; data on
nonlinearbenchmark.org and 4TU.ResearchData, doi:10.4121/12960104) is a water level rig: a pump (input ``u``,
volts) fills an upper tank that drains into a lower one, whose level alone is measured (output ``y``,
volts, saturating at 10 V when the tank overflows). One estimation and one validation record of 1024
samples at Ts = 4 s. fnnlib reads the published file from a data directory, checks its SHA-256 and shapes,
and refuses anything else; tests and the smoke profile use :func:`synthetic_tanks` instead.

The benchmark's metric is the RMSE of the *simulated* (free-run) output on the validation record; the
initial state of each record is unknown and must be estimated (:func:`simulation_rmse` scores after the
samples used for that).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import Tensor

from fnnlib.data.bottle import DataError, _sha256

__all__ = ["PUBLISHED_RESULTS", "TANKS_ARCHIVE_MEMBER", "TANKS_FILE", "TANKS_SHA256", "TANKS_SOURCES", "TS",
           "PublishedResult", "TanksRecords", "load_tanks", "simulation_rmse", "synthetic_tanks", "tanks_records"]

TANKS_FILE = "dataBenchmark.mat"
"""The data file, read from ``<data_dir>/cascaded_tanks/``."""
TANKS_SHA256 = "cb2f88d4388be4d3f2a24c6402fba804976aac5f2e1f26cda59ea0a38d016eab"
"""SHA-256 of the published ``dataBenchmark.mat`` (the member of the official archive)."""
TANKS_ARCHIVE_MEMBER = "CascadedTanksFiles/dataBenchmark.mat"
"""Where the file lies in the official archive ``CascadedTanksFiles.zip``."""
TANKS_SOURCES: dict[str, str] = {
    "4TU.ResearchData": "https://data.4tu.nl/file/d4810b78-6cdd-48fe-8950-9bd601e5f47f/"
                        "3b697e42-01a4-4979-a370-813a456c36f5",
    "nonlinearbenchmark.org": "http://www.nonlinearbenchmark.org/FILES/BENCHMARKS/CASCADEDTANKS/CascadedTanksFiles.zip",
}
"""Where the archive ``CascadedTanksFiles.zip`` is published, tried in this order (the member's SHA-256 is
checked, whatever serves it)."""
TS = 4.0
"""Sample step, s."""
SATURATION = 10.0
"""The measured level saturates here (volts) when the lower tank overflows."""
_VARS = ("uEst", "yEst", "uVal", "yVal")
_SAMPLES = 1024


@dataclass(frozen=True)
class TanksRecords:
    """The estimation and validation records, each (T, 1) float64, volts.

    Attributes
    ----------
    u_est, y_est : Tensor, shape (T, 1)
        Pump voltage and lower level of the estimation record (what a model may be fitted and tuned on).
    u_val, y_val : Tensor, shape (T, 1)
        The validation record (what a model is judged on, never tuned on).
    Ts : float
        Sample step, s.
    source : str
        ``"real"`` (the published file) or ``"synthetic"``.
    x_est, x_val : Tensor, shape (T, 2), optional
        The true states (upper, lower level) of a synthetic record; None for the real data.
    """

    u_est: Tensor
    y_est: Tensor
    u_val: Tensor
    y_val: Tensor
    Ts: float = TS
    source: str = "real"
    x_est: Tensor | None = None
    x_val: Tensor | None = None

    @property
    def t(self) -> Tensor:
        """Sample times of either record, (T,), s."""
        return torch.arange(self.y_est.shape[0], dtype=torch.float64) * self.Ts

    def saturated(self, which: str = "val") -> Tensor:
        """Where the measured level sits at the sensor's limit (10 V), (T,) bool; ``which`` in ``est``, ``val``."""
        y = {"est": self.y_est, "val": self.y_val}[which]
        return y[:, 0] >= SATURATION - 1e-9


def load_tanks(data_dir: str | Path, *, verify: bool = True) -> TanksRecords:
    """Load the benchmark's records from ``<data_dir>/cascaded_tanks/dataBenchmark.mat``.

    Parameters
    ----------
    data_dir : path
        The data directory.
    verify : bool
        Check the file's SHA-256 against the published file (default).

    Returns
    -------
    TanksRecords

    Raises
    ------
    DataError
        The file is missing (the message says where it comes from), fails its checksum, or does not hold
        four finite (1024, 1) records and Ts = 4.
    """
    from scipy.io import loadmat  # noqa: PLC0415

    path = Path(data_dir) / "cascaded_tanks" / TANKS_FILE
    if not path.is_file():
        raise DataError(f"missing {path}. It is the cascaded tanks benchmark's data file (member "
                        f"{TANKS_ARCHIVE_MEMBER} of CascadedTanksFiles.zip on nonlinearbenchmark.org / "
                        "4TU.ResearchData); get it with `fnn-pipeline data fetch --tanks` or pass another data directory.")
    if verify and _sha256(path) != TANKS_SHA256:
        raise DataError(f"{path} fails its SHA-256 check: it is not the published file (corrupt or changed)")
    try:
        mat = loadmat(path)
        arrays = [np.asarray(mat[v], dtype=np.float64) for v in _VARS]
        Ts = float(np.asarray(mat["Ts"]).squeeze())
    except Exception as exc:  # scipy raises several types for damaged files
        raise DataError(f"{path} cannot be read as the benchmark's MATLAB file ({', '.join(_VARS)}, Ts): {exc}") from exc
    for name, a in zip(_VARS, arrays):
        if a.shape != (_SAMPLES, 1) or not np.isfinite(a).all():
            raise DataError(f"{path}: {name} must be a finite ({_SAMPLES}, 1) array, got {a.shape}")
    if Ts != TS:
        raise DataError(f"{path}: Ts must be {TS} s, got {Ts}")
    u_est, y_est, u_val, y_val = (torch.from_numpy(np.ascontiguousarray(a)) for a in arrays)
    return TanksRecords(u_est, y_est, u_val, y_val, Ts, "real")


def _multisine(T: int, Ts: float, gen: torch.Generator, *, f_max: float = 0.0125, low: float = 0.5,
               high: float = 6.5) -> Tensor:
    """A random-phase multisine of equal amplitudes at the record's harmonics up to ``f_max`` Hz, scaled to
    [low, high] volts (like the benchmark's excitation); (T, 1)."""
    k = torch.arange(1, max(2, int(f_max * T * Ts)) + 1, dtype=torch.float64)
    phase = 2 * math.pi * torch.rand(k.numel(), generator=gen, dtype=torch.float64)
    t = torch.arange(T, dtype=torch.float64)
    s = torch.cos(2 * math.pi * k[None, :] * t[:, None] / T + phase[None, :]).sum(-1)
    s = (s - s.min()) / (s.max() - s.min())
    return (low + (high - low) * s)[:, None]


def synthetic_tanks(n_samples: int = _SAMPLES, *, seed: int = 0, noise_std: float = 0.02, Ts: float = TS,
                    system: object | None = None) -> TanksRecords:
    """Records of :class:`~fnnlib.systems.tanks.CascadedTanks` shaped like the benchmark's: two records of
    ``n_samples`` (estimation, validation), each from its own multisine and its own initial levels, the
    lower level measured with Gaussian noise of ``noise_std`` volts and saturated at 10 V.

    Parameters
    ----------
    n_samples : int
        Samples per record (>= 10).
    seed : int
        Seeds the inputs, initial levels and noise.
    noise_std : float
        Sensor noise, volts (>= 0).
    Ts : float
        Sample step, s.
    system : CascadedTanks, optional
        The plant (default: its default coefficients).

    Returns
    -------
    TanksRecords
        ``source="synthetic"``, with the true states ``x_est``, ``x_val``.
    """
    from fnnlib.systems.tanks import CascadedTanks  # noqa: PLC0415

    if int(n_samples) != n_samples or n_samples < 10:
        raise ValueError(f"n_samples must be an integer >= 10, got {n_samples}")
    if not noise_std >= 0 or not math.isfinite(noise_std):
        raise ValueError(f"noise_std must be finite and >= 0, got {noise_std}")
    if not Ts > 0:
        raise ValueError(f"Ts must be > 0, got {Ts}")
    plant = CascadedTanks() if system is None else system
    gen = torch.Generator().manual_seed(int(seed))
    T = int(n_samples)
    t = torch.arange(T, dtype=torch.float64) * Ts
    u = torch.stack([_multisine(T, Ts, gen), _multisine(T, Ts, gen)])  # (2, T, 1)
    x0 = 3.0 + 3.0 * torch.rand(2, 2, generator=gen, dtype=torch.float64)
    x = plant.simulate(x0, t, u, substeps=4)  # (2, T, 2)
    y = (plant.measure(x) + noise_std * torch.randn(2, T, 1, generator=gen, dtype=torch.float64))
    y = y.clamp(max=plant.h_max)
    return TanksRecords(u[0], y[0], u[1], y[1], float(Ts), "synthetic", x[0], x[1])


#: where the records come from: the benchmark's file, or :func:`synthetic_tanks`
TANKS_DATA = ("real", "synthetic")


def tanks_records(data: str, *, data_dir: str | Path = "data", n_samples: int = _SAMPLES, seed: int = 0,
                  noise_std: float = 0.02) -> TanksRecords:
    """The benchmark's records (``data="real"``, from ``data_dir``) or synthetic ones (``"synthetic"``)."""
    if data == "real":
        return load_tanks(data_dir)
    if data == "synthetic":
        return synthetic_tanks(n_samples, seed=seed, noise_std=noise_std)
    raise ValueError(f"data must be one of {TANKS_DATA}, got {data!r}")


def simulation_rmse(y_sim: Tensor | np.ndarray, y: Tensor | np.ndarray, *, skip: int = 0) -> float:
    r"""The benchmark's metric: :math:`\sqrt{\frac{1}{T-s}\sum_{k\ge s} (\hat y_k - y_k)^2}` of a free-run
    simulation ``y_sim`` against the measured ``y``, over the samples from ``skip`` on (the first ``skip``
    samples are the ones the initial state was estimated from, and are not scored).

    Parameters
    ----------
    y_sim, y : array, shape (T,) or (T, 1)
        Simulated and measured output, volts.
    skip : int
        Samples left out at the start, 0 <= skip < T.

    Returns
    -------
    float
        RMSE in the data's units (volts).
    """
    a = np.asarray(y_sim, dtype=float).reshape(-1)
    b = np.asarray(y, dtype=float).reshape(-1)
    if a.shape != b.shape:
        raise ValueError(f"y_sim and y must have the same length, got {a.shape} and {b.shape}")
    if not 0 <= int(skip) < a.size:
        raise ValueError(f"skip must be in 0..{a.size - 1}, got {skip}")
    if not np.isfinite(a).all():
        raise ValueError("y_sim holds non-finite values (a diverged simulation)")
    return float(np.sqrt(np.mean((a[skip:] - b[skip:]) ** 2)))


@dataclass(frozen=True)
class PublishedResult:
    """One published result on the benchmark, as its source states it.

    Attributes
    ----------
    method : str
        The model and how it was fitted.
    value : float
        The validation error the source gives, volts.
    metric : str
        What the number is, in the source's own words (the benchmark's metric is the simulation RMSE).
    reference : str
        Who published the result (the original work).
    source : str
        Where we read the number (a URL), which may be a later paper's comparison table.
    protocol : str
        The protocol the source states (records used, initial state, simulation or prediction).
    """

    method: str
    value: float
    metric: str
    reference: str
    source: str
    protocol: str


_HBJ_TABLE = "https://preview.hindawi.com/journals/mpe/2021/6613425/tab2"
_HBJ = ("as tabulated in Table 2 of 'Hammerstein Box-Jenkins System Identification of the Cascaded Tanks "
        "Benchmark System', Mathematical Problems in Engineering 2021, article 6613425")
_HBJ_METRIC = ("the source's column 'MSE (validation)', which the source says compares previous studies on the "
               "validation record; the benchmark's metric is an RMSE in volts, and the source does not say which")
_HBJ_PROTOCOL = "identified on the estimation record, judged on the validation record (as the source states)"

PUBLISHED_RESULTS: tuple[PublishedResult, ...] = (
    PublishedResult("NLSS2 (nonlinear state-space model)", 0.3433, _HBJ_METRIC, f"earlier work {_HBJ}", _HBJ_TABLE,
                    _HBJ_PROTOCOL),
    PublishedResult("PNLSS-I (polynomial nonlinear state space)", 0.4498, _HBJ_METRIC, f"earlier work {_HBJ}",
                    _HBJ_TABLE, _HBJ_PROTOCOL),
    PublishedResult("Volterra model, 3rd degree, with transient removal", 0.54, _HBJ_METRIC, f"earlier work {_HBJ}",
                    _HBJ_TABLE, _HBJ_PROTOCOL),
    PublishedResult("BLA (best linear approximation)", 0.7574, _HBJ_METRIC, f"earlier work {_HBJ}", _HBJ_TABLE,
                    _HBJ_PROTOCOL),
)
"""Published results on the benchmark's validation record that we can cite, each with where we read it.
Only numbers read in a source we can point to are here; the chapter keeps them apart from ours."""
