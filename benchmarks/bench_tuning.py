"""The differentiable cascade (cascade_forward) against today's cascade_predict, and one tune_gains step.

Paper settings: 1000-sample test spiral, N = 50, L = 20, beta = 0.02, MLP 2-50-50-2, float32.
Reports the best of ``--repeats`` wall times of: cascade_predict (no graph), cascade_forward under no_grad,
cascade_forward with the graph built, and forward + backward (what one tune_gains iteration costs).

    .venv/bin/python benchmarks/bench_tuning.py [--repeats 5]
"""

from __future__ import annotations

import json
import warnings

import torch

import fnnlib as F
from fnnlib.feedback import CascadeGains, GainWarning, cascade_forward
from bench_cascade import best_of, spiral_case


def main() -> None:
    args, model, x = spiral_case(__doc__.splitlines()[0])
    for p in model.parameters():
        p.requires_grad_(False)  # frozen, as tune_gains keeps it
    Ts = 0.01
    gains = CascadeGains(2, Ts, L0=20.0, beta0=0.02)
    L, beta = torch.tensor(gains.values()["L"]), gains.values()["beta"]
    warnings.simplefilter("ignore", GainWarning)

    def backward():
        gains.zero_grad()
        F.feedback.prediction_loss(cascade_forward(model, x, Ts, args.N, gains), x, args.N).backward()

    def forward_no_grad():
        with torch.no_grad():
            cascade_forward(model, x, Ts, args.N, gains)

    res = {"T": args.T, "N": args.N,
           "cascade_predict_ms": best_of(lambda: F.cascade_predict(model, x, Ts, args.N, F.Gains(L, beta)), args.repeats),
           "forward_no_grad_ms": best_of(forward_no_grad, args.repeats),
           "forward_graph_ms": best_of(lambda: cascade_forward(model, x, Ts, args.N, gains), args.repeats),
           "forward_backward_ms": best_of(backward, args.repeats)}
    with torch.no_grad():
        diff = float((cascade_forward(model, x, Ts, args.N, gains) - F.cascade_predict(model, x, Ts, args.N,
                                                                                       F.Gains(L, beta)))
                     .abs().max())
    out = {k: round(1000 * v, 2) if k.endswith("_ms") else v for k, v in res.items()}
    out["max_abs_diff"] = diff
    print(json.dumps(out))


if __name__ == "__main__":
    main()
