"""Per-step cost of the Eq. (28) MPC: linearisation of a torch model and the parametrised QP vs a rebuilt one.

Paper settings (App. A.5.3): n = 12, m = 4, N = 10, Q = diag(100 x3, 50 x6, 1 x3), R = I4,
0 <= u <= 4, |Theta| <= pi/2 (x[6:9]). The model is a representative RK4 rigid body (Eq. 27-like,
Euler angles, 4 thrusts through an allocation matrix) with a 6-36-36-3 drag MLP inside, written
here so that the benchmark does not depend on fnnlib.systems. Each of ~300 steps moves the
reference, the state and the linearisation slowly; timings are per step (parameter assignment +
solve), reported as wall time and as this thread's CPU time (the CPU figure is the one to trust
on a shared machine). ``solver`` is the time the QP solver reports; ``max|du|`` is the largest
deviation of the planned inputs from a Clarabel solve at 1e-10 (same cost variant). Both cost
variants of Eq. (28) are timed (``as_written``, ``as_flown``: as the paper writes it and as the release
flies it). For the fast path
(``OSQPMPC``: OSQP updated from cvxpy's canonicalisation) the step is split into the guard and
plan checks, applying cvxpy's parameter tensor + ``update``, and OSQP's own solve.

    .venv/bin/python benchmarks/bench_mpc.py [--steps 300] [--rebuild-steps 60]
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from collections.abc import Callable

import numpy as np
import torch
from torch import nn

from fnnlib.quadrotor.mpc import LinearizedMPC, OSQPMPC, RebuildMPC, linearize
from fnnlib.quadrotor.mpc.linearized import COSTS
from fnnlib.quadrotor.presets import PAPER_MPC_WEIGHTS, PAPER_THETA_MAX

N, NX, NU, DT = 10, 12, 4, 0.05
Q = np.array(PAPER_MPC_WEIGHTS["Q"])
R = np.array(PAPER_MPC_WEIGHTS["R"])
BOX = {"u_lb": np.zeros(NU), "u_ub": np.full(NU, 4.0),
       "x_lb": np.r_[np.full(6, -np.inf), np.full(3, -PAPER_THETA_MAX), np.full(3, -np.inf)],
       "x_ub": np.r_[np.full(6, np.inf), np.full(3, PAPER_THETA_MAX), np.full(3, np.inf)]}


class RigidBody(nn.Module):
    """x = (p, v, Theta, omega) in R^12, u = 4 thrusts; one RK4 step of length Ts (float64)."""

    def __init__(self, Ts: float = DT) -> None:
        super().__init__()
        torch.manual_seed(0)
        self.Ts, self.mass, self.g = Ts, 1.0, 9.81
        arm, kappa = 0.15, 0.02
        self.register_buffer("J", torch.tensor([0.01, 0.01, 0.02], dtype=torch.float64))
        self.register_buffer("C", torch.tensor([[1.0, 1.0, 1.0, 1.0], [0.0, arm, 0.0, -arm],
                                                [-arm, 0.0, arm, 0.0], [kappa, -kappa, kappa, -kappa]],
                                               dtype=torch.float64))
        self.register_buffer("gz", torch.tensor([0.0, 0.0, self.g], dtype=torch.float64))
        self.drag = nn.Sequential(nn.Linear(6, 36), nn.Tanh(), nn.Linear(36, 36), nn.Tanh(),
                                  nn.Linear(36, 3)).double()
        for p in self.drag.parameters():
            p.requires_grad_(False)

    def f(self, x: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        v, th, w = x[:, 3:6], x[:, 6:9], x[:, 9:12]
        s, c = th.sin(), th.cos()
        sph, sth, sps = s.unbind(-1)
        cph, cth, cps = c.unbind(-1)
        wrench = u @ self.C.T  # (T, tau)
        zb = torch.stack([cph * sth * cps + sph * sps, cph * sth * sps - sph * cps, cph * cth], -1)
        a = self.gz - zb * (wrench[:, :1] / self.mass) + self.drag(torch.cat([v, th], -1))
        p_, q_, r_ = w.unbind(-1)
        tth = sth / cth
        th_dot = torch.stack([p_ + (sph * q_ + cph * r_) * tth, cph * q_ - sph * r_, (sph * q_ + cph * r_) / cth], -1)
        w_dot = (wrench[:, 1:] - torch.linalg.cross(w, w * self.J)) / self.J
        return torch.cat([v, a, th_dot, w_dot], -1)

    def forward(self, x: torch.Tensor, u: torch.Tensor, k: torch.Tensor) -> torch.Tensor:
        h = self.Ts
        k1 = self.f(x, u)
        k2 = self.f(x + 0.5 * h * k1, u)
        k3 = self.f(x + 0.5 * h * k2, u)
        k4 = self.f(x + h * k3, u)
        return x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def count_torch_calls(model: nn.Module) -> int:
    from torch.overrides import TorchFunctionMode

    class Counter(TorchFunctionMode):
        calls = 0

        def __torch_function__(self, func, types, args=(), kwargs=None):  # type: ignore[no-untyped-def]
            Counter.calls += 1
            return func(*args, **(kwargs or {}))

    x, u = torch.zeros(N, NX, dtype=torch.float64), torch.ones(N, NU, dtype=torch.float64)
    with torch.no_grad(), Counter():
        model(x, u, torch.arange(N))
    return Counter.calls


def reference(t: float) -> np.ndarray:
    """Slow circle at constant height, level attitude: (p, v, Theta, omega)."""
    w = 2 * np.pi / 10.0
    p = np.array([np.cos(w * t), np.sin(w * t), -0.5])
    v = np.array([-w * np.sin(w * t), w * np.cos(w * t), 0.0])
    return np.r_[p, v, np.zeros(6)]


def timed(fn: Callable[[], object]) -> tuple[float, float]:
    w0, c0 = time.perf_counter(), time.thread_time()
    fn()
    return time.perf_counter() - w0, time.thread_time() - c0


def stats(samples: list[tuple[float, float]]) -> dict[str, float]:
    wall, cpu = (1e3 * np.array(s) for s in zip(*samples))
    return {"wall_med_ms": float(np.median(wall)), "wall_p95_ms": float(np.percentile(wall, 95)),
            "cpu_med_ms": float(np.median(cpu)), "cpu_p95_ms": float(np.percentile(cpu, 95))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--rebuild-steps", type=int, default=60)
    ap.add_argument("--lin-repeats", type=int, default=100)
    args = ap.parse_args()
    torch.set_num_threads(1)
    model = RigidBody()
    u_hover = np.full(NU, model.mass * model.g / NU)

    # --- data: a slowly moving reference, state near it, linearisation along the reference ---------------------
    data = []
    rng = np.random.default_rng(0)
    for i in range(args.steps):
        t = i * DT
        x_ref = np.stack([reference(t + (k + 1) * DT) for k in range(N)])  # x^r_1..x^r_N
        x_bar = np.stack([reference(t + k * DT) for k in range(N)])  # linearisation points x_0..x_{N-1}
        x0 = x_bar[0] + 0.05 * np.sin(0.1 * i + np.arange(NX)) + 0.002 * rng.normal(size=NX)
        data.append((x0, x_bar, x_ref))
    u_bar = np.tile(u_hover, (N, 1))

    # --- linearisation ----------------------------------------------------------------------------------------
    lin_rows = {}
    for method in ("reverse", "vmap"):
        x_bar = data[0][1]
        for _ in range(5):
            linearize(model, x_bar, u_bar, method=method)  # type: ignore[arg-type]
        lin_rows[method] = stats([timed(lambda d=data[i % len(data)]: linearize(model, d[1], u_bar, method=method))  # type: ignore[misc]
                                  for i in range(args.lin_repeats)])
    xb, ub, kk = torch.tensor(data[0][1]), torch.tensor(u_bar), torch.arange(N)
    with warnings.catch_warnings():  # the same model as a TorchScript trace (traced at the replicated batch n N)
        warnings.simplefilter("ignore")
        traced = torch.jit.trace(model, (xb.repeat(NX, 1), ub.repeat(NX, 1), kk.repeat(NX)), check_trace=False)
    gap = np.abs(linearize(traced, xb, u_bar).A - linearize(model, xb, u_bar).A).max()
    assert gap < 1e-12, gap
    for _ in range(5):
        linearize(traced, xb, u_bar)
    lin_rows["reverse, torch.jit.trace'd model"] = stats(
        [timed(lambda d=data[i % len(data)]: linearize(traced, d[1], u_bar)) for i in range(args.lin_repeats)])  # type: ignore[misc]
    with torch.no_grad():
        lin_rows["forward only"] = stats([timed(lambda: model(xb, ub, kk)) for _ in range(args.lin_repeats)])
    lins = [linearize(model, d[1], u_bar) for d in data]

    # --- QP ---------------------------------------------------------------------------------------------------
    exact = {cost: LinearizedMPC(N, Q, R, cost=cost, **BOX, solver="CLARABEL", eps_abs=1e-10, eps_rel=1e-10)
             for cost in COSTS}
    u_exact = {cost: [mpc.solve(d[0], lin.A, lin.B, lin.c, d[2], u_bar).u for d, lin in zip(data, lins)]
               for cost, mpc in exact.items()}

    def run(mpc: LinearizedMPC | RebuildMPC | OSQPMPC, steps: int) -> dict[str, float]:
        samples, solver_ms, statuses, u_err, inner = [], [], {}, 0.0, []
        real_solve_qp = mpc._solve_qp

        def timed_solve_qp(*a: object) -> object:  # the step without the guard and the plan checks
            t = time.perf_counter()
            out = real_solve_qp(*a)
            inner.append(1e3 * (time.perf_counter() - t))
            return out

        mpc._solve_qp = timed_solve_qp  # type: ignore[method-assign]
        for i in range(steps):
            (x0, _, x_ref), lin = data[i], lins[i]
            box: list[object] = []
            samples.append(timed(lambda: box.append(mpc.solve(x0, lin.A, lin.B, lin.c, x_ref, u_bar))))
            sol = box[0]
            statuses[sol.status] = statuses.get(sol.status, 0) + 1  # type: ignore[attr-defined]
            solver_ms.append(1e3 * sol.solver_time_s)  # type: ignore[attr-defined]
            u_err = max(u_err, float(np.abs(sol.u - u_exact[mpc.cost][i]).max()))  # type: ignore[attr-defined]
        row = stats(samples[1:])  # the first call compiles
        row["first_call_ms"] = 1e3 * samples[0][0]
        row["solver_med_ms"] = float(np.nanmedian(solver_ms[1:]))
        row["solve_qp_med_ms"] = float(np.median(inner[1:]))
        row["max_u_err"] = u_err
        row["fallbacks"] = mpc.n_fallbacks
        row["statuses"] = statuses  # type: ignore[assignment]
        return row

    configs = {}
    for cost in COSTS:
        configs.update({
            f"{cost}: OSQPMPC, OSQP from cvxpy's canonical form (eps 1e-5)": (OSQPMPC, {"cost": cost}),
            f"{cost}: cvxpy Parameters, OSQP (eps 1e-5, no polish)": (LinearizedMPC, {"cost": cost}),
        })
    configs.update({
        "as_written: cvxpy Parameters, OSQP eps 1e-5 + polish": (LinearizedMPC, {"cost": "as_written",
                                                                                 "solver_options": {"polishing": True}}),
        "as_written: cvxpy Parameters, OSQP eps 1e-3": (LinearizedMPC, {"cost": "as_written", "eps_abs": 1e-3,
                                                                        "eps_rel": 1e-3}),
        "as_written: cvxpy Parameters, CLARABEL": (LinearizedMPC, {"cost": "as_written", "solver": "CLARABEL"}),
        "as_written: RebuildMPC OSQP (eps 1e-5)": (RebuildMPC, {"cost": "as_written"}),
        "as_written: RebuildMPC CLARABEL": (RebuildMPC, {"cost": "as_written", "solver": "CLARABEL"}),
    })
    qp_rows = {}
    for name, (cls, kw) in configs.items():
        steps = args.rebuild_steps if cls is RebuildMPC else args.steps
        qp_rows[name] = run(cls(N, Q, R, **BOX, **kw), steps)  # type: ignore[arg-type]

    # where the time goes in the parametrised OSQP solve: parameter assignment alone
    mpc = LinearizedMPC(N, Q, R, cost="as_written", **BOX)
    lin = lins[0]

    def assign() -> None:
        mpc.A_param.value = lin.A[1:].reshape(-1, NX)
        mpc.B_param.value = lin.B.reshape(-1, NU)
        mpc.d_param.value = lin.c
        mpc.x_r_param.value = data[0][2]
        mpc.u_r_param.value = u_bar

    assign_row = stats([timed(assign) for _ in range(300)])

    print(f"linearisation of the RK4 rigid body ({count_torch_calls(model)} torch calls per step, N = {N}):")
    print(f"{'method':<42}{'wall med':>10}{'wall p95':>10}{'cpu med':>10}{'cpu p95':>10}   (ms)")
    for name, r in lin_rows.items():
        print(f"{name:<42}{r['wall_med_ms']:>10.2f}{r['wall_p95_ms']:>10.2f}{r['cpu_med_ms']:>10.2f}{r['cpu_p95_ms']:>10.2f}")
    print(f"\nQP per step, n = {NX}, m = {NU}, N = {N} (assignment + solve):")
    print(f"{'configuration':<66}{'wall med':>10}{'wall p95':>10}{'cpu med':>10}{'cpu p95':>10}{'solver':>9}{'first':>9}{'max|du|':>9}  fallbacks")
    for name, r in qp_rows.items():
        print(f"{name:<66}{r['wall_med_ms']:>10.2f}{r['wall_p95_ms']:>10.2f}{r['cpu_med_ms']:>10.2f}{r['cpu_p95_ms']:>10.2f}"
              f"{r['solver_med_ms']:>9.2f}{r['first_call_ms']:>9.1f}{r['max_u_err']:>9.0e}  {r['fallbacks']} {r['statuses']}")
    print(f"{'(parameter assignment alone)':<66}{assign_row['wall_med_ms']:>10.2f}{assign_row['wall_p95_ms']:>10.2f}"
          f"{assign_row['cpu_med_ms']:>10.2f}{assign_row['cpu_p95_ms']:>10.2f}")
    cvx = qp_rows["as_written: cvxpy Parameters, OSQP (eps 1e-5, no polish)"]
    ratio = qp_rows["as_written: RebuildMPC OSQP (eps 1e-5)"]["cpu_med_ms"] / cvx["cpu_med_ms"]
    print(f"\nrebuild / parametrised (OSQP, cpu median): {ratio:.1f}x")
    print(f"cvxpy overhead in the parametrised OSQP step: {cvx['cpu_med_ms'] - cvx['solver_med_ms']:.2f} ms "
          f"of {cvx['cpu_med_ms']:.2f} ms (solver reports {cvx['solver_med_ms']:.2f} ms)")
    step_cpu = {}
    for cost in COSTS:
        fast = qp_rows[f"{cost}: OSQPMPC, OSQP from cvxpy's canonical form (eps 1e-5)"]
        print(f"{cost}: fast path, wall median {fast['wall_med_ms']:.2f} ms = guard + plan checks "
              f"{fast['wall_med_ms'] - fast['solve_qp_med_ms']:.2f} + parameter tensor and update "
              f"{fast['solve_qp_med_ms'] - fast['solver_med_ms']:.2f} + OSQP solve {fast['solver_med_ms']:.2f}")
        step_cpu[cost] = lin_rows["reverse"]["cpu_med_ms"] + fast["cpu_med_ms"]
        print(f"{cost}: per control step, linearisation (reverse) + QP (fast path), cpu median: "
              f"{step_cpu[cost]:.2f} ms (target 4 ms)")
    print(json.dumps({"linearize": lin_rows, "qp": qp_rows, "assign": assign_row, "rebuild_ratio": ratio,
                      "step_cpu_med_ms": step_cpu}))


if __name__ == "__main__":
    main()
