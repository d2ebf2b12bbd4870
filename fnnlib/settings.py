"""Each notebook's settings, checked before any work starts.

One function, :func:`check_notebook_settings`, holds the value checks of
every notebook (a stable feedback gain, a horizon that fits the data, sizes
of at least one). A notebook calls it right after its ``parameters`` cell;
``fnn-pipeline check`` and the start of ``fnn-pipeline run`` call it for
every task before any task runs, so a bad value fails in seconds, not after
the upstream tasks have trained.

>>> check_notebook_settings("spiral", {"L": -1.0, "Ts": 0.01, "N": 50, "N_max": 100, "beta": 0.02,
...                                    "n_samples": 1000})
Traceback (most recent call last):
...
fnnlib.feedback.gains.GainError: ...
"""

from __future__ import annotations

import math

import re
import warnings
from collections.abc import Callable, Mapping, MutableMapping
from types import MappingProxyType
from pathlib import Path
from typing import Any

from fnnlib import quadrotor_presets as QP
from fnnlib import spiral_presets as SP
from fnnlib.data.bottle import BOTTLE_FILES, TS as BOTTLE_TS, DataError
from fnnlib.feedback import GainWarning, check_gain, decayed_gains
from fnnlib.sweeps import colon_range
from fnnlib.systems.quadrotor import TEST_TRUTH, TRAINING_TRUTH
from fnnlib.training import PAPER_BOTTLE_RECIPE, PAPER_SPIRAL_RECIPE

__all__ = ["NOTEBOOK_PRESETS", "MissingDataError", "check_notebook_settings", "fill_presets", "notebook_presets"]


class MissingDataError(DataError):
    """A notebook needs data files that are not in its data directory."""


def _at_least(p: Mapping[str, Any], minimum: int, *names: str) -> None:
    for name in names:
        if name in p and not (isinstance(p[name], int) and p[name] >= minimum):
            raise ValueError(f"{name} must be an integer >= {minimum}, got {p[name]!r}")


def _sizes(p: Mapping[str, Any], *names: str) -> None:
    """Layer widths: a list of integers >= 1."""
    for name in names:
        if name in p and (not p[name] or not all(isinstance(h, int) and h >= 1 for h in p[name])):
            raise ValueError(f"{name} must list layer widths >= 1, got {p[name]!r}")


def _gain_and_decay(p: Mapping[str, Any], n: int, Ts: float, N: int) -> None:
    """A gain that Theorem 1 / Eq. (25) accept, and a decay Eq. (11) accepts over N layers."""
    decayed_gains(check_gain(p["L"], n, Ts), N, p.get("beta", 0.0))


def _horizon(p: Mapping[str, Any], N: int) -> None:
    if not 1 <= N < p["n_samples"]:
        raise ValueError(f"need 1 <= N < n_samples, got N={N}, n_samples={p['n_samples']}")


def _seeds(p: Mapping[str, Any]) -> None:
    """``seeds``: at least two distinct integers (a paired comparison over seeds needs two, B2)."""
    if "seeds" not in p:
        return
    seeds = p["seeds"]
    if not isinstance(seeds, list) or len(seeds) < 2 or len(set(seeds)) != len(seeds) or not all(
            isinstance(s, int) for s in seeds):
        raise ValueError(f"seeds must list at least two distinct integers, got {seeds!r}")


def _grids(p: Mapping[str, Any]) -> None:
    """Every ``*_range`` is a non-empty grid ``{start: step: stop}``."""
    for name, value in p.items():
        if name.endswith("_range") and isinstance(value, list):
            if len(value) != 3:
                raise ValueError(f"{name} must be [start, step, stop], got {value!r}")
            colon_range(*value)


def _spiral(p: Mapping[str, Any]) -> None:
    _gain_and_decay(p, 2, p["Ts"], p["N_max"])
    if not 1 <= p["N"] <= p["N_max"] < p["n_samples"]:
        raise ValueError(f"need 1 <= N <= N_max < n_samples, got N={p['N']}, N_max={p['N_max']}, "
                         f"n_samples={p['n_samples']}")
    _at_least(p, 1, "iterations", "batch_size", "batch_time")
    _sizes(p, "hidden")
    _seeds(p)
    if "noise_sweep" in p:  # S3 is judged at noise_std, against the noise-free control
        sweep, std = p["noise_sweep"], p["noise_std"]
        if 0.0 not in sweep or std not in sweep or std <= 0:
            raise ValueError(f"noise_sweep must hold 0 and the judged level noise_std > 0, got {sweep} and {std}")


def _theory(p: Mapping[str, Any]) -> None:
    for g in [p["L"], *p.get("L_sweep", [])]:
        check_gain(g, 2, p["Ts"])
    _at_least(p, 2, "n_samples")


