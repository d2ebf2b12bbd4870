"""The settings of ``notebooks/16_why_beyond``: the tuning objective (B1) and the claims without a seed spread (B2)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

from fnnbook.tasks._base import TaskSettings, setting
from fnnbook.tasks._checks import N1, need, some, why_grid
from fnnlib import checks as C

__all__ = ["WhyBeyondSettings"]


@dataclass(frozen=True, kw_only=True)
class WhyBeyondSettings(TaskSettings, notebook="why_beyond"):
    """The tuning objectives compared (B1; the multi-step one over ``multi_step_N`` steps) and the least numbers
    of seeds a claim's spread is read at (B2)."""

    objectives: list[str] = setting(["one_step", "multi_step", "judged"], some("one_step", "multi_step", "judged"))
    multi_step_N: int = setting(50, N1)
    min_seeds_grid: list[int] = setting([2, 3, 5], partial(C.number_list, minimum=2.0, distinct=True))

    def check_relations(self) -> None:
        """Two values per axis at least, the objective ``tuned_gains`` tunes on among them, and whole numbers of
        seeds."""
        why_grid(self, "objectives", "min_seeds_grid")
        need("judged" in self.objectives,
             f"objectives must hold 'judged', the objective tuned_gains tunes on (got {self.objectives})")
        need(all(float(k).is_integer() for k in self.min_seeds_grid),
             f"min_seeds_grid must list whole numbers of seeds, got {self.min_seeds_grid}")
