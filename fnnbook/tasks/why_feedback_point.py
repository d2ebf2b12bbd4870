"""The settings of ``notebooks/13_why_feedback_point``: the neural feedback retrained with one setting changed."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from fnnbook.tasks._base import setting
from fnnbook.tasks._checks import N1, N2, OPTIMIZER, POS, SPIRAL3, changes, horizon, need
from fnnbook.tasks._spiral import (DomainRandomization, FeedbackNetwork, FeedbackRules, FeedbackTraining,
                                   ResidualGrid, SpiralTrajectory)
from fnnlib.paper import spiral_presets as SP

__all__ = ["WHY_FEEDBACK_CHANGES", "WhyFeedbackPointSettings"]

#: the one-factor changes a why_feedback_point may make to the paper profile's feedback training
WHY_FEEDBACK_CHANGES = ("optimizer", "lr_times", "iterations_times", "refresh_every")


@dataclass(frozen=True, kw_only=True)
class WhyFeedbackPointSettings(FeedbackRules, ResidualGrid, FeedbackTraining, FeedbackNetwork, DomainRandomization,
                               SpiralTrajectory, notebook="why_feedback_point"):
    """One point of the why grid of D2-D4: Alg. 1's training with ``change`` applied (keys among
    :data:`WHY_FEEDBACK_CHANGES`), over ``n_seeds`` seeds."""

    change: dict[str, Any] = setting({"optimizer": "adam"}, changes)
    n_seeds: int = setting(5, N2)
    nominal: list[float] = setting(SP.SPIRAL_NOMINAL, SPIRAL3)
    N: int = setting(SP.PAPER_SPIRAL_N, N1)

    def check_relations(self) -> None:
        """The change's keys and values, and ``N < n_samples``."""
        change = self.change
        need(set(change) <= set(WHY_FEEDBACK_CHANGES),
             f"change must be a mapping with keys among {', '.join(WHY_FEEDBACK_CHANGES)}, got {change!r}")
        OPTIMIZER("change.optimizer", change.get("optimizer", "adam"))
        for key in ("lr_times", "iterations_times"):
            POS(f"change.{key}", change.get(key, 1.0))
        N1("change.refresh_every", change.get("refresh_every", 1))
        horizon(self)
