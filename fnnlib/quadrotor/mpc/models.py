r"""Prediction models for the quadrotor MPC of Sec. 5.2 and App. A.5.3-A.5.4, behind one interface.

Every model is a discrete map for horizon step ``k``,
``step(x, u, k) -> x_next`` (batched, torch), which the MPC linearizes along
its previous plan. Between control steps the MPC loop calls

* :meth:`PredictionModel.observe` with the new measured state (before solving),
* :meth:`PredictionModel.commit` with the plan it applied (after solving),

which is where the feedback cascade and the adaptive laws learn online.

The seven models of the paper's comparison (App. A.5.4):

===========  ==============================================================
``Nomi``     the nominal model, Eq. (27)
``Neural``   nominal + the residual neural ODE trained with App. A.1
``MLP``      nominal + a feed-forward residual trained on single-step labels
``FB``       nominal + the linear feedback cascade (Eqs. (7)-(8), (11))
``AdapNN``   nominal + residual with an adaptive last layer (Cheng et al.)
``FNN``      nominal + residual neural ODE + the feedback cascade
``AdapFNN``  ``FNN`` with the adaptive last layer, Eqs. (29)-(30)
===========  ==============================================================
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor, nn

from fnnlib._validation import check_finite, check_positive
from fnnlib.quadrotor.residual import AdaptiveResidual
from fnnlib.feedback import check_gain, decayed_gains
from fnnlib.quadrotor.system import Quadrotor

__all__ = ["AdaptiveNNModel", "FeedbackCascadeModel", "PredictionModel", "paper_models"]


class PredictionModel:
    r"""Nominal dynamics Eq. (27) plus an optional learned residual, discretised by RK4.

    :math:`\Phi(x, u)`: one RK4 step of length ``Ts`` (``substeps`` sub-steps) of
    :math:`\dot x = f(x, u) + [0, f_{neural}(v, \Theta), 0, 0]`.

    Parameters
    ----------
    name : str
        Label used in tables and figures.
    plant : Quadrotor
        The model's own (nominal) quadrotor; never the test vehicle.
    residual : callable or None
        ``residual(x) -> (..., 3)`` acceleration, e.g. an
        :class:`~fnnlib.quadrotor.residual.AeroResidual`; ``None`` for the nominal model.
    Ts : float
        Control / prediction step (0.02 s in the paper).
    substeps : int
        RK4 sub-steps per ``Ts``.
    """

    def __init__(self, name: str, plant: Quadrotor, residual: Callable[[Tensor], Tensor] | None = None, *,
                 Ts: float, substeps: int = 1) -> None:
        self.name = str(name)
        self.plant = plant
        self.residual = residual
        self.Ts = check_positive(Ts, name="Ts")
        self.substeps = int(substeps)
        if isinstance(residual, nn.Module):
            for p in residual.parameters():
                p.requires_grad_(False)

    # -- the model --------------------------------------------------------
    def f(self, x: Tensor, u: Tensor) -> Tensor:
        """Continuous change rate of the model, (..., 12)."""
        return self.plant.f(x, u, a_res=None if self.residual is None else self.residual(x))

    def phi(self, x: Tensor, u: Tensor, k1: Tensor | None = None) -> Tensor:
        r""":math:`\Phi(x, u)`, the RK4 step of :meth:`f` (no feedback); ``k1 = f(x, u)`` if already computed."""
        return self.plant.step(x, u, Ts=self.Ts, substeps=self.substeps, a_res_fn=self.residual, k1=k1)

    def step(self, x: Tensor, u: Tensor, k: Tensor) -> Tensor:
        """The discrete model for horizon steps ``k`` (LongTensor, batch); here the same for every ``k``."""
        return self.phi(x, u)

    def xdot(self, x: Tensor, u: Tensor, f: Tensor | None = None) -> Tensor:
        """The model's first-step change-rate prediction at the measured state (Fig. S8); ``f = f(x, u)`` if known."""
        return self.f(x, u) if f is None else f

    def feedback_terms(self) -> tuple[Tensor, Tensor] | None:
        r"""The affine correction inside the horizon, if any: the pair ``(Ts * L_k, x_hat)``, shapes (N, 12, 12), (N, 12).

        :meth:`step` at horizon step ``k`` is :meth:`phi` plus ``Ts L_k (x - x_hat[k])``; the compiled
        linearization (:mod:`fnnlib.quadrotor.mpc.compiled`) adds it in closed form. ``None``: no correction.
        """
        return None

    # -- online hooks -----------------------------------------------------
    def observe(self, x_meas: Tensor) -> None:
        """A new measured state (12,), before the MPC solves."""

    def commit(self, plan_x: Tensor, plan_u: Tensor, phi_plan: Tensor | None = None) -> None:
        """The plan just solved: states (N+1, 12) from the measured state, inputs (N, 4); ``plan_u[0]`` is applied.

        ``phi_plan`` (N, 12), if given, is :meth:`phi` of ``(plan_x[:-1], plan_u)`` already computed by the
        caller (the flight loop needs it too); models that need it compute it otherwise.
        """

    def reset(self) -> None:
        """Forget everything learned online."""

    @property
    def observer_error(self) -> Tensor | None:
        r"""The layer-0 observation error :math:`\tilde x = x - \hat x` at the last measurement, if any."""
        return None


