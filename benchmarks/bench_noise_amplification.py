"""``noise_amplification_exact``: its time, and its value against a Monte Carlo run of the cascade on white noise.

Cases: scalar and diagonal gains (n up to 12, N up to 50), and a stable linear model whose Jacobian damps
the noise (``A=...``). The Monte Carlo figure is what a user measures: the RMS over every component of the
cascade's output noise (after the start-up transient), divided by the input noise's; f = A x linear, so the
cascade is exactly linear in the noise.

    .venv/bin/python benchmarks/bench_noise_amplification.py [--repeats 5] [--json]
"""

from __future__ import annotations

import argparse
import json
import time
import warnings

import torch

import fnnlib as F
from fnnlib.feedback import GainWarning, noise_amplification_exact

F64 = torch.float64


def best_ms(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * min(times)


def monte_carlo(L, Ts: float, N: int, beta: float, A: torch.Tensor, *, T: int = 6000, draws: int = 8) -> float:
    """RMS of the cascade's output on unit white noise (f = A x, so the response is the noise's alone)."""
    n = A.shape[0]
    v = torch.randn(draws, T, n, generator=torch.Generator().manual_seed(0), dtype=F64)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GainWarning)
        z = F.cascade_predict(lambda t, x: x @ A.T, v, Ts, N, F.Gains(L, beta))
    return float(z[:, 2000:].pow(2).mean().sqrt())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    Ts = 0.01
    rows = []
    cases = [
        ("scalar L=20, N=50, beta=0.02, n=2", 20.0, 50, 0.02, torch.zeros(2, 2, dtype=F64)),
        ("diagonal L=(40, 2), N=30, beta=0.02", torch.tensor([40.0, 2.0]), 30, 0.02, torch.zeros(2, 2, dtype=F64)),
        ("diagonal n=12 L=1..45, N=50, beta=0.02", torch.linspace(1.0, 45.0, 12), 50, 0.02, torch.zeros(12, 12, dtype=F64)),
        ("scalar L=20, N=30, damped model A", 20.0, 30, 0.0, torch.tensor([[0.0, 1.0], [-25.0, -8.0]], dtype=F64)),
    ]
    for name, L, N, beta, A in cases:
        n = A.shape[0]
        with_A = bool(A.abs().sum() > 0)
        kw = {"n": n, **({"A": A} if with_A else {})}
        exact = noise_amplification_exact(F.Gains(L, beta), Ts, N, **kw)
        ms = best_ms(lambda: noise_amplification_exact(F.Gains(L, beta), Ts, N, **kw), args.repeats)
        bound = F.noise_amplification(F.Gains(L, beta), Ts, N, n=n)
        worst = noise_amplification_exact(F.Gains(L, beta), Ts, N, n=n, reduce="max")
        mc = monte_carlo(L, Ts, N, beta, A)
        rows.append({"case": name, "exact_rms": exact, "monte_carlo_rms": mc, "rel_diff": exact / mc - 1,
                     "ms": ms, "product_bound": bound, "worst_direction": worst})
    if args.json:
        print(json.dumps(rows, indent=1))
        return
    print(f"{'case':42s} {'exact':>7s} {'MC':>7s} {'diff':>7s} {'ms':>7s} {'bound':>7s} {'worst':>7s}")
    for r in rows:
        print(f"{r['case']:42s} {r['exact_rms']:7.3f} {r['monte_carlo_rms']:7.3f} {100 * r['rel_diff']:6.2f}% "
              f"{r['ms']:7.2f} {r['product_bound']:7.3f} {r['worst_direction']:7.3f}")


if __name__ == "__main__":
    main()
