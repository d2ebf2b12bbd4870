"""Cascade prediction over a whole trajectory: batched (fnnlib) vs the straightforward loop.

Paper settings: 1000-sample test spiral, N = 50, L = 20, beta = 0.02, MLP 2-50-50-2.

    .venv/bin/python benchmarks/bench_cascade.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import json
import time

import torch

import fnnlib as F
from fnnlib.feedback import cascade_predict_loop, Gains
from fnnlib.seeding import seed_everything
from fnnlib.systems import Spiral


def best_of(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def spiral_case(description: str):
    """The command line (--repeats, --T, --N) and the paper's test case: an untrained 2-50-50-2 model, the test spiral."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--T", type=int, default=1000)
    ap.add_argument("--N", type=int, default=50)
    args = ap.parse_args()
    seed_everything(0)
    model = F.NeuralODE(2, (50, 50), "relu")
    t = torch.arange(args.T, dtype=torch.float64) * 0.01
    x = Spiral(3.0, 0.05, 10.0).simulate(torch.tensor([9.0, 0.0]), t).float()
    return args, model, x


def main() -> None:
    args, model, x = spiral_case(__doc__.splitlines()[0])
    batched = best_of(lambda: F.cascade_predict(model, x, 0.01, args.N, F.Gains(20.0, 0.02)), args.repeats)
    loop = best_of(lambda: cascade_predict_loop(model, x, 0.01, args.N, Gains(20.0, 0.02)), max(1, args.repeats // 5))
    # agreement, in float64 (float32 rounding is amplified by up to (1 + Ts L)^N along the cascade)
    m64, x64 = model.double(), x.double()
    a = F.cascade_predict(m64, x64, 0.01, args.N, F.Gains(20.0, 0.02))
    b = cascade_predict_loop(m64, x64, 0.01, args.N, Gains(20.0, 0.02))
    diff = float((a - b).abs().max() / b.abs().max())
    print(json.dumps({"T": args.T, "N": args.N, "batched_ms": round(1000 * batched, 2),
                      "loop_ms": round(1000 * loop, 1), "speedup": round(loop / batched, 1),
                      "max_rel_diff_float64": diff}))


if __name__ == "__main__":
    main()