class AdaptiveNNModel(PredictionModel):
    r"""AdapNN: nominal + a residual whose last layer adapts from the one-step velocity error.

    The adaptive-network baseline (Cheng et al. 2019, App. A.5.4): the update
    has the form of Eq. (30) with the error signal taken as the one-step
    acceleration prediction error :math:`\tilde a_t = (v_{t+1} - \hat v_{t+1}) / Ts`, where
    :math:`\hat v_{t+1}` is the model's prediction from :math:`(x_t, u_t)` (there is no
    observer to supply :math:`\tilde x`).

    **The gain's convention**. Eq. (30), :math:`\dot{\hat\chi} = \Gamma\,\Xi^\top\tilde x`, is
    stepped by explicit Euler over :math:`T_s` with the error above, so each step is
    :math:`\hat\chi \mathrel{+}= T_s \Gamma\, \tilde a_t \phi^\top = \Gamma\,(v_{t+1} - \hat v_{t+1})\,\phi^\top`
    (measurement minus prediction; :meth:`AdaptiveResidual.adapt`). The authors' release steps
    :math:`T_s \Gamma_{rel}\, e\, \phi^\top` with :math:`e` the velocity error taken with the opposite sign
    convention, i.e. 1/50 of this update at the same number (:math:`T_s` = 0.02). A release gain converts as
    :math:`\Gamma = T_s \Gamma_{rel}` (the sign absorbed by the error's definition): the paper's
    :math:`\Gamma = 8` is :math:`\Gamma \approx 0.16` here, and :math:`\Gamma = 8` in this convention is 50 times
    the release's adaptation (it runs away). Choose :math:`\Gamma` on validation flights,
    :func:`fnnlib.quadrotor.mpc.tuning.select_gain_on_validation`, over a grid that brackets 0.16.
    """

    def __init__(self, name: str, plant: Quadrotor, residual: AdaptiveResidual, *, Ts: float,
                 substeps: int = 1) -> None:
        if not isinstance(residual, AdaptiveResidual):
            raise TypeError(f"AdaptiveNNModel needs an AdaptiveResidual, got {type(residual).__name__}")
        super().__init__(name, plant, residual, Ts=Ts, substeps=substeps)
        self._last: tuple[Tensor, Tensor] | None = None  # (x_t, predicted x_{t+1})

    def observe(self, x_meas: Tensor) -> None:
        check_finite(x_meas, name="x_meas")
        if self._last is not None:
            x_prev, x_pred = self._last
            a_tilde = (x_meas[3:6] - x_pred[3:6]) / self.Ts
            self.residual.adapt(x_prev, a_tilde, self.Ts)  # type: ignore[union-attr]

    def commit(self, plan_x: Tensor, plan_u: Tensor, phi_plan: Tensor | None = None) -> None:
        with torch.no_grad():
            x_pred = self.phi(plan_x[0], plan_u[0]) if phi_plan is None else phi_plan[0]
            self._last = (plan_x[0].clone(), x_pred.clone())

    def reset(self) -> None:
        self._last = None
        self.residual.reset()  # type: ignore[union-attr]


