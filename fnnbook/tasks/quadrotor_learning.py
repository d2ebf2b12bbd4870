"""The settings of ``notebooks/07_quadrotor_learning``: a quadrotor's aerodynamic residual (Sec. 5.2, App. A.1)."""

from __future__ import annotations

from dataclasses import dataclass

from fnnbook.tasks._base import TaskSettings, setting
from fnnbook.tasks._checks import ACT, N1, N2, POS, SEED, SEEDS1, WIDTHS, need, vec
from fnnlib.quadrotor import presets as QP
from fnnlib.quadrotor.system import TRAINING_TRUTH

__all__ = ["QuadrotorLearningSettings"]

_RESIDUAL = QP.PAPER_RESIDUAL_RECIPE


@dataclass(frozen=True, kw_only=True)
class QuadrotorLearningSettings(TaskSettings, notebook="quadrotor_learning"):
    """The training and validation flights (flights, nodes, waypoints; the truth's drag and RK4 sub-steps), the
    neural-ODE residual trained by Alg. 3 (App. A.5.4) and the single-step MLP baseline."""

    seed: int = setting(0, SEED)
    seeds: list[int] = setting([0, 1, 2, 3, 4], SEEDS1)
    n_flights: int = setting(40, N1)
    n_nodes: int = setting(200, N2)
    n_waypoints: int = setting(QP.PAPER_FLIGHT_DATA["n_waypoints"], N2)
    val_flights: int = setting(3, N1)
    val_nodes: int = setting(500, N2)
    val_waypoints: int = setting(6, N2)
    Ts: float = setting(QP.PAPER_TS, POS)
    truth_drag: list[float] = setting(TRAINING_TRUTH.drag, vec(3, 0.0))
    truth_substeps: int = setting(QP.PAPER_FLIGHT_DATA["substeps"], N1)
    hidden: list[int] = setting(_RESIDUAL["hidden"], WIDTHS)
    activation: str = setting(_RESIDUAL["activation"], ACT)
    epochs: int = setting(_RESIDUAL["epochs"], N1)
    segment_length: int = setting(_RESIDUAL["segment_length"], N1)
    batch_size: int = setting(_RESIDUAL["batch_size"], N1)
    lr: float = setting(_RESIDUAL["lr"], POS)
    val_every: int = setting(10, N1)
    mlp_epochs: int = setting(QP.PAPER_MLP_RECIPE["epochs"], N1)
    mlp_lr: float = setting(QP.PAPER_MLP_RECIPE["lr"], POS)

    def check_relations(self) -> None:
        """A training segment fits a flight."""
        need(self.segment_length <= self.n_nodes,
             f"segment_length must be in 1..{self.n_nodes} (n_nodes), got {self.segment_length}")
