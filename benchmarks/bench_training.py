"""ms per training iteration of the spiral neural ODE, per solver / gradient choice.

Paper settings (App. A.3.2): MLP 2-50-50-2 ReLU, RMSprop 1e-3, batch 20 segments
of 10 samples from the nominal spiral (1000 samples, Ts = 0.01).

    .venv/bin/python benchmarks/bench_training.py [--iterations 40]
"""

from __future__ import annotations

import argparse
import json

import torch

import fnnlib as F
from fnnlib.seeding import seed_everything
from fnnlib.systems import Spiral
from fnnlib.training import PAPER_SPIRAL_RECIPE

CHOICES = [
    # (solver, adjoint, seminorm, rtol, atol)
    ("dopri5", True, True, 1e-7, 1e-9),
    ("dopri5", True, False, 1e-7, 1e-9),
    ("dopri5", True, True, 1e-5, 1e-6),
    ("dopri5", False, False, 1e-7, 1e-9),
    ("rk4", True, False, 0, 0),
    ("rk4", False, False, 0, 0),
    ("euler", False, False, 0, 0),
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--iterations", type=int, default=40)
    ap.add_argument("--warmup", type=int, default=200, help="iterations of dopri5 direct training first, so the "
                    "timed model is as far along as in the middle of the paper's run")
    args = ap.parse_args()
    t = torch.arange(1000, dtype=torch.float64) * 0.01
    x = Spiral(2.0, 0.1, 0.0).simulate(torch.tensor([9.0, 0.0]), t).float()
    seed_everything(0)
    base = F.NeuralODE(2, (50, 50), "relu")
    recipe = PAPER_SPIRAL_RECIPE.replace(rtol=1e-7, atol=1e-9)
    F.train_neural_ode(base, t.float(), x, recipe.replace(iterations=args.warmup, adjoint=False), seed=0, progress=False)
    rows = []
    for method, adjoint, semi, rtol, atol in CHOICES:
        model = F.NeuralODE(2, (50, 50), "relu")
        model.load_state_dict(base.state_dict())
        h = F.train_neural_ode(model, t.float(), x, recipe.replace(iterations=args.iterations, method=method,
                               adjoint=adjoint, adjoint_seminorm=semi, rtol=rtol or 1e-7, atol=atol or 1e-9),
                               seed=1, progress=False)
        row = {"solver": method, "adjoint": adjoint, "seminorm": semi, "rtol": rtol, "atol": atol,
               "ms_per_iteration": round(h.ms_per_iteration, 1),
               "paper_400_iterations_s": round(h.ms_per_iteration * 400 / 1000, 1)}
        rows.append(row)
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