class FeedbackCascadeModel(PredictionModel):
    r"""A model corrected by the linear feedback cascade inside the MPC horizon (Sec. 3.3, App. A.5.3).

    Layer ``k = 0 .. N-1`` of the cascade keeps an estimate :math:`\hat x^{(k)}` and
    corrects horizon step ``k`` by Eq. (7) with the decayed gain of Eq. (11),
    :math:`L_k = L e^{-\beta k}`, in the discrete form

    .. math:: x_{k+1} = \Phi(x_k, u_k) + T_s L_k (x_k - \hat x^{(k)}).

    Layer 0 observes the measured state; layer ``k`` observes the plan's state
    ``k`` steps ahead. After each solve every layer advances one step along
    the new plan ``(X_k, u_k)`` by the RK4 form of Eq. (8):

    .. math:: \hat x^{(k)} \leftarrow \hat x^{(k)} + [\Phi(X_k, u_k) - X_k] + T_s L_k (X_k - \hat x^{(k)}),

    so that for layer 0 the error obeys Eq. (25),
    :math:`\tilde x_{t+1} = (I - T_s L)\tilde x_t + T_s\Delta_t` with :math:`\Delta_t` the
    model's one-step residual, and :math:`L\tilde x \to \Delta`.

    With an :class:`~fnnlib.quadrotor.residual.AdaptiveResidual` (``adaptive=True``) this is
    AdapFNN: at each measurement the last layer moves by Eq. (30) with the
    velocity part of :math:`\tilde x = x - \hat x^{(0)}` (Eqs. (29)-(30), Theorem 2).

    Parameters
    ----------
    base : PredictionModel
        The model being corrected (nominal, or nominal + residual).
    L : float or Tensor
        Feedback gain (scalar, (12,) diagonal or (12, 12)); the paper: 3 I.
    beta : float
        Gain decay rate of Eq. (11); the paper: 0.1.
    N : int
        Horizon length (number of cascade layers).
    name : str, optional
        Defaults to ``"FB-" + base.name``.

    Attributes
    ----------
    L_stack : Tensor, shape (N, 12, 12)
        The decayed gains of Eq. (11), ``L_stack[k] = L_k = L e^{-beta k}`` (``L`` is the base gain).
    """

    def __init__(self, base: PredictionModel, L: float | Tensor, beta: float, N: int, *, name: str | None = None,
                 adaptive: bool = False) -> None:
        super().__init__(name or f"FB-{base.name}", base.plant, base.residual, Ts=base.Ts, substeps=base.substeps)
        self.base = base
        # positive definite and stable at the model's Ts, as Theorem 1 needs
        L_mat = check_gain(L, 12, self.Ts)
        self.L_stack = torch.stack(decayed_gains(L_mat, int(N), beta))  # L_k = L e^{-beta k}, (N, 12, 12)
        self._Ts_L_stack = self.Ts * self.L_stack
        self.N = int(N)
        self.beta = float(beta)
        if adaptive and not isinstance(base.residual, AdaptiveResidual):
            raise TypeError("adaptive=True needs a base model whose residual is an AdaptiveResidual")
        self.adaptive = bool(adaptive)
        self.x_hat: Tensor | None = None  # (N, 12)
        self._x_tilde: Tensor | None = None

    def _correction(self, x: Tensor, k: Tensor) -> Tensor:
        if self.x_hat is None:
            return torch.zeros_like(x)
        L_k = self.L_stack.to(x.dtype)[k]  # (..., 12, 12)
        # L_k (x - x_hat^(k))   (Eq. 7)
        return (L_k @ (x - self.x_hat.to(x.dtype)[k]).unsqueeze(-1)).squeeze(-1)

    def step(self, x: Tensor, u: Tensor, k: Tensor) -> Tensor:
        return self.phi(x, u) + self.Ts * self._correction(x, k)

    def feedback_terms(self) -> tuple[Tensor, Tensor] | None:
        if self.x_hat is None:
            return None
        return self._Ts_L_stack, self.x_hat

    def xdot(self, x: Tensor, u: Tensor, f: Tensor | None = None) -> Tensor:
        rate = self.f(x, u) if f is None else f
        if self.x_hat is None:
            return rate
        # layer 0's correction L_0 (x - x_hat^(0))   (Eq. 7)
        return rate + (x - self.x_hat[0].to(x.dtype)) @ self.L_stack[0].to(x.dtype).T

    def observe(self, x_meas: Tensor) -> None:
        check_finite(x_meas, name="x_meas")
        if self.x_hat is None:
            return
        self._x_tilde = (x_meas - self.x_hat[0]).detach().clone()
        if self.adaptive:
            # chi_hat' = Gamma Xi^T x_tilde   (Eq. 30), velocity rows
            self.residual.adapt(x_meas, self._x_tilde[3:6], self.Ts)  # type: ignore[union-attr]

    def commit(self, plan_x: Tensor, plan_u: Tensor, phi_plan: Tensor | None = None) -> None:
        if plan_x.shape != (self.N + 1, 12) or plan_u.shape != (self.N, 4):
            raise ValueError(f"plan must be x (N+1, 12), u (N, 4) with N = {self.N}; got {tuple(plan_x.shape)}, "
                             f"{tuple(plan_u.shape)}")
        with torch.no_grad():
            X, U = plan_x[:-1], plan_u
            if self.x_hat is None:  # start every layer on the plan: zero correction
                self.x_hat = X.clone()
            Lk = self.L_stack.to(X.dtype)
            # x_hat <- x_hat + [Phi(X, u) - X] + Ts L_k (X - x_hat)   (Eq. 8, RK4 form)
            fb = (Lk @ (X - self.x_hat).unsqueeze(-1)).squeeze(-1)
            if phi_plan is None:
                phi_plan = self.phi(X, U)
            elif phi_plan.shape != X.shape:
                raise ValueError(f"phi_plan must have shape {tuple(X.shape)}, got {tuple(phi_plan.shape)}")
            self.x_hat = self.x_hat + (phi_plan - X) + self.Ts * fb
            check_finite(self.x_hat, name="x_hat")

    def reset(self) -> None:
        self.x_hat = None
        self._x_tilde = None
        if self.adaptive:
            self.residual.reset()  # type: ignore[union-attr]

    @property
    def observer_error(self) -> Tensor | None:
        return self._x_tilde


