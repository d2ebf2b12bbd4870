"""The groups of settings the spiral notebooks (Sec. 3-4) share, each written once: a notebook's settings class
derives from the groups it uses. Shared paper values come from :mod:`fnnlib.paper.spiral_presets`."""

from __future__ import annotations

from dataclasses import dataclass

from fnnbook.tasks._base import TaskSettings, setting
from fnnbook.tasks._checks import ACT, GAIN, GAINS, GRID, N1, N2, NONNEG, OPTIMIZER, POS, SPIRAL3, WIDTHS, X0, need
from fnnlib.paper import spiral_presets as SP

#: Alg. 1's randomized spirals: ``[start, step, stop]`` of ``(omega, eta, eps)``, the neural feedback's training
#: cases (the Kalman baseline of S11 tunes its disturbance noise on spirals from the same range)
DR_RANGES = {"dr_omega_range": (0.8, 0.12, 3.08), "dr_eta_range": (0.04, 0.005, 0.135),
             "dr_eps_range": (-24.0, 2.4, 21.6)}


@dataclass(frozen=True, kw_only=True)
class SpiralTrajectory(TaskSettings):
    """The spiral data of Eq. (26): samples per trajectory, sampling time (s), initial state."""

    n_samples: int = setting(SP.SPIRAL_SAMPLES, N2)
    Ts: float = setting(SP.SPIRAL_TS, POS)
    x0: list[float] = setting(SP.SPIRAL_X0, X0)


@dataclass(frozen=True, kw_only=True)
class SpiralFeedback(TaskSettings):
    """The linear feedback of Eqs. (7)-(8): gain ``L``, its decay ``beta`` (Eq. (11)), horizon ``N``."""

    L: float = setting(SP.PAPER_SPIRAL_L, GAIN)
    beta: float = setting(SP.PAPER_SPIRAL_BETA, NONNEG)
    N: int = setting(SP.PAPER_SPIRAL_N, N1)


@dataclass(frozen=True, kw_only=True)
class MeasurementNoise(TaskSettings):
    """The measurement-noise std at which the noise claims are judged."""

    noise_std: float = setting(SP.SPIRAL_NOISE_STD, POS)


@dataclass(frozen=True, kw_only=True)
class ResidualGrid(TaskSettings):
    """App. A.7's grid of changes of ``(omega, eta, eps)`` around ``residual_base``: ``[start, step, stop]``."""

    residual_base: list[float] = setting(SP.SPIRAL_NOMINAL, SPIRAL3)
    domega_range: list[float] = setting(SP.RESIDUAL_GRID["domega_range"], GRID)
    deta_range: list[float] = setting(SP.RESIDUAL_GRID["deta_range"], GRID)
    deps_range: list[float] = setting(SP.RESIDUAL_GRID["deps_range"], GRID)


@dataclass(frozen=True, kw_only=True)
class NoiseDraws(TaskSettings):
    """Noise realisations per point of a noisy sweep."""

    noise_draws: int = setting(3, N1)


@dataclass(frozen=True, kw_only=True)
class GainSweep(TaskSettings):
    """Theorem 1's gain sweep (App. A.2): the gains, the transient's length in time constants ``1 / lambda_m(L)``,
    and the least ratio of Theorem 1's bound to the measured limit that counts as conservative."""

    L_sweep: list[float] = setting([5.0, 10.0, 20.0, 40.0, 80.0], GAINS)
    transient_time_constants: float = setting(5.0, POS)
    conservative_ratio: float = setting(2.0, POS)


@dataclass(frozen=True, kw_only=True)
class SwitchTest(TaskSettings):
    """The spiral switched at ``t_switch`` (s) from ``before`` to ``after`` (Sec. 3.4), judged over windows of
    ``steady_window`` s before the switch and at the run's end."""

    t_switch: float = setting(7.0, POS)
    before: list[float] = setting(SP.SPIRAL_TEST, SPIRAL3)
    after: list[float] = setting([1.0, 0.12, 5.0], SPIRAL3)
    steady_window: float = setting(1.0, POS)

    def check_switch(self, n_samples: int, Ts: float) -> None:
        """The switch leaves a steady window on both sides within the run of ``n_samples`` at ``Ts``."""
        end, w = (n_samples - 1) * Ts, self.steady_window
        need(w < self.t_switch < end - w, f"need steady_window < t_switch < the run's end {end:g} s - steady_window, "
                                          f"got t_switch={self.t_switch}, steady_window={w}")


@dataclass(frozen=True, kw_only=True)
class DomainRandomization(TaskSettings):
    """Alg. 1's randomized spirals: ``[start, step, stop]`` of ``(omega, eta, eps)``, their samples and step (s)."""

    dr_omega_range: list[float] = setting(DR_RANGES["dr_omega_range"], GRID)
    dr_eta_range: list[float] = setting(DR_RANGES["dr_eta_range"], GRID)
    dr_eps_range: list[float] = setting(DR_RANGES["dr_eps_range"], GRID)
    dr_n_samples: int = setting(1000, N2)
    dr_Ts: float = setting(0.02, POS)


@dataclass(frozen=True, kw_only=True)
class FeedbackTraining(TaskSettings):
    """Alg. 1's training of the neural feedback: iterations, learning rate, optimizer, and how many iterations a
    batch of randomized spirals is kept."""

    fb_iterations: int = setting(2000, N1)
    fb_lr: float = setting(0.01, POS)
    fb_optimizer: str = setting("rmsprop", OPTIMIZER)
    refresh_every: int = setting(10, N1)


@dataclass(frozen=True, kw_only=True)
class FeedbackNetwork(TaskSettings):
    """The neural feedback ``h_neural`` (App. A.3.3): hidden widths, activation, batch size of its training."""

    fb_hidden: list[int] = setting(SP.PAPER_SPIRAL_HIDDEN, WIDTHS)
    fb_activation: str = setting(SP.SPIRAL_ACTIVATION, ACT)
    fb_batch_size: int = setting(100, N1)


@dataclass(frozen=True, kw_only=True)
class FeedbackRules(TaskSettings):
    """The thresholds of the rules D2-D3 (``fnnbook.rules.sec4``) and the held-out spiral: the signs that flip
    the test spiral and its least distance from the training range."""

    d2_factor: float = setting(1.5, POS)
    d3_ratio: float = setting(0.5, POS)
    d3_flat: float = setting(0.1, POS)
    heldout_flip: list[float] = setting([1.0, -1.0, 1.0], SPIRAL3)
    heldout_min_distance: float = setting(3.0, POS)


@dataclass(frozen=True, kw_only=True)
class D1Rule(TaskSettings):
    """The factor of the rule D1 (``fnnbook.rules.sec4``)."""

    d1_factor: float = setting(1.5, POS)
