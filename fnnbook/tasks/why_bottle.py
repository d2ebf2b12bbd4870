"""The settings of ``notebooks/15_why_bottle``: the bottle's gains ``L`` x ``beta`` and the authors' network (O1)."""

from __future__ import annotations

from dataclasses import dataclass

from fnnbook.tasks._base import TaskSettings, setting
from fnnbook.tasks._checks import SWEEP0, need, why_grid

__all__ = ["WhyBottleSettings"]


@dataclass(frozen=True, kw_only=True)
class WhyBottleSettings(TaskSettings, notebook="why_bottle"):
    """The grid of gains ``L`` (Eqs. (7)-(8)) and decay rates ``beta`` (Eq. (11)) over which O1's rule is read."""

    L_grid: list[float] = setting([2.5, 5.0, 10.0, 20.0], SWEEP0)
    beta_grid: list[float] = setting([0.005, 0.02, 0.1], SWEEP0)

    def check_relations(self) -> None:
        """Two values per axis at least, and gains > 0 (``L = 0`` is the open loop, judged anyway)."""
        why_grid(self, "L_grid", "beta_grid")
        need(min(self.L_grid) > 0, f"L_grid must list gains > 0 (L = 0 is the open loop, judged anyway), "
                                   f"got {self.L_grid}")