def paper_models(residual: nn.Module, mlp: nn.Module, *, plant: Quadrotor, L: float | Tensor, beta: float, N: int,
                 Gamma: float, Ts: float, substeps: int = 1, adapnn_gamma: float | None = None) -> list[PredictionModel]:
    """The seven prediction models of App. A.5.4 (see the module docstring), in the paper's order.

    ``residual`` is the neural ODE's :class:`~fnnlib.quadrotor.residual.AeroResidual` (trained with App. A.1),
    ``mlp`` the single-step one. AdapNN and AdapFNN adapt the last layer of a copy of ``residual``
    (the same network as Neural and FNN, so the comparison isolates the online part). ``plant`` is the
    models' own vehicle (the paper's: ``Quadrotor(NOMINAL)``); the paper's ``L``, ``beta``, ``N``, ``Gamma``
    and ``Ts`` are in :mod:`fnnlib.quadrotor.presets`. AdapNN adapts at ``adapnn_gamma`` where given (its gain
    chosen on validation flights, :func:`~fnnlib.quadrotor.mpc.experiment.adapnn_gain_on_validation`), else at ``Gamma``.
    """
    kw = {"Ts": Ts, "substeps": substeps}
    nomi = PredictionModel("Nomi", plant, None, **kw)
    neural = PredictionModel("Neural", plant, residual, **kw)
    return [
        nomi,
        neural,
        PredictionModel("MLP", plant, mlp, **kw),
        FeedbackCascadeModel(nomi, L, beta, N, name="FB"),
        AdaptiveNNModel("AdapNN", plant, AdaptiveResidual(residual, Gamma if adapnn_gamma is None else adapnn_gamma),
                        **kw),
        FeedbackCascadeModel(neural, L, beta, N, name="FNN"),
        FeedbackCascadeModel(PredictionModel("AdapNeural", plant, AdaptiveResidual(residual, Gamma), **kw), L, beta,
                             N, name="AdapFNN", adaptive=True),
    ]
