"""ms per gradient: explicit adjoint (Alg. 2) vs autograd through the rollout, quadrotor-sized toy.

Representative size of the paper's quadrotor learning (App. A.5): B = 80 segments
(40 trajectories of 200 nodes, two segments each) of T = 100 steps, an 18-state
closed loop (12 plant + 6 controller states) integrated by RK4, a 2x36 tanh MLP
residual on (v, Theta). The toy closed loop is a PID-controlled rigid body with a
small attitude-to-acceleration coupling, not the quadrotor.

    .venv/bin/python benchmarks/bench_external.py [--quick] [--dtype float64] [--device cuda]
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import torch
from torch import Tensor, nn

import fnnlib  # noqa: F401  (sets torch to one intra-op thread, as in training)
from fnnlib.models import mlp
from fnnlib.training.external import adjoint_gradient, rollout, trajectory_loss


class ToyLoop(nn.Module):
    """``x = (p, v, Theta, omega, z_p, z_Theta)`` (18), ``I = (p_ref, Theta_ref)`` (6), residual r(v, Theta)."""

    def __init__(self) -> None:
        super().__init__()
        self.residual = mlp(6, 3, (36, 36), "tanh")

    def forward(self, x: Tensor, I: Tensor) -> Tensor:
        p, v, th, om, zp, zt = x.split(3, dim=1)
        ep, et = I[:, :3] - p, I[:, 3:] - th
        tilt = torch.stack([torch.sin(th[:, 1]), -torch.sin(th[:, 0]), torch.zeros_like(th[:, 0])], dim=1)
        dv = 4.0 * ep - 3.0 * v + 0.5 * zp + 2.0 * tilt + self.residual(torch.cat([v, th], dim=1))
        dom = 16.0 * et - 8.0 * om + zt
        return torch.cat([v, dv, om, dom, ep, et], dim=1)


def rk4(f: nn.Module, x: Tensor, I: Tensor, Ts: float) -> Tensor:
    k1 = f(x, I)
    k2 = f(x + 0.5 * Ts * k1, I)
    k3 = f(x + 0.5 * Ts * k2, I)
    k4 = f(x + Ts * k3, I)
    return x + Ts / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)


def saved_mib(fn: Callable[[], object]) -> float:
    """MiB of tensors saved for backward while ``fn`` runs (shared storages counted once per save)."""
    total = 0

    def pack(t: Tensor) -> Tensor:
        nonlocal total
        total += t.numel() * t.element_size()
        return t

    with torch.autograd.graph.saved_tensors_hooks(pack, lambda t: t):
        fn()
    return total / 2**20


def median_ms(fn: Callable[[], object], reps: int, sync: Callable[[], None]) -> float:
    fn()
    sync()
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        sync()
        times.append(1000.0 * (time.perf_counter() - t0))
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="T = 20 and 3 repetitions (a smoke run)")
    ap.add_argument("--B", type=int, default=80)
    ap.add_argument("--T", type=int, default=100)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--dtype", choices=["float32", "float64"], default="float32")
    ap.add_argument("--device", default="cpu")
    args = ap.parse_args()
    T, reps = (20, 3) if args.quick else (args.T, args.reps)
    B, Ts = args.B, 0.01
    dtype, device = getattr(torch, args.dtype), torch.device(args.device)
    sync = torch.cuda.synchronize if device.type == "cuda" else (lambda: None)

    torch.manual_seed(0)
    model = ToyLoop().to(dtype=dtype, device=device)
    step = lambda x, u: rk4(model, x, u, Ts)  # noqa: E731
    params = list(model.parameters())
    t = torch.arange(T, dtype=dtype, device=device) * Ts
    I = torch.sin(t[None, :, None] * (1.0 + torch.rand(B, 1, 6, dtype=dtype, device=device))
                  + 6.28 * torch.rand(B, 1, 6, dtype=dtype, device=device))  # (B, T, 6)
    x_r = rollout(step, 0.1 * torch.randn(B, 18, dtype=dtype, device=device), I)
    x_r = x_r + 0.01 * torch.randn_like(x_r)
    W = torch.cat([torch.ones(12), torch.zeros(6)]).to(dtype=dtype, device=device)

    def adjoint() -> None:
        adjoint_gradient(step, params, x_r[:, 0], I, x_r, W)

    def autograd() -> None:
        xs = [x_r[:, 0]]
        for i in range(T):
            xs.append(step(xs[-1], I[:, i]))
        model.zero_grad(set_to_none=True)
        trajectory_loss(torch.stack(xs, dim=1), x_r, W).backward()

    def forward() -> None:
        rollout(step, x_r[:, 0], I)

    def adjoint_one_step() -> None:  # the most graph the adjoint holds at a time: one step
        x = x_r[:, 0].detach().requires_grad_()
        step(x, I[:, 0])

    rows = [("forward rollout only (no grad)", median_ms(forward, reps, sync), 0.0),
            ("adjoint_gradient (Alg. 2)", median_ms(adjoint, reps, sync), saved_mib(adjoint_one_step)),
            ("autograd through rollout", median_ms(autograd, reps, sync), saved_mib(autograd))]
    print(f"B = {B} segments, T = {T} steps, n = 18, m = 6, RK4, MLP 6-36-36-3 tanh, {args.dtype}, {device}, "
          f"torch threads = {torch.get_num_threads()}, median of {reps}")
    print(f"{'method':34s} {'ms/gradient':>12s} {'ms/step':>8s} {'graph MiB':>10s}")
    for name, ms, mib in rows:
        print(f"{name:34s} {ms:12.1f} {ms / T:8.2f} {mib:10.2f}")
    print(f"adjoint / autograd time: {rows[1][1] / rows[2][1]:.2f}x; the paper's 50 epochs as 50 full-batch "
          f"adjoint updates of these {B} segments: ~{50 * rows[1][1] / 1000:.0f} s")


if __name__ == "__main__":
    main()
