"""Partial measurements: ``MeasuredFeedback.predict`` (under no_grad), the cascade with ``C`` and through gaps,
the EKF and the UKF, on a damped cart of which only the position is measured (T samples, N steps).

    .venv/bin/python benchmarks/bench_measured.py [--repeats 5] [--T 500] [--N 20]
"""

from __future__ import annotations

import argparse
import json

import torch

import fnnlib as F
from bench_cascade import best_of

F64 = torch.float64


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--T", type=int, default=500)
    ap.add_argument("--N", type=int, default=20)
    args = ap.parse_args()
    F.seed_everything(0)
    Ts, T, N = 0.02, args.T, args.N
    model = F.NeuralODE(2, (32, 32), "tanh", n_input=1).double()
    A = F.model_jacobian(model, torch.zeros(2, dtype=F64), torch.zeros(1, dtype=F64))
    C = torch.tensor([[1.0, 0.0]], dtype=F64)
    L = F.place_observer_gain(torch.eye(2, dtype=F64) + Ts * A, Ts * C, [0.8, 0.85])
    gen = F.make_generator(0)
    y = torch.randn(T, 1, generator=gen, dtype=F64)
    u = torch.randn(T, 1, generator=gen, dtype=F64)
    y_gap = y.clone()
    y_gap[torch.rand(T, generator=gen) < 0.3] = float("nan")
    mf = F.MeasuredFeedback(model, L, C, Ts, A=A)
    ekf = F.ExtendedKalmanObserver(model, Ts, 2, [1e-6, 1e-6, 1e-3], 1e-3, C=C, disturbance=[1], A=A)
    ukf = F.UnscentedKalmanObserver(model, Ts, 2, [1e-6, 1e-6, 1e-3], 1e-3, C=C, disturbance=[1], A=A)
    cases = {
        "MeasuredFeedback.predict (no_grad)": lambda: mf.predict(y, N, u),
        "MeasuredFeedback.predict with autograd on (the former path)": lambda: _with_grad(mf, y, N, u),
        "cascade_predict with C": lambda: F.cascade_predict(model, y, Ts, N, L, 0.05, u=u, C=C, A=A),
        "cascade_predict with C, 30 % gaps": lambda: F.cascade_predict(model, y_gap, Ts, N, L, 0.05, u=u, C=C, A=A),
        "EKF.predict, 30 % gaps": lambda: ekf.predict(y_gap, N, u),
        "UKF.predict, 30 % gaps": lambda: ukf.predict(y_gap, N, u),
    }
    out = {name: 1e3 * best_of(fn, args.repeats) for name, fn in cases.items()}
    print(json.dumps({"T": T, "N": N, "ms": {k: round(v, 1) for k, v in out.items()}}, indent=1))


def _with_grad(mf, y, N, u):
    """The former ``predict``: the same steps with autograd recording."""
    z = mf.observe(y, u).x_hat
    for j in range(N):
        z = z + mf.Ts * F.eval_field(mf.f, z, F.feedback.layer.shift_inputs(u, j))
    return z


if __name__ == "__main__":
    main()