def _ablations(p: Mapping[str, Any]) -> None:
    _grids(p)
    _gain_and_decay(p, 2, p["Ts"], p["N"])
    _horizon(p, p["N"])
    _at_least(p, 1, "noise_draws")


def _observers(p: Mapping[str, Any]) -> None:
    _gain_and_decay(p, 2, p["Ts"], p["N"])
    _horizon(p, p["N"])
    _at_least(p, 1, "repeats")
    _at_least(p, 0, "settle")
    _at_least(p, 2, "kf_tuning_cases")


def _neural_feedback(p: Mapping[str, Any]) -> None:
    _grids(p)
    _gain_and_decay(p, 2, p["Ts"], p["N"])
    _horizon(p, p["N"])
    _at_least(p, 1, "iterations", "batch_size", "batch_time", "fb_iterations", "fb_batch_size", "refresh_every",
              "dr_n_samples")
    _sizes(p, "hidden", "fb_hidden")


def _bottle_data(data: str, data_dir: str | None) -> None:
    """``data`` is ``"real"`` (then the throws must be in ``data_dir``) or ``"synthetic"``."""
    if data not in ("real", "synthetic"):
        raise ValueError(f"data must be 'real' or 'synthetic', got {data!r}")
    if data == "real":
        folder = Path(data_dir or ".") / "bottle"
        missing = [f for f in BOTTLE_FILES if not (folder / f).is_file()]
        if missing:
            raise MissingDataError(f"data missing: {', '.join(missing)} not in {folder}. Get the authors' "
                                   "published throws with `fnn-pipeline data fetch` (see data/README.md).")


def _bottle(p: Mapping[str, Any]) -> None:
    if p["data"] not in ("real", "synthetic"):
        raise ValueError(f"data must be 'real' or 'synthetic', got {p['data']!r}")
    _gain_and_decay(p, 6, BOTTLE_TS, p["N"])
    _at_least(p, 1, "iterations", "batch_size", "batch_time")
    _sizes(p, "hidden")
    _seeds(p)
    _bottle_data(p["data"], p.get("data_dir"))


def _quadrotor_learning(p: Mapping[str, Any]) -> None:
    seeds = p["seeds"]
    if not seeds or len(set(seeds)) != len(seeds):
        raise ValueError(f"seeds must be distinct and non-empty, got {seeds}")
    _at_least(p, 1, "n_flights", "n_nodes", "val_flights", "val_nodes", "epochs", "batch_size", "val_every",
              "mlp_epochs", "truth_substeps")
    if not 1 <= p["segment_length"] <= p["n_nodes"]:
        raise ValueError(f"segment_length must be in 1..{p['n_nodes']}, got {p['segment_length']}")
    _sizes(p, "hidden")


def _quadrotor_mpc(p: Mapping[str, Any]) -> None:
    Ts = p["Ts"]
    check_gain(p["L"], 12, Ts)
    if not p["u_max"] or min(p["u_max"]) <= 0:
        raise ValueError(f"u_max must list positive thrust bounds, got {p['u_max']}")
    if p["u_max_judged"] not in p["u_max"]:
        raise ValueError(f"u_max_judged = {p['u_max_judged']} must be one of u_max = {p['u_max']}")
    if not p["costs"] or any(c not in ("as_written", "as_flown") for c in p["costs"]):
        raise ValueError(f"costs must list 'as_written' and/or 'as_flown', got {p['costs']}")
    _at_least(p, 1, "steps", "N", "truth_substeps", "validation_flights", "validation_steps", "validation_vehicles")
    _at_least(p, 0, "disturbance_draws")
    grid = p.get("Gamma_adapnn_grid", [1.0])  # AdapNN's validation grid and tie tolerance (fnnlib.mpc.tuning)
    if not grid or len(set(grid)) != len(grid) or any(not (math.isfinite(g) and g > 0) for g in grid):
        raise ValueError(f"Gamma_adapnn_grid must list distinct finite gains > 0, got {grid}")
    if not (math.isfinite(p.get("Gamma_rtol", 0.0)) and p.get("Gamma_rtol", 0.0) >= 0):
        raise ValueError(f"Gamma_rtol must be finite and >= 0, got {p['Gamma_rtol']}")


