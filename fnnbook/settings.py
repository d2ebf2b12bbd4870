"""The book's notebooks: each one's paper presets and value checks, run before any work starts.

A notebook of the book calls :func:`check_notebook_settings` with its name right after its ``parameters``
cell; ``fnn-pipeline check`` and the start of ``fnn-pipeline run`` run the same checks for every task before
any task runs, so a bad value fails in seconds, not after the upstream tasks have trained. Each parameter of
each notebook has a check (:data:`VALUE_CHECKS`, built from the plain checks of :mod:`fnnlib.checks`);
:data:`RELATIONS` checks the values that depend on each other (a gain stable at the step ``Ts``, a horizon
that fits the data). A name that is not a notebook of the book is refused.

>>> check_notebook_settings("spiral", {"L": -1.0, "Ts": 0.01, "N": 50, "N_max": 100, "beta": 0.02,
...                                    "n_samples": 1000})  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
ValueError: notebook 'spiral': setting(s) missing: ...
"""

from __future__ import annotations

import json
import re
import warnings
from collections.abc import Callable, Mapping, MutableMapping
from functools import partial
from pathlib import Path
from types import MappingProxyType
from typing import Any

from fnnlib import checks as C
from fnnlib import quadrotor_presets as QP
from fnnlib import spiral_presets as SP
from fnnlib.checks import MissingDataError
from fnnlib.data.bottle import BOTTLE_FILES, TS as BOTTLE_TS
from fnnlib.data.release import SPIRAL_FEEDBACK_NAMES, SPIRAL_ODE_NAMES
from fnnlib.data.tanks import TANKS_FILE, TANKS_SHA256
from fnnlib.feedback import GainWarning
from fnnlib.models import ACTIVATIONS
from fnnlib.systems.quadrotor import TEST_TRUTH, TRAINING_TRUTH
from fnnlib.training import PAPER_BOTTLE_RECIPE, PAPER_SPIRAL_RECIPE

__all__ = ["NOTEBOOK_PRESETS", "RELATIONS", "VALUE_CHECKS", "MissingDataError", "check_notebook_settings",
           "fill_presets", "notebook_name", "notebook_presets"]


# -- the paper values the notebooks share, each written once (in the preset modules and the recipes)
def _recipe(recipe: Any, *names: str) -> dict[str, Any]:
    return {name: getattr(recipe, name) for name in names}


_SPIRAL_DATA = {"Ts": SP.SPIRAL_TS, "n_samples": SP.SPIRAL_SAMPLES, "x0": SP.SPIRAL_X0}
_SPIRAL_FEEDBACK = {"L": SP.PAPER_SPIRAL_L, "beta": SP.PAPER_SPIRAL_BETA, "N": SP.PAPER_SPIRAL_N}

NOTEBOOK_PRESETS: Mapping[str, Mapping[str, Any]] = MappingProxyType({
    "spiral": {**_SPIRAL_DATA, "nominal": SP.SPIRAL_NOMINAL, "test": SP.SPIRAL_TEST,
               "hidden": SP.PAPER_SPIRAL_HIDDEN, "activation": SP.SPIRAL_ACTIVATION,
               **_recipe(PAPER_SPIRAL_RECIPE, "iterations", "batch_size", "batch_time", "lr", "method", "adjoint",
                         "rtol", "atol"),
               **_SPIRAL_FEEDBACK, "noise_std": SP.SPIRAL_NOISE_STD},
    "theory": {**_SPIRAL_DATA, "test": SP.SPIRAL_TEST, "L": SP.PAPER_SPIRAL_L},
    "ablations": {**_SPIRAL_DATA, "nominal": SP.SPIRAL_NOMINAL, "test": SP.SPIRAL_TEST, **_SPIRAL_FEEDBACK,
                  "noise_std": SP.SPIRAL_NOISE_STD, "residual_base": SP.SPIRAL_NOMINAL, **SP.RESIDUAL_GRID,
                  "before": SP.SPIRAL_TEST},
    "observers": {**_SPIRAL_DATA, "test": SP.SPIRAL_TEST, **_SPIRAL_FEEDBACK, "noise_std": SP.SPIRAL_NOISE_STD,
                  **SP.KALMAN_SETTINGS},
    "neural_feedback": {**_SPIRAL_DATA, "nominal": SP.SPIRAL_NOMINAL, **_SPIRAL_FEEDBACK,
                        "fb_hidden": SP.PAPER_SPIRAL_HIDDEN, "fb_activation": SP.SPIRAL_ACTIVATION,
                        "residual_base": SP.SPIRAL_NOMINAL, **SP.RESIDUAL_GRID},
    "why_feedback_point": {**_SPIRAL_DATA, "nominal": SP.SPIRAL_NOMINAL, "N": SP.PAPER_SPIRAL_N,
                           "fb_hidden": SP.PAPER_SPIRAL_HIDDEN, "fb_activation": SP.SPIRAL_ACTIVATION,
                           "residual_base": SP.SPIRAL_NOMINAL, **SP.RESIDUAL_GRID},
    "why_feedback": {**_SPIRAL_DATA, "nominal": SP.SPIRAL_NOMINAL, "N": SP.PAPER_SPIRAL_N,
                     "residual_base": SP.SPIRAL_NOMINAL, **SP.RESIDUAL_GRID},
    "bottle": _recipe(PAPER_BOTTLE_RECIPE, "iterations", "batch_size", "batch_time", "lr", "method", "adjoint"),
    "quadrotor_learning": {
        "Ts": QP.PAPER_TS, "n_waypoints": QP.PAPER_FLIGHT_DATA["n_waypoints"],
        "truth_drag": TRAINING_TRUTH.drag, "truth_substeps": QP.PAPER_FLIGHT_DATA["substeps"],
        **{k: QP.PAPER_RESIDUAL_RECIPE[k] for k in ("hidden", "activation", "epochs", "segment_length",
                                                    "batch_size", "lr")},
        "mlp_epochs": QP.PAPER_MLP_RECIPE["epochs"], "mlp_lr": QP.PAPER_MLP_RECIPE["lr"]},
    "quadrotor_mpc": {
        "N": QP.PAPER_HORIZON, "Ts": QP.PAPER_TS, **QP.PAPER_MPC_WEIGHTS, "theta_max": QP.PAPER_THETA_MAX,
        "L": QP.PAPER_L, "beta": QP.PAPER_BETA, "Gamma": QP.PAPER_GAMMA, "truth_mass": TEST_TRUTH.mass,
        "truth_inertia": TEST_TRUTH.inertia, "truth_drag": TEST_TRUTH.drag,
        "disturbance": TEST_TRUTH.force_disturbance},
    "own_system": {
        "L_hand": SP.PAPER_SPIRAL_L, "beta_hand": SP.PAPER_SPIRAL_BETA, **SP.KALMAN_SETTINGS,
        "spiral_n_samples": SP.SPIRAL_SAMPLES, "spiral_Ts": SP.SPIRAL_TS, "spiral_test": SP.SPIRAL_TEST,
        "spiral_x0": SP.SPIRAL_X0, "spiral_N": SP.PAPER_SPIRAL_N, "spiral_noise_std": SP.SPIRAL_NOISE_STD,
        "spiral_L": SP.PAPER_SPIRAL_L, "spiral_beta": SP.PAPER_SPIRAL_BETA},
    "why_sec3": {**_SPIRAL_DATA, "test": SP.SPIRAL_TEST, **_SPIRAL_FEEDBACK, "noise_std": SP.SPIRAL_NOISE_STD,
                 "residual_base": SP.SPIRAL_NOMINAL, **SP.RESIDUAL_GRID, "before": SP.SPIRAL_TEST},
})
"""Per notebook: the parameters its ``parameters`` cell leaves at ``None``, and the paper value each takes.

A value several notebooks (or a notebook and the library) share is written once, in
:mod:`fnnlib.spiral_presets`, :mod:`fnnlib.quadrotor_presets`, the vehicles of :mod:`fnnlib.systems.quadrotor`
or the training recipes; this table only says which parameter takes which. A profile may override any of them."""


