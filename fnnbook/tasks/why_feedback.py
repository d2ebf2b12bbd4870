"""The settings of ``notebooks/14_why_feedback``: the feedback-training grid and the authors' networks (Sec. 4)."""

from __future__ import annotations

from dataclasses import dataclass

from fnnbook.tasks._base import setting
from fnnbook.tasks._checks import N1, SPIRAL3, SWEEP0, choice, horizon
from fnnbook.tasks._spiral import (D1Rule, DomainRandomization, FeedbackRules, FeedbackTraining, ResidualGrid,
                                   SpiralTrajectory)
from fnnlib.paper import spiral_presets as SP
from fnnlib.release import SPIRAL_FEEDBACK_NAMES, SPIRAL_ODE_NAMES

__all__ = ["WhyFeedbackSettings"]


@dataclass(frozen=True, kw_only=True)
class WhyFeedbackSettings(D1Rule, FeedbackRules, FeedbackTraining, ResidualGrid, DomainRandomization,
                          SpiralTrajectory, notebook="why_feedback"):
    """The rules D1-D4 over the why grid's points, the decay rates ``d4_beta`` of D4, and the authors' released
    networks (file names in their release) judged by the same rules."""

    nominal: list[float] = setting(SP.SPIRAL_NOMINAL, SPIRAL3)
    N: int = setting(SP.PAPER_SPIRAL_N, N1)
    d4_beta: list[float] = setting([0.0, 0.02, 0.1], SWEEP0)
    authors_ode: str = setting("Neural_ODE_ite400_loss0.2.pt", choice(*SPIRAL_ODE_NAMES))
    authors_dr_ode: str = setting("Neural_ODE_domran.pt", choice(*SPIRAL_ODE_NAMES))
    authors_feedback: str = setting("FeedbackNN_ite477_loss0.494530_conver.pt", choice(*SPIRAL_FEEDBACK_NAMES))

    def check_relations(self) -> None:
        """``N < n_samples``."""
        horizon(self)
