"""The settings of ``notebooks/11_quick_start``: your own system, partly measured, with gaps."""

from __future__ import annotations

from dataclasses import dataclass

from fnnbook.tasks._base import TaskSettings, setting
from fnnbook.tasks._checks import N1, N2, POS, fraction, need
from fnnlib import checks as C

__all__ = ["QuickStartSettings"]


@dataclass(frozen=True, kw_only=True)
class QuickStartSettings(TaskSettings, notebook="quick_start"):
    """A record of ``T`` samples at ``Ts`` with measurement noise and a share ``drop`` of samples lost, a horizon
    ``N``, and the steps of the training and of the gains' tuning."""

    T: int = setting(300, N2)
    Ts: float = setting(0.1, POS)
    N: int = setting(10, N1)
    noise_std: float = setting(0.02, POS)
    drop: float = setting(0.2, fraction)
    train_iterations: int = setting(200, N1)
    tune_iterations: int = setting(30, N1)

    def check_relations(self) -> None:
        """``N < T``, and a record of at least one training segment: 20 samples to estimate from, 40 predicted
        (``OutputRecipe``'s defaults)."""
        C.horizon("N", self.N, below=self.T, below_name="T")
        need(self.T >= 60, f"T = {self.T} is below the 60 samples of one training segment (20 + 40)")