# -- one check per parameter: check(name, value) raises ValueError naming the parameter
Check = Callable[[str, Any], Any]


def _int(minimum: int) -> Check:
    return partial(C.integer, minimum=minimum)


def _vec(n: int | None = None, minimum: float | None = None) -> Check:
    return partial(C.numbers, n=n, minimum=minimum)


def _choice(*choices: str) -> Check:
    return partial(C.one_of, choices=choices)


def _ode_methods() -> tuple[str, ...]:
    from torchdiffeq._impl.odeint import SOLVERS  # noqa: PLC0415 (torchdiffeq's solver names; no public list)

    return tuple(SOLVERS)


def _cvxpy_solvers() -> tuple[str, ...]:
    import cvxpy  # noqa: PLC0415

    return tuple(cvxpy.installed_solvers())


def _lazy_choice(choices: Callable[[], tuple[str, ...]]) -> Check:
    return lambda name, value: C.one_of(name, value, choices())


def _from_mpc(attribute: str, module: str) -> Check:
    """One of the names a table of :mod:`fnnlib.mpc` holds (imported on use: the MPC loads numba)."""
    import importlib  # noqa: PLC0415

    return _lazy_choice(lambda: tuple(getattr(importlib.import_module(f"fnnlib.mpc.{module}"), attribute)))


_SEED, _SEEDS2, _POS, _NONNEG, _BOOL = C.seed, partial(C.distinct_seeds, at_least=2), C.positive, C.nonnegative, \
    C.boolean
_SEEDS1 = partial(C.distinct_seeds, at_least=1)
_N1, _N0, _N2 = _int(1), _int(0), _int(2)
_WIDTHS, _GRID = C.layer_widths, C.colon_grid
_SPIRAL3 = _vec(3)  # (omega, eta, eps) of the spiral Eq. (26)
_X0 = _vec(2)
_ACT = _choice(*ACTIVATIONS)
_METHOD = _lazy_choice(_ode_methods)
_OPTIMIZER = _choice("rmsprop", "adam")
_SWEEP0 = partial(C.number_list, minimum=0.0, distinct=True)
_GAINS = C.number_list  # scalar gains, each stable at the step Ts (RELATIONS)



def _changes(name: str, value: Any) -> Mapping[str, Any]:
    """One-factor changes to a training recipe: a mapping (its keys are checked with the other settings)."""
    if not isinstance(value, Mapping):
        raise ValueError(f"{name} must be a mapping of changes, got {value!r}")
    return value


def _fraction(name: str, value: Any) -> float:
    """A share in [0, 1), e.g. of the samples a sensor loses."""
    share = C.nonnegative(name, value)
    if share >= 1:
        raise ValueError(f"{name} must lie in [0, 1), got {value!r}")
    return share


def _synthetic_sizes(name: str, value: Any) -> list[int]:
    """``[training throws, test throws, samples per throw]`` of the synthetic stand-in: >= 1, >= 1, >= 2."""
    if not (isinstance(value, list) and len(value) == 3):
        raise ValueError(f"{name} must be [training throws, test throws, samples per throw], got {value!r}")
    for what, size, minimum in zip(("training throws", "test throws", "samples per throw"), value, (1, 1, 2)):
        C.integer(f"{name} ({what})", size, minimum=minimum)
    return value


