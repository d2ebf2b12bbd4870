"""The paper's own experiments, apart from the method: its settings and the sweeps of its ablations.

* :mod:`~fnnlib.paper.spiral_presets`: every Sec. 3-4 setting of the paper (the spiral of Eq. (26),
  App. A.3 and A.7, the authors' release), written once.
* :mod:`~fnnlib.paper.sweeps`: the MATLAB-style grids and uncertainty levels of Sec. 3.4 and App. A.3
  (:func:`colon_range`, :func:`paired_levels`, :func:`simulate_levels`, :func:`offset_spirals`), and the
  sweeps of the ablations and whys over gains, decay rates and levels run on them.

The paper's systems are in :mod:`fnnlib.systems` (the spiral of Eq. (26), the switched spirals of Fig. S12,
the thrown object of Sec. 5.1), its bottle data in :mod:`fnnlib.data`, the Sec. 5 quadrotor stack in
:mod:`fnnlib.quadrotor`, and the authors' released networks in :mod:`fnnlib.release`.

The sweeps' names are loaded on first use (PEP 562): ``from fnnlib.paper import spiral_presets`` does not
import torch.
"""

from __future__ import annotations

from typing import Any

__all__ = ["cascade_position_errors", "colon_range", "level_errors", "n_step_gain_sweep", "n_step_rmse",
           "offset_spirals", "outward_increase_fraction", "paired_levels", "position_gain_sweep",
           "position_gain_tuning", "residual_level_runs", "simulate_levels", "sweep_errors", "switched_spiral_run"]


def __getattr__(name: str) -> Any:
    if name in __all__:
        from fnnlib.paper import sweeps  # noqa: PLC0415 (torch)

        value = getattr(sweeps, name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'fnnlib.paper' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
