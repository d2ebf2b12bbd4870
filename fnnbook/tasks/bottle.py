"""The settings of ``notebooks/06_bottle``: trajectory prediction of a thrown irregular bottle (Sec. 5.1)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from fnnbook.tasks._base import TaskSettings, setting
from fnnbook.tasks._checks import (ACT, BOOL, GAIN, METHOD, N1, N2, NONNEG, POS, SEEDS2, WIDTHS, choice, gain, need,
                                   synthetic_sizes)
from fnnlib import checks as C
from fnnlib.data.bottle import BOTTLE_FILES, TS as BOTTLE_TS
from fnnlib.training import PAPER_BOTTLE_RECIPE as RECIPE

__all__ = ["BottleSettings"]


@dataclass(frozen=True, kw_only=True)
class BottleSettings(TaskSettings, notebook="bottle"):
    """The bottle's neural ODE (trained with the paper's recipe) on the authors' throws (``data = "real"``) or a
    synthetic stand-in of ``synthetic_sizes`` = [training throws, test throws, samples per throw], and its linear
    feedback (Eqs. (7)-(8), decay Eq. (11)) over ``N`` steps, over the seeds of one ensemble."""

    data: str = setting("real", choice("real", "synthetic"))
    seeds: list[int] = setting([0, 1, 2, 3, 4], SEEDS2)
    hidden: list[int] = setting([100, 100, 100], WIDTHS)
    activation: str = setting("relu", ACT)
    iterations: int = setting(RECIPE.iterations, N1)
    batch_size: int = setting(RECIPE.batch_size, N1)
    batch_time: int = setting(RECIPE.batch_time, N2)
    lr: float = setting(RECIPE.lr, POS)
    method: str = setting(RECIPE.method, METHOD)
    adjoint: bool = setting(RECIPE.adjoint, BOOL)
    L: float = setting(5.0, GAIN)
    beta: float = setting(0.02, NONNEG)
    N: int = setting(500, N1)
    synthetic_sizes: list[int] = setting([21, 9, 1058], synthetic_sizes)

    def samples_per_throw(self) -> int:
        """The samples of one throw: the synthetic stand-in's, or the published throws'."""
        if self.data == "synthetic":
            return self.synthetic_sizes[2]
        return next(iter(BOTTLE_FILES.values()))[1][1]

    def check_relations(self) -> None:
        """A gain stable at the throws' step (Theorem 1, Eq. (25); Eq. (11) over ``N``); ``N`` and ``batch_time``
        within one throw."""
        gain(self, 6, BOTTLE_TS, self.N)
        n_samples = self.samples_per_throw()
        C.horizon("N", self.N, below=n_samples, below_name="the samples per throw")
        need(self.batch_time <= n_samples,
             f"batch_time must be <= {n_samples} samples per throw, got {self.batch_time}")

    def check_data(self, data_dir: Path) -> None:
        """The real throws must be in ``data_dir / "bottle"`` with their pinned SHA-256."""
        if self.data == "real":
            C.data_files(data_dir / "bottle", {f: d for f, (_, _, d) in BOTTLE_FILES.items()},
                         how_to_get="Get the authors' published throws with `fnn-pipeline data fetch` "
                                    "(see data/README.md).")