_SPIRAL_TRAJ = {"n_samples": _N2, "Ts": _POS, "x0": _X0}
_GAIN = C.finite  # a gain L: stable at the step Ts (RELATIONS)


def _why_axis(name: str, value: Any, *, positive: bool = False) -> list[float]:
    """A why grid's axis: at least 2 distinct finite numbers (each > 0 with ``positive``)."""
    values = C.number_list(name, value, distinct=True)
    _need(len(values) >= 2, f"{name}: a grid axis needs at least 2 values, got {value!r}")
    _need(not positive or min(values) > 0, f"{name} must list values > 0, got {value!r}")
    return values


_WHY_AXIS, _WHY_AXIS_POS = _why_axis, partial(_why_axis, positive=True)


def _horizons(name: str, value: Any) -> list[int]:
    """Prediction horizons: distinct integers >= 1."""
    values = C.number_list(name, value, minimum=1.0, distinct=True)
    if not all(isinstance(v, int) and not isinstance(v, bool) for v in value):
        raise ValueError(f"{name} must list distinct integers >= 1, got {value!r}")
    return [int(v) for v in values]
_SPIRAL_FB = {"L": _GAIN, "beta": _NONNEG, "N": _N1}
_ODE_FIT = {"hidden": _WIDTHS, "activation": _ACT, "iterations": _N1, "batch_size": _N1, "batch_time": _N2,
            "lr": _POS, "method": _METHOD, "adjoint": _BOOL}

