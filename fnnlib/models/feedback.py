"""The neural feedback part h_neural(x - x_hat, xi) of Sec. 4."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from torch import Tensor, nn

from fnnlib.models.neural_ode import mlp


class NeuralFeedback(nn.Module):
    r"""A learned feedback :math:`h_{neural}(x - \hat x, \xi)` (Sec. 4, Eq. (12) `learn_feedback_part`).

    It replaces the linear term :math:`L(x - \hat x)` of Eq. (7): the corrected change rate is
    :math:`\hat f = f_{neural}(x) + h_{neural}(x - \hat x)`. Called as ``h(e)`` with the observation
    error ``e`` of shape (batch, n); returns the correction, shape (batch, n).

    Parameters
    ----------
    n_state : int
        State dimension n.
    hidden : sequence of int
        Hidden widths; the paper's spiral feedback is ``(50, 50)`` (App. A.3.3).
    activation : str
        One of :data:`fnnlib.models.ACTIVATIONS`.
    """

    def __init__(self, n_state: int, hidden: Sequence[int], activation: str) -> None:
        super().__init__()
        self.n_state = int(n_state)
        self.hidden = tuple(int(h) for h in hidden)
        self.activation = str(activation)
        self.net = mlp(self.n_state, self.n_state, self.hidden, self.activation)

    @property
    def config(self) -> dict[str, Any]:
        """Constructor arguments, enough to rebuild the model (used by checkpoints)."""
        return {"n_state": self.n_state, "hidden": list(self.hidden), "activation": self.activation}

    def forward(self, e: Tensor) -> Tensor:
        """h_neural(e): ``e`` (batch, n) -> (batch, n)."""
        if e.shape[-1] != self.n_state:
            raise ValueError(f"error e has dimension {e.shape[-1]}, feedback expects {self.n_state}")
        return self.net(e)
