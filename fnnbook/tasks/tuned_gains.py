"""The settings of ``notebooks/10_tuned_gains``: gains tuned from data against gains set by hand (B1)."""

from __future__ import annotations

from dataclasses import dataclass

from fnnbook.tasks._base import TaskSettings, setting
from fnnbook.tasks._checks import GRID0, N1, POS, need

__all__ = ["TunedGainsSettings"]


@dataclass(frozen=True, kw_only=True)
class TunedGainsSettings(TaskSettings, notebook="tuned_gains"):
    """Only the tuning's own settings: the data and flights come from the upstream runs (whose ``Ts`` and ``N``
    are checked there). The bottle's tuning throws, steps and rate, and hand grid; the quadrotor's tuning grid,
    validation cases and hand grid."""

    bottle_tune_throws: int = setting(1, N1)
    bottle_tune_iterations: int = setting(6, N1)
    bottle_tune_lr: float = setting(0.3, POS)
    bottle_hand_L_grid: list[float] = setting([0.8, 5.0, 31.0], GRID0)
    bottle_hand_beta_grid: list[float] = setting([0.003, 0.12], GRID0)
    quad_tune_cases: int = setting(1, N1)
    quad_L_grid: list[float] = setting([1.5, 3.0, 6.0], GRID0)
    quad_beta_grid: list[float] = setting([0.02, 0.1], GRID0)
    quad_hand_L_grid: list[float] = setting([1.5, 3.0, 6.0], GRID0)
    quad_hand_beta_grid: list[float] = setting([0.02, 0.1], GRID0)

    def check_relations(self) -> None:
        """Every gain of a grid > 0 (``sweep_gains`` refuses the rest) and B1's equal budget of evaluations."""
        for name in ("bottle_hand_L_grid", "quad_L_grid", "quad_hand_L_grid"):
            need(min(getattr(self, name)) > 0, f"{name} must list gains > 0, got {getattr(self, name)}")
        bottle_points = len(self.bottle_hand_L_grid) * len(self.bottle_hand_beta_grid)
        need(self.bottle_tune_iterations == bottle_points,
             "B1 gives the tuned and the hand gains the same budget of evaluations: bottle_tune_iterations must "
             f"equal the bottle hand grid's {bottle_points} points, got {self.bottle_tune_iterations}")
        tuned = len(self.quad_L_grid) * len(self.quad_beta_grid) * self.quad_tune_cases  # a flight per point, case
        hand = len(self.quad_hand_L_grid) * len(self.quad_hand_beta_grid)
        need(tuned == hand, f"B1 gives the tuned and the hand gains the same budget of evaluations: the quadrotor's "
                            f"tuning flies {tuned} flights (grid points x quad_tune_cases), its hand grid has {hand} "
                            "points")