VALUE_CHECKS: Mapping[str, Mapping[str, Check]] = MappingProxyType({
    "spiral": {"seeds": _SEEDS2, **_SPIRAL_TRAJ, "nominal": _SPIRAL3, "test": _SPIRAL3, **_ODE_FIT,
               "rtol": _POS, "atol": _POS, **_SPIRAL_FB, "N_max": _N1, "noise_std": _POS, "noise_sweep": _SWEEP0},
    "theory": {"seed": _SEED, **_SPIRAL_TRAJ, "test": _SPIRAL3, "L": _GAIN, "L_sweep": _GAINS,
               "transient_time_constants": _POS, "conservative_ratio": _POS, "discrete_gains": _SWEEP0,
               "growth_threshold": _POS, "rate_tolerance": _POS},
    "ablations": {"seed": _SEED, **_SPIRAL_TRAJ, "nominal": _SPIRAL3, "test": _SPIRAL3, **_SPIRAL_FB,
                  "noise_std": _POS, "noise_draws": _N1, "gain_range": _GRID, "omega_range": _GRID,
                  "eta_range": _GRID, "eps_range": _GRID, "trend_fraction": _POS, "residual_base": _SPIRAL3,
                  "domega_range": _GRID, "deta_range": _GRID, "deps_range": _GRID, "beta_range": _GRID,
                  "beta_extended": _SWEEP0, "t_switch": _POS, "before": _SPIRAL3, "after": _SPIRAL3,
                  "steady_window": _POS, "band_factor": _POS, "settle_threshold": _POS},
    "observers": {"seed": _SEED, **_SPIRAL_TRAJ, "test": _SPIRAL3, "noise_std": _POS, **_SPIRAL_FB,
                  "settle": _N0, "luenberger_poles": _vec(4), "kf_q_x": _NONNEG, "kf_tuning_low": _SPIRAL3,
                  "kf_tuning_high": _SPIRAL3, "kf_tuning_cases": _N2, "kf_p0_d": _NONNEG, "repeats": _N1},
    "neural_feedback": {"seed": _SEED, "x0": _X0, "nominal": _SPIRAL3, "n_samples": _N2, "Ts": _POS,
                        "dr_omega_range": _GRID, "dr_eta_range": _GRID, "dr_eps_range": _GRID,
                        "dr_n_samples": _N2, "dr_Ts": _POS, "fb_hidden": _WIDTHS, "fb_activation": _ACT,
                        "fb_iterations": _N1, "fb_batch_size": _N1, "fb_lr": _POS, "fb_optimizer": _OPTIMIZER,
                        "refresh_every": _N1, **_SPIRAL_FB, "residual_base": _SPIRAL3, "domega_range": _GRID,
                        "deta_range": _GRID, "deps_range": _GRID, "d1_factor": _POS, "d2_factor": _POS,
                        "d3_ratio": _POS, "d3_flat": _POS, "heldout_flip": _SPIRAL3, "heldout_min_distance": _POS},
    "why_feedback_point": {"n_seeds": _N2, "change": _changes,
                           "x0": _X0, "nominal": _SPIRAL3, "n_samples": _N2, "Ts": _POS,
                           "dr_omega_range": _GRID, "dr_eta_range": _GRID, "dr_eps_range": _GRID,
                           "dr_n_samples": _N2, "dr_Ts": _POS, "fb_hidden": _WIDTHS, "fb_activation": _ACT,
                           "fb_iterations": _N1, "fb_batch_size": _N1, "fb_lr": _POS, "fb_optimizer": _OPTIMIZER,
                           "refresh_every": _N1, "N": _N1, "residual_base": _SPIRAL3, "domega_range": _GRID,
                           "deta_range": _GRID, "deps_range": _GRID, "d2_factor": _POS, "d3_ratio": _POS,
                           "d3_flat": _POS, "heldout_flip": _SPIRAL3, "heldout_min_distance": _POS},
    "why_feedback": {"x0": _X0, "nominal": _SPIRAL3, "n_samples": _N2, "Ts": _POS, "N": _N1,
                     "dr_omega_range": _GRID, "dr_eta_range": _GRID, "dr_eps_range": _GRID,
                     "residual_base": _SPIRAL3, "domega_range": _GRID, "deta_range": _GRID, "deps_range": _GRID,
                     "fb_iterations": _N1, "fb_lr": _POS, "fb_optimizer": _OPTIMIZER, "refresh_every": _N1,
                     "d1_factor": _POS, "d2_factor": _POS, "d3_ratio": _POS, "d3_flat": _POS,
                     "heldout_flip": _SPIRAL3, "heldout_min_distance": _POS,
                     "dr_n_samples": _N2, "dr_Ts": _POS, "d4_beta": _SWEEP0,
                     "authors_ode": _choice(*SPIRAL_ODE_NAMES), "authors_dr_ode": _choice(*SPIRAL_ODE_NAMES),
                     "authors_feedback": _choice(*SPIRAL_FEEDBACK_NAMES)},
    "bottle": {"data": _choice("real", "synthetic"), "seeds": _SEEDS2, **_ODE_FIT, **_SPIRAL_FB,
               "synthetic_sizes": _synthetic_sizes},
    "quadrotor_learning": {"seed": _SEED, "seeds": _SEEDS1, "n_flights": _N1, "n_nodes": _N2, "n_waypoints": _N2,
                           "val_flights": _N1, "val_nodes": _N2, "val_waypoints": _N2, "Ts": _POS,
                           "truth_drag": _vec(3, 0.0), "truth_substeps": _N1, "hidden": _WIDTHS, "activation": _ACT,
                           "epochs": _N1, "segment_length": _N1, "batch_size": _N1, "lr": _POS, "val_every": _N1,
                           "mlp_epochs": _N1, "mlp_lr": _POS},
    "quadrotor_mpc": {"steps": _N1, "N": _N1, "Ts": _POS, "Q": _vec(12, 0.0), "R": _vec(4, 0.0),
                      "costs": partial(C.some_of, choices=("as_written", "as_flown")), "u_max": _vec(), "u_max_judged": _POS, "theta_max": _POS, "L": _GAIN,
                      "beta": _NONNEG, "Gamma": _POS, "Gamma_adapnn_grid": _vec(), "Gamma_rtol": _NONNEG,
                      "validation_flights": _N1, "validation_steps": _N1, "validation_waypoints": _N2,
                      "validation_seed": _SEED, "truth_mass": _POS, "truth_inertia": _vec(3, 0.0),
                      "truth_drag": _vec(3, 0.0), "disturbance": _vec(3), "disturbance_draws": _N0,
                      "disturbance_spread": _NONNEG, "disturbance_seed": _SEED, "truth_substeps": _N1,
                      "solver": _lazy_choice(_cvxpy_solvers), "qp": _from_mpc("QP_CLASSES", "experiment"),
                      "linearize_method": _from_mpc("METHODS", "linearize"),
                      "backend": _from_mpc("BACKENDS", "backends"), "transient_s": _NONNEG,
                      "validation_vehicles": _N1, "validation_vehicle_seed": _SEED},
    "why_quadrotor_point": {"u_max": _POS, "Gamma_grid": _SWEEP0, "Gamma_adapnn_grid": _SWEEP0,
                            "authors_u_max": _SWEEP0},
    "why_quadrotor": {},
    "own_system": {"seeds": _SEEDS2, "Ts": _POS, "n_train": _N2, "n_test": _N2, "nominal": _vec(4),
                   "test": _vec(4), "u_amp": _NONNEG, "hidden": _WIDTHS, "activation": _ACT, "iterations": _N1,
                   "noise_std": _POS, "N": _N1, "L_hand": _GAIN, "beta_hand": _NONNEG, "L0": _GAIN, "beta0": _NONNEG,
                   "tune_iterations": _N1, "tune_lr": _POS, "kf_q_x": _NONNEG, "kf_q_d": _NONNEG,
                   "kf_p0_d": _NONNEG, "spiral_n_samples": _N2, "spiral_Ts": _POS, "spiral_test": _SPIRAL3,
                   "spiral_x0": _X0, "spiral_tune_x0": _X0, "spiral_tune_samples": _N2, "spiral_N": _N1,
                   "spiral_noise_std": _POS, "spiral_L": _GAIN, "spiral_beta": _NONNEG,
                   "spiral_tune_iterations": _N1, "hand_L_grid": _vec(minimum=0.0), "hand_beta_grid": _vec(minimum=0.0)},
    "quick_start": {"T": _N2, "Ts": _POS, "N": _N1, "noise_std": _POS, "drop": _fraction,
                    "train_iterations": _N1, "tune_iterations": _N1},
    "tuned_gains": {"bottle_tune_throws": _N1, "bottle_tune_iterations": _N1, "bottle_tune_lr": _POS,
                    "bottle_hand_L_grid": _vec(minimum=0.0),
                    "bottle_hand_beta_grid": _vec(minimum=0.0), "quad_tune_cases": _N1,
                    "quad_L_grid": _vec(minimum=0.0), "quad_beta_grid": _vec(minimum=0.0),
                    "quad_hand_L_grid": _vec(minimum=0.0), "quad_hand_beta_grid": _vec(minimum=0.0)},
    "why_sec3": {"seed": _SEED, **_SPIRAL_TRAJ, "test": _SPIRAL3, **_SPIRAL_FB, "noise_std": _POS,
                 "s3_noise": _WHY_AXIS_POS, "s3_beta": _WHY_AXIS_POS, "s5_eps": _WHY_AXIS, "s5_eta": _WHY_AXIS_POS,
                 "L_sweep": _GAINS, "transient_time_constants": _POS, "conservative_ratio": _POS,
                 "residual_base": _SPIRAL3, "domega_range": _GRID, "deta_range": _GRID, "deps_range": _GRID,
                 "s8_L": _WHY_AXIS_POS, "s9_beta_steps": _WHY_AXIS_POS, "s9_beta_max": _POS,
                 "s9_noise": _WHY_AXIS_POS, "noise_draws": _N1, "t_switch": _POS, "before": _SPIRAL3,
                 "after": _SPIRAL3, "steady_window": _POS, "s10_band": _WHY_AXIS_POS, "s10_settle": _WHY_AXIS_POS},
    "why_bottle": {"L_grid": _SWEEP0, "beta_grid": _SWEEP0},
    "cascaded_tanks": {"data": _choice("real", "synthetic"), "synthetic_samples": _N2, "synthetic_noise": _NONNEG,
                       "seed": _SEED, "n_init": _N1, "arx_max_order": _N1, "seeds": _SEEDS2, "hidden": _WIDTHS,
                       "activation": _ACT, "x_center": C.finite, "x_scale": _POS, "u_center": C.finite,
                       "u_scale": _POS, "rate": _POS, "observer_gain": _vec(2, 0.0), "train_N": _N1,
                       "train_iterations": _N1, "train_lr": _POS, "L_start": _POS, "beta_start": _NONNEG,
                       "horizons": _horizons, "hand_L_grid": _vec(minimum=0.0), "hand_beta_grid": _vec(minimum=0.0),
                       "kf_q": _vec(2, 0.0), "kf_qd_grid": _vec(minimum=0.0), "kf_r": _POS, "overflow_after": _N1, "overflow_gap": _N0,
                       "series_N": _N1, "baseline_starts": partial(C.some_of, choices=("free", "encoder")),
                       "baseline_horizon": _N1},
    "why_tanks": {"L_grid": _vec(minimum=0.0), "beta_grid": _vec(minimum=0.0),
                  "windows": partial(C.some_of, choices=("all", "outside_overflow")),
                  "first_estimates": partial(C.some_of, choices=("first_level", "least_squares")),
                  "b5_starts": partial(C.some_of, choices=("free", "encoder")), "b5_horizons": _vec(minimum=1.0)},
    "why_beyond": {"objectives": partial(C.some_of, choices=("one_step", "multi_step", "judged")),
                   "multi_step_N": _N1, "min_seeds_grid": partial(C.number_list, minimum=2.0, distinct=True)},
})
"""Per notebook: parameter -> its check, ``check(name, value)`` (:mod:`fnnlib.checks`); every parameter of
every ``parameters`` cell but the injected ``profile``, ``out_dir``, ``data_dir`` and ``upstream_dirs``."""


