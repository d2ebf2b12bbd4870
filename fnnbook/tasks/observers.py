"""The settings of ``notebooks/04_observers``: observers side by side (S11)."""

from __future__ import annotations

from dataclasses import dataclass

from fnnbook.tasks._base import setting
from fnnbook.tasks._checks import N0, N1, N2, NONNEG, SEED, SPIRAL3, gain, horizon, need, vec
from fnnbook.tasks._spiral import DR_RANGES, MeasurementNoise, SpiralFeedback, SpiralTrajectory
from fnnlib.paper import spiral_presets as SP

__all__ = ["ObserversSettings"]


@dataclass(frozen=True, kw_only=True)
class ObserversSettings(MeasurementNoise, SpiralFeedback, SpiralTrajectory, notebook="observers"):
    """The linear feedback beside a Luenberger observer (its discrete poles) and an augmented Kalman filter,
    whose disturbance noise ``q_d`` is tuned on ``kf_tuning_cases`` spirals drawn between ``kf_tuning_low`` and
    ``kf_tuning_high`` (Alg. 1's training range, never the test spiral); errors after ``settle`` samples."""

    seed: int = setting(0, SEED)
    test: list[float] = setting(SP.SPIRAL_TEST, SPIRAL3)
    settle: int = setting(50, N0)
    luenberger_poles: list[float] = setting([0.5, 0.5, 0.8, 0.8], vec(4))
    kf_q_x: float = setting(SP.KALMAN_SETTINGS["kf_q_x"], NONNEG)
    kf_tuning_low: list[float] = setting([r[0] for r in DR_RANGES.values()], SPIRAL3)  # Alg. 1's range
    kf_tuning_high: list[float] = setting([r[2] for r in DR_RANGES.values()], SPIRAL3)
    kf_tuning_cases: int = setting(20, N2)
    kf_p0_d: float = setting(SP.KALMAN_SETTINGS["kf_p0_d"], NONNEG)
    repeats: int = setting(3, N1)

    def check_relations(self) -> None:
        """A stable gain (Theorem 1, Eq. (25); Eq. (11) over ``N``), ``N`` and ``settle`` below ``n_samples``, and
        a tuning range from low to high."""
        gain(self, 2, self.Ts, self.N)
        horizon(self)
        need(self.settle < self.n_samples, f"settle must be < n_samples = {self.n_samples}, got {self.settle}")
        need(all(lo <= hi for lo, hi in zip(self.kf_tuning_low, self.kf_tuning_high)),
             f"kf_tuning_low must be <= kf_tuning_high, got {self.kf_tuning_low} and {self.kf_tuning_high}")
