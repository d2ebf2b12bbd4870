"""The settings of ``notebooks/19_cascaded_tanks``: the cascaded tanks benchmark, learned from its measured level."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from fnnbook.tasks._base import TaskSettings, setting
from fnnbook.tasks._checks import (ACT, GAIN, GRID0, N0, N1, N2, NONNEG, POS, SEED, SEEDS2, WIDTHS, choice, horizons,
                                   need, some, vec)
from fnnlib import checks as C
from fnnlib.data.tanks import TANKS_FILE, TANKS_SHA256

__all__ = ["CascadedTanksSettings"]

#: samples of each of the benchmark's two records
RECORD_SAMPLES = 1024


@dataclass(frozen=True, kw_only=True)
class CascadedTanksSettings(TaskSettings, notebook="cascaded_tanks"):
    """The benchmark's records (``data = "real"``) or a synthetic stand-in, the first ``n_init`` measured samples
    a simulation starts from, the ARX baseline's orders, the neural ODE (its scaling, training horizon and
    steps) and its feedback's gains (start, hand grid), the Kalman baseline's noises, the overflow window, the
    judged horizons, and the published baseline's starts and horizon."""

    data: str = setting("real", choice("real", "synthetic"))
    synthetic_samples: int = setting(RECORD_SAMPLES, N2)
    synthetic_noise: float = setting(0.02, NONNEG)
    seed: int = setting(0, SEED)
    n_init: int = setting(5, N1)
    arx_max_order: int = setting(4, N1)
    seeds: list[int] = setting([0, 1, 2, 3, 4], SEEDS2)
    hidden: list[int] = setting([16, 16], WIDTHS)
    activation: str = setting("tanh", ACT)
    x_center: float = setting(5.0, GAIN)
    x_scale: float = setting(3.0, POS)
    u_center: float = setting(3.0, GAIN)
    u_scale: float = setting(2.0, POS)
    rate: float = setting(0.05, POS)
    observer_gain: list[float] = setting([0.02, 0.15], vec(2, 0.0))
    train_N: int = setting(25, N1)
    train_iterations: int = setting(80, N1)
    train_lr: float = setting(0.01, POS)
    L_start: float = setting(0.01, POS)
    beta_start: float = setting(0.1, NONNEG)
    horizons: list[int] = setting([1, 5, 10, 25, 50], horizons)
    hand_L_grid: list[float] = setting([0.005, 0.01, 0.02, 0.05], GRID0)
    hand_beta_grid: list[float] = setting([0.0, 0.1, 0.2], GRID0)
    kf_q: list[float] = setting([0.0001, 0.0001], vec(2, 0.0))
    kf_qd_grid: list[float] = setting([1e-08, 1e-06], GRID0)
    kf_r: float = setting(0.0004, POS)
    overflow_after: int = setting(25, N1)
    overflow_gap: int = setting(3, N0)
    series_N: int = setting(10, N1)
    baseline_starts: list[str] = setting(["free", "encoder"], some("free", "encoder"))
    baseline_horizon: int = setting(100, N1)

    def check_relations(self) -> None:
        """The horizons, the initial samples and the training horizon fit a record; ``series_N`` is a judged
        horizon; ``n_init`` covers the ARX orders."""
        samples = RECORD_SAMPLES if self.data == "real" else self.synthetic_samples
        need(max(self.horizons) + self.n_init < samples and self.train_N < samples // 2,
             f"the horizons (largest {max(self.horizons)}) after n_init = {self.n_init} samples and train_N = "
             f"{self.train_N} must fit a record of {samples} samples")
        need(self.n_init + self.baseline_horizon <= samples, f"baseline_horizon = {self.baseline_horizon} after "
             f"n_init = {self.n_init} samples must fit a record of {samples} samples")
        need(self.series_N in self.horizons, f"series_N = {self.series_N} must be one of horizons = {self.horizons}")
        need(self.arx_max_order + 1 <= self.n_init < samples // 2,
             f"n_init (the measured samples a simulation starts from) must be in {self.arx_max_order + 1}.."
             f"{samples // 2 - 1} (above arx_max_order = {self.arx_max_order}, below half a record of {samples}), "
             f"got {self.n_init}")

    def check_data(self, data_dir: Path) -> None:
        """The benchmark's file in ``data_dir / "cascaded_tanks"`` with its pinned SHA-256 (real data)."""
        if self.data == "real":
            C.data_files(data_dir / "cascaded_tanks", {TANKS_FILE: TANKS_SHA256},
                         how_to_get="Get the benchmark's file with `fnn-pipeline data fetch --tanks` "
                                    "(see data/README.md).")