# -- the values that depend on each other
def _need(condition: bool, message: str) -> None:
    if not condition:
        raise ValueError(message)


def _gain(p: Mapping[str, Any], n: int, Ts: float, N: int, *, L: str = "L", beta: str = "beta") -> None:
    """A gain that Theorem 1 / Eq. (25) accept, and a decay Eq. (11) accepts over N layers."""
    C.stable_gain(L, p[L], n=n, Ts=Ts, N=N, beta=p.get(beta, 0.0))


def _noise_levels(p: Mapping[str, Any]) -> None:
    """S3 is judged at noise_std, against the noise-free control."""
    sweep, std = p["noise_sweep"], p["noise_std"]
    _need(0.0 in sweep and std in sweep, f"noise_sweep must hold 0 and the judged level noise_std = {std}, "
                                         f"got {sweep}")


def _spiral(p: Mapping[str, Any]) -> None:
    _gain(p, 2, p["Ts"], p["N_max"])
    _need(p["N"] <= p["N_max"] < p["n_samples"], f"need 1 <= N <= N_max < n_samples, got N={p['N']}, "
                                                  f"N_max={p['N_max']}, n_samples={p['n_samples']}")
    _noise_levels(p)


def _theory(p: Mapping[str, Any]) -> None:
    C.stable_gain("L", p["L"], n=2, Ts=p["Ts"])
    for g in p["L_sweep"]:
        C.stable_gain("L_sweep", g, n=2, Ts=p["Ts"])


def _horizon(p: Mapping[str, Any]) -> None:
    C.horizon("N", p["N"], below=p["n_samples"], below_name="n_samples")


def _ablations(p: Mapping[str, Any]) -> None:
    _gain(p, 2, p["Ts"], p["N"])
    _horizon(p)
    end, w = (p["n_samples"] - 1) * p["Ts"], p["steady_window"]
    _need(w < p["t_switch"] < end - w, f"need steady_window < t_switch < the run's end {end:g} s - steady_window, "
                                       f"got t_switch={p['t_switch']}, steady_window={w}")


def _observers(p: Mapping[str, Any]) -> None:
    _gain(p, 2, p["Ts"], p["N"])
    _horizon(p)
    _need(p["settle"] < p["n_samples"], f"settle must be < n_samples = {p['n_samples']}, got {p['settle']}")
    _need(all(lo <= hi for lo, hi in zip(p["kf_tuning_low"], p["kf_tuning_high"])),
          f"kf_tuning_low must be <= kf_tuning_high, got {p['kf_tuning_low']} and {p['kf_tuning_high']}")


def _neural_feedback(p: Mapping[str, Any]) -> None:
    _gain(p, 2, p["Ts"], p["N"])
    _horizon(p)
    _need(p["dr_n_samples"] >= 2, f"dr_n_samples must be >= 2, got {p['dr_n_samples']}")


#: the one-factor changes a why_feedback_point may make to the paper profile's feedback training
WHY_FEEDBACK_CHANGES = ("optimizer", "lr_times", "iterations_times", "refresh_every")


