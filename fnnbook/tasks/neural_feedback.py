"""The settings of ``notebooks/05_neural_feedback``: neural feedback by domain randomization (Sec. 4, Alg. 1)."""

from __future__ import annotations

from dataclasses import dataclass

from fnnbook.tasks._base import setting
from fnnbook.tasks._checks import SEED, SPIRAL3, gain, horizon
from fnnbook.tasks._spiral import (D1Rule, DomainRandomization, FeedbackNetwork, FeedbackRules, FeedbackTraining,
                                   ResidualGrid, SpiralFeedback, SpiralTrajectory)
from fnnlib.paper import spiral_presets as SP

__all__ = ["NeuralFeedbackSettings"]


@dataclass(frozen=True, kw_only=True)
class NeuralFeedbackSettings(D1Rule, FeedbackRules, ResidualGrid, SpiralFeedback, FeedbackTraining, FeedbackNetwork,
                             DomainRandomization, SpiralTrajectory, notebook="neural_feedback"):
    """The neural feedback trained on randomized spirals (Alg. 1) beside the linear one, judged over the
    residual grid of App. A.7 and on held-out spirals (D1-D4)."""

    seed: int = setting(0, SEED)
    nominal: list[float] = setting(SP.SPIRAL_NOMINAL, SPIRAL3)

    def check_relations(self) -> None:
        """A stable gain (Theorem 1, Eq. (25); Eq. (11) over ``N``) and ``N < n_samples``."""
        gain(self, 2, self.Ts, self.N)
        horizon(self)
