"""What one RK4 step of the MPC's prediction model costs in eager torch, a numpy twin and the numba kernel.

The flight loop of Sec. 5.2 evaluates three RK4 steps of Eq. (27) per control step (the
linearization batch, the truth, the model along the new plan); in eager torch each costs about a
millisecond of per-op overhead whatever the batch size. This script measures that cost for the
fnnlib model (nominal Eq. (27) + the 6-36-36-3 tanh residual) against a numpy transcription of the
same right-hand side written here only to measure the option (it is not library code; it is checked
equal to fnnlib to 1e-12 first), and against the compiled kernel the flight loop uses
(:mod:`fnnlib.quadrotor.mpc.compiled`), whose exact step Jacobians for the 10 plan points are timed too (they
replace the 170-row forward-difference batch). Batch sizes: 1 (truth), 10 (model along the plan), 170
(forward-difference linearization, N (n + m + 1)).

    .venv/bin/python benchmarks/bench_rhs_backends.py [--repeats 300]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from fnnlib.quadrotor.residual import AeroResidual
from fnnlib.quadrotor.mpc.compiled import CompiledQuadrotor, warm_up
from fnnlib.quadrotor.presets import PAPER_RESIDUAL_RECIPE, PAPER_TS
from fnnlib.quadrotor.allocation import allocation_matrix
from fnnlib.quadrotor.system import TEST_TRUTH, Quadrotor
from fnnlib.quadrotor.rotations import rotation_matrix


def numpy_twin(q: Quadrotor, net: AeroResidual):
    """Eq. (27) + residual in numpy, the same formulas as ``Quadrotor.rhs`` (matrix form)."""
    prm = q.params
    C = allocation_matrix(prm).numpy()
    J, D, F = (np.array(v) for v in (prm.inertia, prm.drag, prm.force_disturbance))
    e3 = np.array([0.0, 0.0, 1.0])
    layers = [(m.weight.detach().double().numpy(), m.bias.detach().double().numpy())
              for m in net.net if isinstance(m, torch.nn.Linear)]

    def residual(x: np.ndarray) -> np.ndarray:
        h = x[:, 3:9]
        for i, (W, b) in enumerate(layers):
            h = h @ W.T + b
            if i < len(layers) - 1:
                h = np.tanh(h)
        return h

    def f(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        v, th, w = x[:, 3:6], x[:, 6:9], x[:, 9:12]
        c, s = np.cos(th), np.sin(th)
        cf, ct, cp = c[:, 0], c[:, 1], c[:, 2]
        sf, st, sp = s[:, 0], s[:, 1], s[:, 2]
        R = np.stack([cp * ct, cp * st * sf - sp * cf, cp * st * cf + sp * sf,
                      sp * ct, sp * st * sf + cp * cf, sp * st * cf - cp * sf,
                      -st, ct * sf, ct * cf], -1).reshape(-1, 3, 3)
        wr = u @ C.T
        drag = -np.einsum("bij,bj->bi", R, D * np.einsum("bji,bj->bi", R, v))
        v_dot = -(wr[:, :1] / prm.mass) * R[:, :, 2] + prm.g * e3 + drag + F / prm.mass + residual(x)
        a = sf * w[:, 1] + cf * w[:, 2]
        th_dot = np.stack([w[:, 0] + a * st / ct, cf * w[:, 1] - sf * w[:, 2], a / ct], -1)
        w_dot = (wr[:, 1:] - np.cross(w, J * w)) / J
        return np.concatenate([v, v_dot, th_dot, w_dot], -1)

    def step(x: np.ndarray, u: np.ndarray, Ts: float = PAPER_TS) -> np.ndarray:
        k1 = f(x, u)
        k2 = f(x + 0.5 * Ts * k1, u)
        k3 = f(x + 0.5 * Ts * k2, u)
        k4 = f(x + Ts * k3, u)
        return x + Ts / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    return step


def per_call_ms(fn, repeats: int) -> float:
    for _ in range(10):
        fn()
    t = time.perf_counter()
    for _ in range(repeats):
        fn()
    return 1e3 * (time.perf_counter() - t) / repeats


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=300)
    args = ap.parse_args()
    torch.manual_seed(0)
    q = Quadrotor(TEST_TRUTH)
    net = AeroResidual(PAPER_RESIDUAL_RECIPE["hidden"], PAPER_RESIDUAL_RECIPE["activation"]).double()
    for p in net.parameters():
        p.requires_grad_(False)
    twin = numpy_twin(q, net)
    warm_up(net)
    compiled = CompiledQuadrotor(q, net)
    rng = np.random.default_rng(0)
    print(f"{'batch':>6s} {'torch ms':>9s} {'numpy ms':>9s} {'numba ms':>9s} {'torch/numba':>11s}")
    for B in (1, 10, 170):
        x = rng.normal(size=(B, 12)) * 0.3
        u = rng.uniform(1.0, 5.0, size=(B, 4))
        xt, ut = torch.tensor(x), torch.tensor(u)
        with torch.no_grad():
            ref = q.step(xt, ut, Ts=PAPER_TS, a_res_fn=net).numpy()
            assert np.abs(twin(x, u) - ref).max() < 1e-12
            assert np.abs(rotation_matrix(xt[:, 6:9]).numpy()).max() <= 1.0 + 1e-12
            t_torch = per_call_ms(lambda: q.step(xt, ut, Ts=PAPER_TS, a_res_fn=net), args.repeats)
        t_numpy = per_call_ms(lambda: twin(x, u), args.repeats)
        assert np.abs(compiled.step(x, u, PAPER_TS) - ref).max() < 1e-12
        t_numba = per_call_ms(lambda: compiled.step(x, u, PAPER_TS), args.repeats)
        print(f"{B:6d} {t_torch:9.3f} {t_numpy:9.3f} {t_numba:9.3f} {t_torch / t_numba:11.1f}")
    x, u = rng.normal(size=(10, 12)) * 0.3, rng.uniform(1.0, 5.0, size=(10, 4))
    t_jac = per_call_ms(lambda: compiled.step_jacobian(x, u, PAPER_TS), args.repeats)
    print(f"numba step + exact Jacobians at the 10 plan points: {t_jac:.3f} ms")


if __name__ == "__main__":
    main()
