"""The settings of ``notebooks/03_ablations``: ablations of the linear feedback (Sec. 3.4, App. A.7)."""

from __future__ import annotations

from dataclasses import dataclass

from fnnbook.tasks._base import setting
from fnnbook.tasks._checks import GRID, POS, SEED, SPIRAL3, SWEEP0, gain, horizon
from fnnbook.tasks._spiral import (MeasurementNoise, NoiseDraws, ResidualGrid, SpiralFeedback, SpiralTrajectory,
                                   SwitchTest)
from fnnlib import checks as C
from fnnlib.paper import spiral_presets as SP

__all__ = ["AblationsSettings"]


@dataclass(frozen=True, kw_only=True)
class AblationsSettings(SwitchTest, NoiseDraws, ResidualGrid, MeasurementNoise, SpiralFeedback, SpiralTrajectory,
                        notebook="ablations"):
    """The gain and system grids of Fig. 3 (``[start, step, stop]``), the decay grids of Fig. S9, the residual
    grid of Fig. S11 and the switched spiral of Fig. S12, with the thresholds of the rules S7-S10."""

    seed: int = setting(0, SEED)
    nominal: list[float] = setting(SP.SPIRAL_NOMINAL, SPIRAL3)
    test: list[float] = setting(SP.SPIRAL_TEST, SPIRAL3)
    gain_range: list[float] = setting([0.0, 5.0, 45.0], GRID)
    omega_range: list[float] = setting([0.8, 0.4, 4.4], GRID)
    eta_range: list[float] = setting([0.04, 0.02, 0.22], GRID)
    eps_range: list[float] = setting([-24.0, 8.0, 48.0], GRID)
    trend_fraction: float = setting(0.8, POS)
    beta_range: list[float] = setting([0.0, 0.01, 0.06], GRID)
    beta_extended: list[float] = setting([0.0, 0.02, 0.2], SWEEP0)
    band_factor: float = setting(2.0, POS)
    settle_threshold: float = setting(0.5, POS)

    def check_relations(self) -> None:
        """A gain stable at ``Ts`` (Theorem 1, Eq. (25)) and over ``N`` layers (Eq. (11)), every gain of
        ``gain_range`` stable at ``Ts``, ``N < n_samples``, and a switch with a steady window on both sides."""
        from fnnlib.paper.sweeps import colon_range  # noqa: PLC0415 (loads torch)

        gain(self, 2, self.Ts, self.N)
        for g in colon_range(*self.gain_range).tolist():
            C.stable_gain("gain_range", g, n=2, Ts=self.Ts)
        horizon(self)
        self.check_switch(self.n_samples, self.Ts)
