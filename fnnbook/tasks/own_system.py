"""The settings of ``notebooks/09_own_system``: your own system, with inputs, noisy measurements and tuned gains."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

from fnnbook.tasks._base import TaskSettings, setting
from fnnbook.tasks._checks import (ACT, GAIN, GRID0, N1, N2, NONNEG, POS, SEEDS2, SPIRAL3, WIDTHS, X0, gain, need,
                                   vec)
from fnnlib import checks as C
from fnnlib.paper import spiral_presets as SP
from fnnlib.feedback import GainWarning

__all__ = ["OwnSystemSettings"]


@dataclass(frozen=True, kw_only=True)
class OwnSystemSettings(TaskSettings, notebook="own_system"):
    """A damped pendulum with an input (``nominal``/``test`` its parameters), learned from ``n_train`` noisy
    samples; the feedback's gains set by hand (``L_hand``, ``beta_hand``) or tuned from data starting at
    ``L0``, ``beta0``; a Kalman baseline; and the same tuning on the noisy spiral (the ``spiral_`` settings).
    The hand sweep ``hand_L_grid`` x ``hand_beta_grid`` is B1's budget of evaluations."""

    seeds: list[int] = setting([0, 1, 2, 3, 4], SEEDS2)
    Ts: float = setting(0.02, POS)
    n_train: int = setting(500, N2)
    n_test: int = setting(500, N2)
    nominal: list[float] = setting([9.81, 0.1, 1.0, 0.0], vec(4))
    test: list[float] = setting([7.0, 0.4, 1.0, 1.5], vec(4))
    u_amp: float = setting(1.5, NONNEG)
    hidden: list[int] = setting([32, 32], WIDTHS)
    activation: str = setting("tanh", ACT)
    iterations: int = setting(300, N1)
    noise_std: float = setting(0.01, POS)
    N: int = setting(30, N1)
    L_hand: float = setting(SP.PAPER_SPIRAL_L, GAIN)
    beta_hand: float = setting(SP.PAPER_SPIRAL_BETA, NONNEG)
    L0: float = setting(5.0, GAIN)
    beta0: float = setting(0.05, NONNEG)
    tune_iterations: int = setting(36, N1)
    tune_lr: float = setting(0.1, POS)
    kf_q_x: float = setting(SP.KALMAN_SETTINGS["kf_q_x"], NONNEG)
    kf_q_d: float = setting(0.01, NONNEG)
    kf_p0_d: float = setting(SP.KALMAN_SETTINGS["kf_p0_d"], NONNEG)
    spiral_n_samples: int = setting(SP.SPIRAL_SAMPLES, N2)
    spiral_Ts: float = setting(SP.SPIRAL_TS, POS)
    spiral_test: list[float] = setting(SP.SPIRAL_TEST, SPIRAL3)
    spiral_x0: list[float] = setting(SP.SPIRAL_X0, X0)
    spiral_tune_x0: list[float] = setting([0.0, 9.0], X0)
    spiral_tune_samples: int = setting(400, N2)
    spiral_N: int = setting(SP.PAPER_SPIRAL_N, N1)
    spiral_noise_std: float = setting(SP.SPIRAL_NOISE_STD, POS)
    spiral_L: float = setting(SP.PAPER_SPIRAL_L, GAIN)
    spiral_beta: float = setting(SP.PAPER_SPIRAL_BETA, NONNEG)
    spiral_tune_iterations: int = setting(36, N1)
    hand_L_grid: list[float] = setting([0.3, 1.0, 2.0, 4.0, 8.0, 16.0], GRID0)
    hand_beta_grid: list[float] = setting([0.0, 0.02, 0.05, 0.1, 0.2, 0.5], GRID0)

    def check_relations(self) -> None:
        """Horizons within the data; every gain stable (Theorem 1, Eq. (25); Eq. (11) over the horizon) on both
        settings, the hand sweep's too; and B1's equal budget: as many tuning steps as hand grid points."""
        C.horizon("N", self.N, below=self.n_test, below_name="n_test")
        need(self.spiral_N < self.spiral_tune_samples <= self.spiral_n_samples,
             "need 1 <= spiral_N < spiral_tune_samples <= spiral_n_samples, got "
             f"{self.spiral_N}, {self.spiral_tune_samples}, {self.spiral_n_samples}")
        C.stable_gain("L0", self.L0, n=2, Ts=self.Ts)
        with warnings.catch_warnings():  # the hand-picked gain amplifies noise on purpose: the chapter shows it
            warnings.simplefilter("ignore", GainWarning)
            gain(self, 2, self.Ts, self.N, L="L_hand", beta="beta_hand")
            gain(self, 2, self.spiral_Ts, self.spiral_N, L="spiral_L", beta="spiral_beta")
            for L in self.hand_L_grid:  # every pair of the hand sweep, on both settings
                for beta in self.hand_beta_grid:
                    for Ts, N in ((self.Ts, self.N), (self.spiral_Ts, self.spiral_N)):
                        C.stable_gain("hand_L_grid", L, n=2, Ts=Ts, N=N, beta=beta)
        points = len(self.hand_L_grid) * len(self.hand_beta_grid)
        need(self.tune_iterations == self.spiral_tune_iterations == points,
             "B1 gives the tuned and the hand gains the same budget of evaluations: tune_iterations and "
             f"spiral_tune_iterations must equal the hand grid's {points} points, got {self.tune_iterations}, "
             f"{self.spiral_tune_iterations}")
