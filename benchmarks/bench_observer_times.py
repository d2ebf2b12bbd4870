"""The observers on a long record with uneven sample times: seconds per call, Ts against t.

A 2-50-50-2 tanh neural ODE (untrained, seed 0), one record of T samples, position only (``y = C x``,
C = [1, 0]) for the filters that take it, full state for the rest. The times are ``k Ts`` jittered by up to
+-30 % of Ts (every interval distinct). One torch thread; each observer is warmed up on 50 samples first.

    .venv/bin/python benchmarks/bench_observer_times.py [--T 10000] [--repeats 1]
"""

from __future__ import annotations

import argparse
import json
import time

import torch

import fnnlib as F
from fnnlib.models import NeuralFeedback, NeuralODE


def best_of(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--T", type=int, default=10_000)
    ap.add_argument("--N", type=int, default=10)
    ap.add_argument("--repeats", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(0)
    f = NeuralODE(2, (50, 50), "tanh").double()
    h = NeuralFeedback(2, (16,), "tanh").double()
    Ts, T = 0.01, args.T
    g = torch.Generator().manual_seed(0)
    t = torch.arange(T, dtype=torch.float64) * Ts + 0.3 * Ts * (2 * torch.rand(T, dtype=torch.float64, generator=g) - 1)
    tt = torch.linspace(0, 6.28, T, dtype=torch.float64)
    x = torch.stack([torch.sin(tt), torch.cos(tt)], -1)
    C = torch.tensor([[1.0, 0.0]], dtype=torch.float64)
    y = x @ C.T
    out = {"T": T, "N": args.N, "jitter": "+-30% of Ts", "seconds": {}}
    cases = {
        "LinearFeedback": (F.LinearFeedback(f, Ts, gains=F.Gains(5.0), n=2), x),
        "NeuralFeedbackObserver": (F.NeuralFeedbackObserver(f, Ts, h=h, n=2), x),
        "KalmanObserver (full state)": (F.KalmanObserver(f, Ts, n=2, cov=F.Covariances(1e-6, 1e-4)), x),
        "KalmanObserver (full state, steady)": (F.KalmanObserver(f, Ts, n=2, cov=F.Covariances(1e-6, 1e-4),
                                                                 steady_state=True), x),
        "LuenbergerObserver (full state)": (F.LuenbergerObserver(f, Ts, n=2, poles=[0.5, 0.6, 0.7, 0.8]), x),
        "KalmanObserver (C, steady)": (F.KalmanObserver(f, Ts, n=2, cov=F.Covariances([1e-6, 1e-6, 1e-3], 1e-4), C=C,
                                                        disturbance=[1], steady_state=True), y),
        "LuenbergerObserver (C)": (F.LuenbergerObserver(f, Ts, n=2, poles=[0.9, 0.92, 0.94], C=C, disturbance=[1]), y),
        "ExtendedKalmanObserver (C)": (F.ExtendedKalmanObserver(f, Ts, n=2,
                                                                cov=F.Covariances([1e-6, 1e-6, 1e-3], 1e-4), C=C,
                                                                disturbance=[1]), y),
        "UnscentedKalmanObserver (C)": (F.UnscentedKalmanObserver(f, Ts, n=2,
                                                                  cov=F.Covariances([1e-6, 1e-6, 1e-3], 1e-4), C=C,
                                                                  disturbance=[1]), y),
    }
    with torch.no_grad():
        for name, (obs, data) in cases.items():
            row = {}
            obs.observe(data[:50], t=t[:50])  # warm-up: first-call imports and allocations are not timed
            for label, kw in (("Ts", {}), ("t", {"t": t})):
                row[f"observe_{label}"] = round(best_of(lambda: obs.observe(data, **kw), args.repeats), 3)
            row["predict_t"] = round(best_of(lambda: obs.predict(data, args.N, t=t), args.repeats), 3)
            out["seconds"][name] = row
            print(name, row, flush=True)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
