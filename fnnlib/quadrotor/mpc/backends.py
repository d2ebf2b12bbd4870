r"""Who does the numerics of one step of the flight test (:func:`fnnlib.quadrotor.mpc.flight.fly`): one interface, two backends.

Each step of the MPC loop needs three things from the numerics: the prediction model's affine form
along a plan (for the QP of Eq. (28)), the truth vehicle's change rate and RK4 step of Eq. (27) from the
measured state under the applied input, and the model's change rate and :math:`\Phi` along the new plan.

* :class:`TorchBackend` is the reference: the torch models of :mod:`fnnlib.quadrotor.mpc.models` and
  :class:`~fnnlib.quadrotor.system.Quadrotor`, linearized by :func:`~fnnlib.quadrotor.mpc.linearize.linearize`.
* :class:`NumbaBackend` evaluates the same with the compiled twins of :mod:`fnnlib.quadrotor.mpc.compiled` (the
  declared reference twin of the torch code, held to it by the tests), with exact Jacobians; the same
  flight to ~1e-9, several times faster.

The models' online hooks (``observe``, ``commit``) are torch with either backend. Backends are chosen by
name through :data:`BACKENDS`; a flight test names its numerics with a :class:`Backend` (name and, for the
torch reference, the linearization method).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
import torch

from fnnlib.quadrotor.mpc.linearize import Linearization, linearize
from fnnlib.quadrotor.mpc.models import PredictionModel
from fnnlib.quadrotor.system import Quadrotor

__all__ = ["BACKENDS", "Backend", "FlightBackend", "NumbaBackend", "TorchBackend", "check_backend_name", "make_backend"]


class FlightBackend(Protocol):
    """The numerics of one flight step, on numpy float64 arrays.

    Built once per flight for a model, a truth vehicle, the step ``Ts`` and the truth's RK4 ``substeps``.
    """

    name: str

    def linearize(self, x_bar: np.ndarray, u_bar: np.ndarray) -> Linearization:
        """The model's affine form along ``(x_bar (N, 12), u_bar (N, 4))``; ``ValueError`` where not finite."""
        ...

    def truth_rate_and_step(self, x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The truth's change rate at ``(x (12,), u (4,))`` and its state one step ``Ts`` later."""
        ...

    def model_rate_and_phi(self, X: np.ndarray, U: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r"""The model's change rate ``f`` and :math:`\Phi` (no feedback) along ``(X (N, 12), U (N, 4))``."""
        ...


class TorchBackend:
    """The torch reference: the models' own ``f``/``phi``/``step`` and the truth's ``f``/``step``.

    Parameters
    ----------
    model, truth, Ts, substeps
        As in :func:`make_backend`.
    linearize_method : str
        :func:`~fnnlib.quadrotor.mpc.linearize.linearize`'s method (``"forward"`` in the paper run).
    N : int
        Horizon length: the plan's number of points.
    """

    name = "torch"

    def __init__(self, model: PredictionModel, truth: Quadrotor, *, Ts: float, substeps: int,
                 linearize_method: str | None, N: int) -> None:
        if linearize_method is None:
            raise ValueError("the torch backend needs a linearize_method (e.g. 'forward')")
        self.model, self.truth = model, truth
        self.Ts, self.substeps = Ts, substeps
        self.linearize_method = linearize_method
        self._k = torch.arange(N)

    def linearize(self, x_bar: np.ndarray, u_bar: np.ndarray) -> Linearization:
        step = self.model.step
        return linearize(step, torch.from_numpy(x_bar), torch.from_numpy(u_bar), self._k,  # type: ignore[arg-type]
                         method=self.linearize_method)

    def truth_rate_and_step(self, x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x_t, u_t = torch.from_numpy(x), torch.from_numpy(u)
        rate = self.truth.f(x_t, u_t)
        return rate.numpy(), self.truth.step(x_t, u_t, Ts=self.Ts, substeps=self.substeps, k1=rate).numpy()

    def model_rate_and_phi(self, X: np.ndarray, U: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        X_t, U_t = torch.from_numpy(X), torch.from_numpy(U)
        rates = self.model.f(X_t, U_t)
        return rates.numpy(), self.model.phi(X_t, U_t, k1=rates).numpy()


class NumbaBackend:
    """The compiled twins of :mod:`fnnlib.quadrotor.mpc.compiled`, with exact Jacobians.

    ``linearize_method`` and ``N`` are accepted for a uniform signature and not used (the Jacobians are
    exact, forward mode through the RK4 stages). Refuses a model whose step differs from ``Ts``.
    """

    name = "numba"

    def __init__(self, model: PredictionModel, truth: Quadrotor, *, Ts: float, substeps: int,
                 linearize_method: str | None = None, N: int | None = None) -> None:
        from fnnlib.quadrotor.mpc.compiled import CompiledModel, CompiledQuadrotor  # numba loads only when asked for

        self.model, self.truth = CompiledModel(model), CompiledQuadrotor(truth)
        if self.model.Ts != float(Ts):
            raise ValueError(f"the model predicts over Ts = {self.model.Ts} but the loop steps Ts = {Ts}")
        self.Ts, self.substeps = Ts, substeps

    def linearize(self, x_bar: np.ndarray, u_bar: np.ndarray) -> Linearization:
        return self.model.linearize(x_bar, u_bar)

    def truth_rate_and_step(self, x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.truth.rate_and_step(x, u, self.Ts, self.substeps)

    def model_rate_and_phi(self, X: np.ndarray, U: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.model.f_and_phi(X, U)


BACKENDS: dict[str, type[TorchBackend] | type[NumbaBackend]] = {"torch": TorchBackend, "numba": NumbaBackend}
"""Backend name -> class."""


def check_backend_name(name: str) -> str:
    """Refuse a backend name not in :data:`BACKENDS`."""
    if name not in BACKENDS:
        raise ValueError(f"backend must be one of {sorted(BACKENDS)}, got {name!r}")
    return name


def make_backend(name: str, model: PredictionModel, truth: Quadrotor, *, Ts: float, substeps: int, N: int,
                 linearize_method: str | None = None) -> FlightBackend:
    """The backend ``name`` (a key of :data:`BACKENDS`) for one flight of ``model`` on ``truth``.

    ``Ts`` is the control step, ``substeps`` the truth's RK4 sub-steps per step, ``N`` the horizon;
    ``linearize_method`` is needed by the torch backend only.
    """
    return BACKENDS[check_backend_name(name)](model, truth, Ts=Ts, substeps=substeps,
                                              linearize_method=linearize_method, N=N)


#: how the compiled backend linearizes (it takes no method)
EXACT_LINEARIZATION = "exact (forward mode, compiled)"


@dataclass(frozen=True)
class Backend:
    """The numerics a flight test runs on: a key of :data:`BACKENDS`, with the torch reference's linearization.

    ``linearize_method`` is :func:`~fnnlib.quadrotor.mpc.linearize.linearize`'s method, required by ``"torch"`` (the
    paper run's is ``"forward"``); the compiled ``"numba"`` backend has exact Jacobians and ignores it.
    """

    name: str
    linearize_method: str | None = None

    def __post_init__(self) -> None:
        check_backend_name(self.name)
        if self.name == "torch" and self.linearize_method is None:
            raise ValueError("the torch backend needs a linearize_method (e.g. 'forward')")

    @property
    def linearization(self) -> str:
        """How the model is linearized: the torch backend's method, or the compiled backend's exact Jacobians."""
        return str(self.linearize_method) if self.name == "torch" else EXACT_LINEARIZATION

    def build(self, model: PredictionModel, truth: Quadrotor, *, Ts: float, substeps: int, N: int) -> FlightBackend:
        """This backend's numerics for one flight of ``model`` on ``truth`` (see :func:`make_backend`)."""
        return make_backend(self.name, model, truth, Ts=Ts, substeps=substeps, N=N,
                            linearize_method=self.linearize_method)