def _why_feedback_point(p: Mapping[str, Any]) -> None:
    change = p["change"]
    _need(isinstance(change, Mapping) and set(change) <= set(WHY_FEEDBACK_CHANGES),
          f"change must be a mapping with keys among {', '.join(WHY_FEEDBACK_CHANGES)}, got {change!r}")
    _OPTIMIZER("change.optimizer", change.get("optimizer", "adam"))
    for key in ("lr_times", "iterations_times"):
        _POS(f"change.{key}", change.get(key, 1.0))
    _N1("change.refresh_every", change.get("refresh_every", 1))
    _horizon(p)
    _need(p["dr_n_samples"] >= 2, f"dr_n_samples must be >= 2, got {p['dr_n_samples']}")


def _bottle_data(p: Mapping[str, Any]) -> int:
    """The throws: real ones must be in ``data_dir`` with their pinned SHA-256. Returns the samples per throw."""
    if p["data"] == "synthetic":
        return p["synthetic_sizes"][2]
    C.data_files(Path(p.get("data_dir") or ".") / "bottle", {f: d for f, (_, _, d) in BOTTLE_FILES.items()},
                 how_to_get="Get the authors' published throws with `fnn-pipeline data fetch` (see data/README.md).")
    return next(iter(BOTTLE_FILES.values()))[1][1]


def _bottle(p: Mapping[str, Any]) -> None:
    _gain(p, 6, BOTTLE_TS, p["N"])
    n_samples = _bottle_data(p)
    C.horizon("N", p["N"], below=n_samples, below_name="the samples per throw")
    _need(p["batch_time"] <= n_samples, f"batch_time must be <= {n_samples} samples per throw, got {p['batch_time']}")


def _cascaded_tanks(p: Mapping[str, Any]) -> None:
    """The benchmark's file in ``data_dir`` (real data); the initial samples fit the record and the ARX orders."""
    samples = 1024
    if p["data"] == "real":
        C.data_files(Path(p.get("data_dir") or ".") / "cascaded_tanks", {TANKS_FILE: TANKS_SHA256},
                     how_to_get="Get the benchmark's file with `fnn-pipeline data fetch --tanks` (see data/README.md).")
    else:
        samples = p["synthetic_samples"]
    _need(max(p["horizons"]) + p["n_init"] < samples and p["train_N"] < samples // 2,
          f"the horizons (largest {max(p['horizons'])}) after n_init = {p['n_init']} samples and train_N = "
          f"{p['train_N']} must fit a record of {samples} samples")
    _need(p["n_init"] + p["baseline_horizon"] <= samples, f"baseline_horizon = {p['baseline_horizon']} after n_init = "
          f"{p['n_init']} samples must fit a record of {samples} samples")
    _need(p["series_N"] in p["horizons"], f"series_N = {p['series_N']} must be one of horizons = {p['horizons']}")
    _need(p["arx_max_order"] + 1 <= p["n_init"] < samples // 2,
          f"n_init (the measured samples a simulation starts from) must be in {p['arx_max_order'] + 1}.."
          f"{samples // 2 - 1} (above arx_max_order = {p['arx_max_order']}, below half a record of {samples}), "
          f"got {p['n_init']}")


def _quadrotor_learning(p: Mapping[str, Any]) -> None:
    _need(p["segment_length"] <= p["n_nodes"], f"segment_length must be in 1..{p['n_nodes']} (n_nodes), "
                                                f"got {p['segment_length']}")


def _quadrotor_mpc(p: Mapping[str, Any]) -> None:
    C.stable_gain("L", p["L"], n=12, Ts=p["Ts"])
    C.numbers("u_max", p["u_max"], minimum=0.0)
    _need(min(p["u_max"]) > 0, f"u_max must list positive thrust bounds, got {p['u_max']}")
    _need(p["u_max_judged"] in p["u_max"], f"u_max_judged = {p['u_max_judged']} must be one of u_max = {p['u_max']}")
    grid = p["Gamma_adapnn_grid"]  # AdapNN's validation grid (fnnlib.mpc.tuning)
    _need(len(set(grid)) == len(grid) and min(grid) > 0, f"Gamma_adapnn_grid must list distinct finite gains > 0, "
                                                         f"got {grid}")
    _need(min(p["R"]) > 0, f"R must be positive definite (every weight > 0), got {p['R']}")
    _need(min(p["truth_inertia"]) > 0, f"truth_inertia must be > 0 about every axis, got {p['truth_inertia']}")
    _need(p["qp"] != "osqp" or p["solver"] == "OSQP", f"qp 'osqp' solves with solver 'OSQP' only, got solver "
                                                      f"{p['solver']!r} (use qp 'cvxpy' for another solver)")
    length = p["steps"] * p["Ts"]
    _need(p["transient_s"] < length, f"transient_s must be shorter than the flight, steps * Ts = {length:g} s, "
                                     f"got {p['transient_s']}")


