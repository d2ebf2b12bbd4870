"""The settings of ``notebooks/12_why_sec3``: the rules of S3, S5, S8, S9 and S10 over the settings Sec. 3 leaves
open."""

from __future__ import annotations

from dataclasses import dataclass

from fnnbook.tasks._base import setting
from fnnbook.tasks._checks import POS, SEED, SPIRAL3, WHY_AXIS, WHY_AXIS_POS, gain, horizon, need
from fnnbook.tasks._spiral import (GainSweep, MeasurementNoise, NoiseDraws, ResidualGrid, SpiralFeedback,
                                   SpiralTrajectory, SwitchTest)
from fnnlib import checks as C
from fnnlib.paper import spiral_presets as SP

__all__ = ["WhySec3Settings"]


@dataclass(frozen=True, kw_only=True)
class WhySec3Settings(SwitchTest, NoiseDraws, ResidualGrid, GainSweep, MeasurementNoise, SpiralFeedback,
                      SpiralTrajectory, notebook="why_sec3"):
    """The why grids: S3 over noise x decay, S5 over the spiral's ``(eta, eps)``, S8 over the gain, S9 over the
    decay grid's step and noise, S10 over its band and settling time."""

    seed: int = setting(0, SEED)
    test: list[float] = setting(SP.SPIRAL_TEST, SPIRAL3)
    s3_noise: list[float] = setting([0.001, 0.003, 0.01, 0.03], WHY_AXIS_POS)
    s3_beta: list[float] = setting([0.01, 0.02, 0.04, 0.06], WHY_AXIS_POS)
    s5_eps: list[float] = setting([0.0, 2.5, 5.0, 10.0], WHY_AXIS)
    s5_eta: list[float] = setting([0.05, 0.1, 0.2], WHY_AXIS_POS)
    s8_L: list[float] = setting([5.0, 10.0, 20.0, 40.0], WHY_AXIS_POS)
    s9_beta_steps: list[float] = setting([0.01, 0.005], WHY_AXIS_POS)
    s9_beta_max: float = setting(0.06, POS)
    s9_noise: list[float] = setting([0.003, 0.01, 0.03], WHY_AXIS_POS)
    s10_band: list[float] = setting([1.02, 1.05, 1.1, 1.25, 1.5, 2.0], WHY_AXIS_POS)
    s10_settle: list[float] = setting([0.1, 0.25, 0.5, 1.0], WHY_AXIS_POS)

    def check_relations(self) -> None:
        """Every gain of S8 and of the L sweep stable, every decay rate over N layers (Theorem 1, Eqs. (11),
        (25)), the S9 grid steps dividing its end, the switch as in ablations, and the S3 grid through the
        profile's point."""
        gain(self, 2, self.Ts, self.N)
        horizon(self)
        for name in ("s8_L", "L_sweep"):
            for g in getattr(self, name):
                C.stable_gain(name, g, n=2, Ts=self.Ts, N=self.N, beta=self.beta)
        for b in self.s3_beta:
            C.stable_gain("L", self.L, n=2, Ts=self.Ts, N=self.N, beta=b)
        finest = min(self.s9_beta_steps)
        for step in self.s9_beta_steps:
            k, n = step / finest, self.s9_beta_max / finest
            need(abs(k - round(k)) < 1e-9 and abs(n - round(n)) < 1e-9 and round(n) >= 2 * round(k),
                 f"s9_beta_steps must be whole multiples of the finest step that divide s9_beta_max "
                 f"({self.s9_beta_max}) into >= 3 values, got {self.s9_beta_steps}")
        self.check_switch(self.n_samples, self.Ts)
        need(self.noise_std in self.s3_noise and self.beta in self.s3_beta,
             f"the S3 grid must pass through the profile's point: noise_std = {self.noise_std} in s3_noise, "
             f"beta = {self.beta} in s3_beta")
