r"""The flight records of the why grid of Q3-Q5 (Sec. 5.2.2, App. A.5.4, A.9; Eqs. (28)-(30)).

The ``why_quadrotor_point`` notebook flies the paper profile's units at one thrust bound and records, per cost,
what each model's flights give (:func:`flight_numbers`); the two adaptive models are flown once per gain, so
their entries are keyed by the gain. The ``why_quadrotor`` notebook reads the record back at chosen gains
(:func:`at_gains`) and applies the claims' rules (:mod:`fnnbook.rules.quadrotor`).

One cost's record: ``{model: numbers}`` for the models without an adaptive gain, ``{"AdapNN": {str(gain):
numbers}, "AdapFNN": {str(Gamma): numbers}}`` for AdapNN's gain (App. A.5.4) and AdapFNN's :math:`\Gamma` of
Eq. (30); ``numbers`` holds one list entry per unit.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from torch import nn

import fnnlib.quadrotor.mpc as M

__all__ = ["ADAPTIVE", "at_gains", "flight_numbers", "fly_record"]

#: the models flown once per value of their adaptive gain: AdapNN's (App. A.5.4), AdapFNN's Gamma (Eq. (30))
ADAPTIVE = ("AdapNN", "AdapFNN")


def flight_numbers(runs: Sequence[M.FlightResult]) -> dict[str, list]:
    """Per flight (one a unit): the mean per-axis tracking RMSE (:func:`fnnlib.quadrotor.mpc.tracking_rmse`), the first-step
    acceleration prediction RMSE (Fig. S8, :func:`fnnlib.quadrotor.mpc.acc_pred_rmse`) and whether the flight diverged."""
    return {"rmse": [M.tracking_rmse(r.x, r.x_ref)["mean_axis"] for r in runs],
            "acc": [M.acc_pred_rmse(r) for r in runs], "diverged": [bool(r.diverged) for r in runs]}


def at_gains(record: Mapping[str, Any], name: str, adapnn_gamma: float, Gamma: float) -> dict[str, list]:
    """The numbers of model ``name`` in one cost's ``record``: AdapNN's at its gain ``adapnn_gamma``, AdapFNN's at
    ``Gamma`` (Eq. (30)), every other model's as flown (it has no adaptive gain)."""
    gain = dict(zip(ADAPTIVE, (adapnn_gamma, Gamma))).get(name)
    if gain is None:
        return record[name]
    if str(gain) not in record[name]:
        raise KeyError(f"{name} was not flown at the gain {gain:g}: flown at {sorted(record[name])}")
    return record[name][str(gain)]


def fly_record(nets: Sequence[tuple[Any, nn.Module]], mlps: Sequence[tuple[Any, nn.Module]], *,
               tests: Sequence[M.FlightTest], mpc: M.MPC, model_settings: Mapping[str, Any], adapnn_gamma: float,
               names: Sequence[str], adapnn_grid: Sequence[float], Gamma_grid: Sequence[float],
               transient: int) -> dict[str, Any]:
    r"""One cost's record (the layout :func:`at_gains` reads) for one set of networks under ``mpc``: the models in
    ``names`` flown once per unit (:func:`fnnlib.quadrotor.mpc.paired_units`, AdapNN at ``adapnn_gamma``), AdapNN once per gain
    of ``adapnn_grid`` (App. A.5.4) and AdapFNN once per :math:`\Gamma` of ``Gamma_grid`` (Eq. (30)), each AdapFNN
    flight with the share of its steps inside Theorem 2's bound after ``transient`` steps
    (:func:`fnnlib.quadrotor.mpc.theorem2_check` at ``model_settings["L"]``)."""
    fly = dict(tests=tests, mpc=mpc)
    base = M.paired_units(nets, mlps, **fly, model_settings=model_settings, adapnn_gamma=adapnn_gamma, only=names)
    rec: dict[str, Any] = {n: flight_numbers(r) for n, r in base.items()}
    rec["AdapNN"] = {str(g): flight_numbers(M.paired_units(nets, mlps, **fly, model_settings=model_settings,
                                                           adapnn_gamma=g, only=["AdapNN"])["AdapNN"])
                     for g in adapnn_grid}
    rec["AdapFNN"] = {}
    for G in Gamma_grid:
        runs = M.paired_units(nets, mlps, **fly, model_settings={**model_settings, "Gamma": G},
                              adapnn_gamma=adapnn_gamma, only=["AdapFNN"])["AdapFNN"]
        rec["AdapFNN"][str(G)] = flight_numbers(runs) | {
            "theorem2_inside": [M.theorem2_check(r, model_settings["L"], transient)["inside_fraction"] for r in runs]}
    return rec
