"""The settings of ``notebooks/01_spiral``: linear feedback on the spiral (Sec. 3, Fig. 4)."""

from __future__ import annotations

from dataclasses import dataclass

from fnnbook.tasks._base import setting
from fnnbook.tasks._checks import ACT, BOOL, METHOD, N1, N2, POS, SEEDS2, SPIRAL3, SWEEP0, WIDTHS, gain, need
from fnnbook.tasks._spiral import MeasurementNoise, SpiralFeedback, SpiralTrajectory
from fnnlib.paper import spiral_presets as SP
from fnnlib.training import PAPER_SPIRAL_RECIPE as RECIPE

__all__ = ["SpiralSettings"]


@dataclass(frozen=True, kw_only=True)
class SpiralSettings(MeasurementNoise, SpiralFeedback, SpiralTrajectory, notebook="spiral"):
    """The spiral's neural ODE (App. A.3.3, trained with the paper's recipe), its linear feedback (Eqs. (7)-(8),
    decay Eq. (11)), the seeds of the ensemble, the horizons up to ``N_max`` and the noise levels swept."""

    seeds: list[int] = setting([0, 1, 2, 3, 4], SEEDS2)
    nominal: list[float] = setting(SP.SPIRAL_NOMINAL, SPIRAL3)
    test: list[float] = setting(SP.SPIRAL_TEST, SPIRAL3)
    hidden: list[int] = setting(SP.PAPER_SPIRAL_HIDDEN, WIDTHS)
    activation: str = setting(SP.SPIRAL_ACTIVATION, ACT)
    iterations: int = setting(RECIPE.iterations, N1)
    batch_size: int = setting(RECIPE.batch_size, N1)
    batch_time: int = setting(RECIPE.batch_time, N2)
    lr: float = setting(RECIPE.lr, POS)
    method: str = setting(RECIPE.method, METHOD)
    adjoint: bool = setting(RECIPE.adjoint, BOOL)
    rtol: float = setting(RECIPE.rtol, POS)
    atol: float = setting(RECIPE.atol, POS)
    N_max: int = setting(100, N1)
    noise_sweep: list[float] = setting([0.0, 0.003, 0.01, 0.03, 0.1], SWEEP0)

    def check_relations(self) -> None:
        """A gain stable at ``Ts`` (Theorem 1, Eq. (25)) whose decay (Eq. (11)) holds over ``N_max`` layers,
        ``N <= N_max < n_samples``, and a noise sweep through 0 and the judged level ``noise_std`` (S3)."""
        gain(self, 2, self.Ts, self.N_max)
        need(self.N <= self.N_max < self.n_samples, f"need 1 <= N <= N_max < n_samples, got N={self.N}, "
                                                    f"N_max={self.N_max}, n_samples={self.n_samples}")
        sweep, std = self.noise_sweep, self.noise_std
        need(0.0 in sweep and std in sweep, f"noise_sweep must hold 0 and the judged level noise_std = {std}, "
                                            f"got {sweep}")