def _own_system(p: Mapping[str, Any]) -> None:
    if len(p["seeds"]) < 2 or len(set(p["seeds"])) != len(p["seeds"]):
        raise ValueError(f"seeds must be at least 2 distinct values (wins are paired over seeds), got {p['seeds']}")
    if not 1 <= p["N"] < p["n_test"]:
        raise ValueError(f"need 1 <= N < n_test, got N={p['N']}, n_test={p['n_test']}")
    if not 1 <= p["spiral_N"] < p["spiral_tune_samples"] <= p["spiral_n_samples"]:
        raise ValueError("need 1 <= spiral_N < spiral_tune_samples <= spiral_n_samples, got "
                         f"{p['spiral_N']}, {p['spiral_tune_samples']}, {p['spiral_n_samples']}")
    _at_least(p, 1, "n_train", "iterations", "tune_iterations", "spiral_tune_iterations")
    _sizes(p, "hidden")
    with warnings.catch_warnings():  # the hand-picked gain amplifies noise on purpose: the chapter shows it
        warnings.simplefilter("ignore", GainWarning)
        check_gain(p["L_hand"], 2, p["Ts"], N=p["N"], beta=p["beta_hand"])
        check_gain(p["spiral_L"], 2, p["spiral_Ts"], N=p["spiral_N"], beta=p["spiral_beta"])


def _tuned_gains(p: Mapping[str, Any]) -> None:
    """Only the tuning's own settings: the data, hand-tuned gains and flights come from the upstream runs."""
    _at_least(p, 1, "bottle_tune_throws", "bottle_tune_iterations", "quad_tune_flights", "quad_tune_iterations")
    for name in ("bottle_tune_lr", "quad_tune_lr"):
        if not p[name] > 0:
            raise ValueError(f"{name} must be > 0, got {p[name]!r}")


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
})
"""Per notebook: the parameters its ``parameters`` cell leaves at ``None``, and the paper value each takes.

A value several notebooks (or a notebook and the library) share is written once, in
:mod:`fnnlib.spiral_presets`, :mod:`fnnlib.quadrotor_presets`, the vehicles of :mod:`fnnlib.systems.quadrotor`
or the training recipes; this table only says which parameter takes which. A profile may override any of them."""


def _plain(value: Any) -> Any:
    """Tuples (the presets' read-only sequences) as lists, the type a notebook parameter has."""
    return [_plain(v) for v in value] if isinstance(value, (tuple, list)) else value


def notebook_presets(notebook: str) -> dict[str, Any]:
    """The presets of one notebook (``"spiral"``; a leading ``"03_"`` or a suffix is ignored), as plain values."""
    name = re.sub(r"^\d+_", "", Path(notebook).stem)
    return {k: _plain(v) for k, v in NOTEBOOK_PRESETS.get(name, {}).items()}


def fill_presets(notebook: str, settings: MutableMapping[str, Any]) -> dict[str, Any]:
    """Fill, in place, every preset parameter of ``settings`` that is ``None`` (or absent) with its paper value.

    Returns the values filled (empty when the runner already injected every value).
    """
    filled = {k: v for k, v in notebook_presets(notebook).items() if settings.get(k) is None}
    settings.update(filled)
    return filled


_CHECKS: dict[str, Callable[[Mapping[str, Any]], None]] = {
    "spiral": _spiral, "theory": _theory, "ablations": _ablations, "observers": _observers,
    "neural_feedback": _neural_feedback, "bottle": _bottle, "quadrotor_learning": _quadrotor_learning,
    "quadrotor_mpc": _quadrotor_mpc, "own_system": _own_system, "tuned_gains": _tuned_gains,
}


def check_notebook_settings(notebook: str, settings: Mapping[str, Any]) -> None:
    """Fill a notebook's ``None`` settings with the paper presets, then check them; raise on the first bad value.

    Parameters
    ----------
    notebook : str
        The notebook's name (``"spiral"``; a leading ``"03_"`` or a
        ``.ipynb`` suffix is ignored). A notebook without checks passes.
    settings : mapping
        Its parameters, e.g. ``globals()`` right after the parameters cell. A mutable mapping gets its
        ``None`` presets filled in place (:func:`fill_presets`; a run by hand, the runner injects them) and
        the filled values are printed; a read-only one is checked with them.

    Raises
    ------
    ValueError
        A value the notebook cannot use (:class:`~fnnlib.observers.GainError`
        for an unstable gain), or a setting left ``None`` that has no preset.
    MissingDataError
        Data files the settings need are not in ``data_dir``.
    """
    name = re.sub(r"^\d+_", "", Path(notebook).stem)
    if isinstance(settings, MutableMapping):
        filled = fill_presets(name, settings)
        if filled:
            print("paper presets: " + ", ".join(f"{k} = {v!r}" for k, v in filled.items()))
    else:
        settings = {**settings, **{k: v for k, v in notebook_presets(name).items() if settings.get(k) is None}}
    check = _CHECKS.get(name)
    if check is not None:
        try:
            check(settings)
        except KeyError as exc:
            raise ValueError(f"notebook {name!r}: setting {exc.args[0]!r} is missing") from exc