def _own_system(p: Mapping[str, Any]) -> None:
    C.horizon("N", p["N"], below=p["n_test"], below_name="n_test")
    _need(p["spiral_N"] < p["spiral_tune_samples"] <= p["spiral_n_samples"],
          "need 1 <= spiral_N < spiral_tune_samples <= spiral_n_samples, got "
          f"{p['spiral_N']}, {p['spiral_tune_samples']}, {p['spiral_n_samples']}")
    C.stable_gain("L0", p["L0"], n=2, Ts=p["Ts"])
    with warnings.catch_warnings():  # the hand-picked gain amplifies noise on purpose: the chapter shows it
        warnings.simplefilter("ignore", GainWarning)
        _gain(p, 2, p["Ts"], p["N"], L="L_hand", beta="beta_hand")
        _gain(p, 2, p["spiral_Ts"], p["spiral_N"], L="spiral_L", beta="spiral_beta")
        for L in p["hand_L_grid"]:  # every pair of the hand sweep, on both settings
            for beta in p["hand_beta_grid"]:
                for Ts, N in ((p["Ts"], p["N"]), (p["spiral_Ts"], p["spiral_N"])):
                    C.stable_gain("hand_L_grid", L, n=2, Ts=Ts, N=N, beta=beta)
    points = len(p["hand_L_grid"]) * len(p["hand_beta_grid"])
    _need(p["tune_iterations"] == p["spiral_tune_iterations"] == points,
          "B1 gives the tuned and the hand gains the same budget of evaluations: tune_iterations and "
          f"spiral_tune_iterations must equal the hand grid's {points} points, got {p['tune_iterations']}, "
          f"{p['spiral_tune_iterations']}")


def _quick_start(p: Mapping[str, Any]) -> None:
    C.horizon("N", p["N"], below=p["T"], below_name="T")
    if p["T"] < 60:  # a training segment: 20 samples to estimate from, 40 predicted (OutputRecipe's defaults)
        raise ValueError(f"T = {p['T']} is below the 60 samples of one training segment (20 + 40)")


def _why_sec3(p: Mapping[str, Any]) -> None:
    """The why grids of Sec. 3: every gain of S8 and of the L sweep stable, every decay rate over N layers,
    the S9 grid steps dividing its end, the S5 axes inside the (eta > 0) spirals, the switch as in ablations."""
    _gain(p, 2, p["Ts"], p["N"])
    _horizon(p)
    for name in ("s8_L", "L_sweep"):
        for g in p[name]:
            C.stable_gain(name, g, n=2, Ts=p["Ts"], N=p["N"], beta=p["beta"])
    for b in p["s3_beta"]:
        C.stable_gain("L", p["L"], n=2, Ts=p["Ts"], N=p["N"], beta=b)
    finest = min(p["s9_beta_steps"])
    for step in p["s9_beta_steps"]:
        k, n = step / finest, p["s9_beta_max"] / finest
        _need(abs(k - round(k)) < 1e-9 and abs(n - round(n)) < 1e-9 and round(n) >= 2 * round(k),
              f"s9_beta_steps must be whole multiples of the finest step that divide s9_beta_max "
              f"({p['s9_beta_max']}) into >= 3 values, got {p['s9_beta_steps']}")
    end, w = (p["n_samples"] - 1) * p["Ts"], p["steady_window"]
    _need(w < p["t_switch"] < end - w, f"need steady_window < t_switch < the run's end {end:g} s - steady_window, "
                                       f"got t_switch={p['t_switch']}, steady_window={w}")
    _need(p["noise_std"] in p["s3_noise"] and p["beta"] in p["s3_beta"],
          f"the S3 grid must pass through the profile's point: noise_std = {p['noise_std']} in s3_noise, "
          f"beta = {p['beta']} in s3_beta")


def _tuned_gains(p: Mapping[str, Any]) -> None:
    """Only the tuning's own settings: the data and flights come from the upstream runs (whose Ts and N are
    checked there); here every gain of a grid must be > 0 (``sweep_gains`` refuses the rest)."""
    for name in ("bottle_hand_L_grid", "quad_L_grid", "quad_hand_L_grid"):
        _need(min(p[name]) > 0, f"{name} must list gains > 0, got {p[name]}")
    bottle_points = len(p["bottle_hand_L_grid"]) * len(p["bottle_hand_beta_grid"])
    _need(p["bottle_tune_iterations"] == bottle_points,
          "B1 gives the tuned and the hand gains the same budget of evaluations: bottle_tune_iterations must "
          f"equal the bottle hand grid's {bottle_points} points, got {p['bottle_tune_iterations']}")
    tuned, hand = (len(p[f"quad_{h}L_grid"]) * len(p[f"quad_{h}beta_grid"]) for h in ("", "hand_"))
    tuned *= p["quad_tune_cases"]  # one flight per grid point and validation case
    _need(tuned == hand, f"B1 gives the tuned and the hand gains the same budget of evaluations: the quadrotor's "
                         f"tuning flies {tuned} flights (grid points x quad_tune_cases), its hand grid has {hand} points")


def _why_quadrotor_point(p: Mapping[str, Any]) -> None:
    """The adaptive gains of the why grid: > 0 (the flight test's own gains must be among them: checked against
    its run record in the notebook)."""
    for name in ("Gamma_grid", "Gamma_adapnn_grid"):
        _need(len(p[name]) >= 2 and min(p[name]) > 0, f"{name} must list at least 2 gains > 0, got {p[name]}")


def _aggregate(p: Mapping[str, Any]) -> None:
    """An aggregate of a why grid: no settings of its own (its points' records carry them)."""


def _why_grid(p: Mapping[str, Any], *names: str) -> None:
    """A why grid's axes: at least 2 values each (a grid passes through the profile's point and leaves it)."""
    for name in names:
        _need(len(p[name]) >= 2, f"{name} must list at least 2 values (a grid axis), got {p[name]}")


def _why_bottle(p: Mapping[str, Any]) -> None:
    _why_grid(p, "L_grid", "beta_grid")
    _need(min(p["L_grid"]) > 0, f"L_grid must list gains > 0 (L = 0 is the open loop, judged anyway), got {p['L_grid']}")


