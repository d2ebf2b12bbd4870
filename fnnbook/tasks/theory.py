"""The settings of ``notebooks/02_theory``: convergence of the linear feedback, Theorem 1 and App. A.2."""

from __future__ import annotations

from dataclasses import dataclass

from fnnbook.tasks._base import setting
from fnnbook.tasks._checks import GAIN, POS, SEED, SPIRAL3, SWEEP0
from fnnbook.tasks._spiral import GainSweep, SpiralTrajectory
from fnnlib import checks as C
from fnnlib.paper import spiral_presets as SP

__all__ = ["TheorySettings"]


@dataclass(frozen=True, kw_only=True)
class TheorySettings(GainSweep, SpiralTrajectory, notebook="theory"):
    """Theorem 1's bounds on the test spiral at the gain ``L`` and over the gain sweep, and the discrete-time
    stability limit of Eq. (25) over ``discrete_gains`` (a run diverges when its error grows past
    ``growth_threshold``, at the rate Eq. (25) predicts within ``rate_tolerance``)."""

    seed: int = setting(0, SEED)
    test: list[float] = setting(SP.SPIRAL_TEST, SPIRAL3)
    L: float = setting(SP.PAPER_SPIRAL_L, GAIN)
    discrete_gains: list[float] = setting([0.0, 5.0, 10.0, 20.0, 50.0, 100.0, 150.0, 180.0, 190.0, 195.0, 198.0,
                                           199.0, 199.5, 200.0, 201.0, 202.0, 205.0, 210.0, 220.0, 250.0], SWEEP0)
    growth_threshold: float = setting(10.0, POS)
    rate_tolerance: float = setting(0.005, POS)

    def check_relations(self) -> None:
        """``L`` and every gain of the sweep stable at ``Ts`` (Theorem 1, Eq. (25))."""
        C.stable_gain("L", self.L, n=2, Ts=self.Ts)
        for g in self.L_sweep:
            C.stable_gain("L_sweep", g, n=2, Ts=self.Ts)
