"""The settings of ``notebooks/20_why_tanks``: the rules of B4-B6 over the gains, first estimates, overflow window
and the baseline's start."""

from __future__ import annotations

from dataclasses import dataclass

from fnnbook.tasks._base import TaskSettings, setting
from fnnbook.tasks._checks import GRID0, need, some, vec, why_grid

__all__ = ["WhyTanksSettings"]


@dataclass(frozen=True, kw_only=True)
class WhyTanksSettings(TaskSettings, notebook="why_tanks"):
    """The why grid's axes: gains and decay rates, the windows judged, the first estimates of the hidden level,
    and the published baseline's starts and horizons (B5)."""

    L_grid: list[float] = setting([0.005, 0.01, 0.02, 0.05], GRID0)
    beta_grid: list[float] = setting([0.0, 0.1, 0.5], GRID0)
    windows: list[str] = setting(["all", "outside_overflow"], some("all", "outside_overflow"))
    first_estimates: list[str] = setting(["first_level", "least_squares"], some("first_level", "least_squares"))
    b5_starts: list[str] = setting(["free", "encoder"], some("free", "encoder"))
    b5_horizons: list[float] = setting([25, 100], vec(minimum=1.0))

    def check_relations(self) -> None:
        """Two values per axis at least, gains > 0, whole horizons, and the chapter's own point on each axis."""
        why_grid(self, "L_grid", "beta_grid", "windows", "first_estimates", "b5_starts", "b5_horizons")
        need(min(self.L_grid) > 0, f"L_grid must list gains > 0 (L = 0 is the open loop, judged anyway), "
                                   f"got {self.L_grid}")
        need(all(float(h).is_integer() for h in self.b5_horizons),
             f"b5_horizons must list whole samples, got {self.b5_horizons}")
        need("all" in self.windows and "first_level" in self.first_estimates,
             "windows must hold 'all' and first_estimates 'first_level' (the chapter's own point, checked against "
             "its numbers)")
