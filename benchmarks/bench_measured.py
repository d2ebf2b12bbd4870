"""Partial measurements and gaps against the full-state cascade, in one run, as ratios.

A forced Duffing-like plant's learned model (2-50-50-2 tanh with one input, float64), position only, 20 % of
the samples lost. Each case runs the same model, T and N as the full-state cascade; the ratio is its time over
the full-state cascade's. Also: the sequential reference of the observer layer (the former path, a Python loop
over time), the Newton iterations the batched layer takes, and ``tune_gains`` with an observer on a
1000-sample record, N = 25, 100 iterations. One torch thread.

    .venv/bin/python benchmarks/bench_measured.py [--repeats 3] [--T 1000] [--N 50] [--loop]
"""

from __future__ import annotations

import argparse
import json
import time

import torch

import fnnlib as F
from fnnlib.models.neural_ode import init_parameters
from fnnlib.seeding import make_generator
from fnnlib.feedback import gaps
from bench_cascade import best_of

F64 = torch.float64


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--T", type=int, default=1000)
    ap.add_argument("--N", type=int, default=50)
    ap.add_argument("--loop", action="store_true", help="also time the sequential reference (slow at large T)")
    ap.add_argument("--tune", action="store_true", help="also time tune_gains with an observer (T=1000, N=25, 100 its)")
    args = ap.parse_args()
    torch.set_num_threads(1)
    Ts, T, N = 0.02, args.T, args.N
    gen = make_generator(0)
    model = init_parameters(F.NeuralODE(2, (50, 50), "tanh", n_input=1).double(), gen)
    A = F.model_jacobian(model, torch.zeros(2, dtype=F64), torch.zeros(1, dtype=F64))
    C = torch.tensor([[1.0, 0.0]], dtype=F64)
    L_y = F.place_observer_gain(torch.eye(2, dtype=F64) + Ts * A, Ts * C, [0.8, 0.85])
    x = 0.3 * torch.randn(T, 2, generator=gen, dtype=F64).cumsum(0) / T ** 0.5
    u = torch.randn(T, 1, generator=gen, dtype=F64)
    lost = torch.rand(T, generator=gen) < 0.2
    x_gap = x.clone()
    x_gap[lost] = float("nan")
    y = x @ C.T
    y_gap = y.clone()
    y_gap[lost] = float("nan")
    t = torch.cumsum(Ts * (0.5 + torch.rand(T, generator=gen, dtype=F64)), 0)
    obs = F.MeasuredFeedback(model, Ts, L=L_y, measurement=F.Measurement(C=C), A=A, allow_unstable=True)
    obs_t = F.MeasuredFeedback(model, None, L=L_y, measurement=F.Measurement(C=C), A=A, allow_unstable=True)
    h = lambda s: s[..., :1]  # noqa: E731  the same sensor as a function
    obs_h = F.MeasuredFeedback(model, Ts, L=L_y, measurement=F.Measurement(C=h, x0=torch.zeros(2, dtype=F64)),
                               allow_unstable=True)
    cases = {
        "full state": lambda: F.cascade_predict(model, x, Ts, N, F.Gains(2.0, 0.05), u=u),
        "full state, 20 % gaps": lambda: F.cascade_predict(model, x_gap, Ts, N, F.Gains(2.0, 0.05), u=u),
        "y = C x": lambda: F.cascade_predict(model, y, Ts, N, F.Gains(2.0, 0.05), u=u, observer=obs),
        "y = C x, 20 % gaps": lambda: F.cascade_predict(model, y_gap, Ts, N, F.Gains(2.0, 0.05), u=u, observer=obs),
        "y = h(x), 20 % gaps": lambda: F.cascade_predict(model, y_gap, Ts, N, F.Gains(2.0, 0.05), u=u, observer=obs_h),
        "y = C x, 20 % gaps, uneven times": lambda: F.cascade_predict(model, y_gap, None, N, F.Gains(2.0, 0.05), u=u,
                                                                      measurement=F.Measurement(t=t), observer=obs_t),
        "observer alone (MeasuredFeedback.observe), 20 % gaps": lambda: obs.observe(y_gap, u),
    }
    if args.loop:
        cases["observer, sequential reference (the former path)"] = lambda: obs.observe_loop(y_gap, u)
    ms = {name: 1e3 * best_of(fn, args.repeats) for name, fn in cases.items()}
    full = ms["full state"]
    iters = {}
    orig = gaps._newton

    def counting(*a, **k):
        out = orig(*a, **k)
        iters.setdefault(counting.case, []).append(out[2])
        return out

    gaps._newton = counting
    for counting.case, fn in [("y = C x, 20 % gaps", cases["y = C x, 20 % gaps"]),
                              ("full state, 20 % gaps", cases["full state, 20 % gaps"])]:
        fn()
    gaps._newton = orig
    report = {"T": T, "N": N, "ms": {k: round(v, 1) for k, v in ms.items()},
              "ratio to full state": {k: round(v / full, 2) for k, v in ms.items()},
              "Newton iterations": iters}
    if args.tune:
        Tt = 1000
        start = time.perf_counter()
        F.tune_gains(model, y_gap[:Tt], Ts, 25, recipe=F.TuneRecipe(L0=2.0, beta0=0.05, iterations=100, lr=0.1),
                     u=u[:Tt], observer=obs)
        with_obs = time.perf_counter() - start
        start = time.perf_counter()
        F.tune_gains(model, x[:Tt], Ts, 25, recipe=F.TuneRecipe(L0=2.0, beta0=0.05, iterations=100, lr=0.1), u=u[:Tt])
        report["tune_gains, T = 1000, N = 25, 100 iterations [s]"] = {
            "with an observer (y = C x, 20 % gaps)": round(with_obs, 2),
            "full state": round(time.perf_counter() - start, 2)}
    print(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
