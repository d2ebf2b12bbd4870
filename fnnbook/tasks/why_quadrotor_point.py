"""The settings of ``notebooks/17_why_quadrotor_point``: the flight test at one thrust bound, the adaptive gains
swept (Q3-Q5)."""

from __future__ import annotations

from dataclasses import dataclass

from fnnbook.tasks._base import TaskSettings, setting
from fnnbook.tasks._checks import POS, SWEEP0, need

__all__ = ["WhyQuadrotorPointSettings"]


@dataclass(frozen=True, kw_only=True)
class WhyQuadrotorPointSettings(TaskSettings, notebook="why_quadrotor_point"):
    """One thrust bound ``u_max``; the adaptive gains ``Gamma`` (Eq. (30)) and AdapNN's validation grid swept;
    the thrust bounds the authors' networks fly at."""

    u_max: float = setting(6.0, POS)
    Gamma_grid: list[float] = setting([2.0, 8.0, 32.0], SWEEP0)
    Gamma_adapnn_grid: list[float] = setting([0.16, 0.64, 2.56], SWEEP0)
    authors_u_max: list[float] = setting([6.0], SWEEP0)

    def check_relations(self) -> None:
        """The adaptive gains of the grid > 0 (the flight test's own gains must be among them: checked against
        its run record in the notebook)."""
        for name in ("Gamma_grid", "Gamma_adapnn_grid"):
            grid = getattr(self, name)
            need(len(grid) >= 2 and min(grid) > 0, f"{name} must list at least 2 gains > 0, got {grid}")