def _why_tanks(p: Mapping[str, Any]) -> None:
    _why_grid(p, "L_grid", "beta_grid", "windows", "first_estimates", "b5_starts", "b5_horizons")
    _need(min(p["L_grid"]) > 0, f"L_grid must list gains > 0 (L = 0 is the open loop, judged anyway), got {p['L_grid']}")
    _need(all(float(h).is_integer() for h in p["b5_horizons"]), f"b5_horizons must list whole samples, got {p['b5_horizons']}")
    _need("all" in p["windows"] and "first_level" in p["first_estimates"],
          "windows must hold 'all' and first_estimates 'first_level' (the chapter's own point, checked against its numbers)")


def _why_beyond(p: Mapping[str, Any]) -> None:
    _why_grid(p, "objectives", "min_seeds_grid")
    _need(all(float(k).is_integer() for k in p["min_seeds_grid"]),
          f"min_seeds_grid must list whole numbers of seeds, got {p['min_seeds_grid']}")


RELATIONS: Mapping[str, Callable[[Mapping[str, Any]], None]] = MappingProxyType({
    "spiral": _spiral, "theory": _theory, "ablations": _ablations, "observers": _observers,
    "neural_feedback": _neural_feedback, "bottle": _bottle, "quadrotor_learning": _quadrotor_learning,
    "quadrotor_mpc": _quadrotor_mpc, "own_system": _own_system, "tuned_gains": _tuned_gains,
    "quick_start": _quick_start, "why_feedback_point": _why_feedback_point, "why_feedback": _horizon,
    "why_quadrotor_point": _why_quadrotor_point, "why_quadrotor": _aggregate,
    "why_sec3": _why_sec3,
    "why_bottle": _why_bottle, "why_beyond": _why_beyond, "cascaded_tanks": _cascaded_tanks,
    "why_tanks": _why_tanks,
})
"""Per notebook: the checks of values that depend on each other, run after each value passed its own check."""


# -- the notebooks' names
_CALL = re.compile(r"check_notebook_settings\(\s*[\"']([A-Za-z0-9_]+)[\"']")


def _known(notebook: str) -> str:
    """``notebook`` (``"spiral"``; a leading ``"03_"`` or a ``.ipynb`` suffix is ignored), if the book has it."""
    name = re.sub(r"^\d+_", "", Path(notebook).stem)
    if name not in VALUE_CHECKS:
        raise ValueError(f"no notebook of the book is named {notebook!r}; the notebooks are "
                         f"{', '.join(VALUE_CHECKS)}")
    return name


def notebook_name(path: str | Path) -> str | None:
    """The name a notebook file (``.ipynb``) gives :func:`check_notebook_settings`, or None if it calls it not.

    A notebook that does not call it (one of your own, run by the pipeline) has no presets and no value checks
    but the types of its ``parameters`` cell. Raises ``ValueError`` if the name it gives is not the book's.
    """
    try:
        cells = json.loads(Path(path).read_text(encoding="utf-8")).get("cells", [])
    except (OSError, ValueError, AttributeError):
        return None  # fnnbook.params.read_parameters says what is wrong with the file
    source = "".join("".join(c.get("source", "")) for c in cells if c.get("cell_type") == "code")
    found = _CALL.search(source)
    return None if found is None else _known(found.group(1))


def _plain(value: Any) -> Any:
    """Tuples (the presets' read-only sequences) as lists, the type a notebook parameter has."""
    return [_plain(v) for v in value] if isinstance(value, (tuple, list)) else value


def notebook_presets(notebook: str) -> dict[str, Any]:
    """The presets of one notebook (``"spiral"``; a leading ``"03_"`` or a suffix is ignored), as plain values.

    Raises ``ValueError`` for a name that is not a notebook of the book.
    """
    return {k: _plain(v) for k, v in NOTEBOOK_PRESETS.get(_known(notebook), {}).items()}


def fill_presets(notebook: str, settings: MutableMapping[str, Any]) -> dict[str, Any]:
    """Fill, in place, every preset parameter of ``settings`` that is ``None`` (or absent) with its paper value.

    Returns the values filled (empty when the runner already injected every value).
    """
    filled = {k: v for k, v in notebook_presets(notebook).items() if settings.get(k) is None}
    settings.update(filled)
    return filled


def check_notebook_settings(notebook: str, settings: Mapping[str, Any]) -> None:
    """Fill a notebook's ``None`` settings with the paper presets, then check them; raise on the first bad value.

    Parameters
    ----------
    notebook : str
        The notebook's name (``"spiral"``; a leading ``"03_"`` or a ``.ipynb`` suffix is ignored).
    settings : mapping
        Its parameters, e.g. ``globals()`` right after the parameters cell. A mutable mapping gets its
        ``None`` presets filled in place (:func:`fill_presets`; a run by hand, the runner injects them) and
        the filled values are printed; a read-only one is checked with them.

    Raises
    ------
    ValueError
        A name that is not a notebook of the book, a setting missing, or a value the notebook cannot use,
        naming the setting (:class:`~fnnlib.feedback.GainError` for an unstable gain).
    MissingDataError
        Data files the settings need are not in ``data_dir``.
    fnnlib.data.bottle.DataError
        A data file is there but is not the published one (its SHA-256).
    """
    name = _known(notebook)
    if isinstance(settings, MutableMapping):
        filled = fill_presets(name, settings)
        if filled:
            print("paper presets: " + ", ".join(f"{k} = {v!r}" for k, v in filled.items()))
    else:
        settings = {**settings, **{k: v for k, v in notebook_presets(name).items() if settings.get(k) is None}}
    checks = VALUE_CHECKS[name]
    missing = [k for k in checks if k not in settings]
    if missing:
        raise ValueError(f"notebook {name!r}: setting(s) missing: {', '.join(missing)}")
    for key, check in checks.items():
        check(key, settings[key])
    RELATIONS[name](settings)
