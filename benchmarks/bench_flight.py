"""The Sec. 5.2 flight loop end to end: per-step time of each prediction model and the real-time factor.

One 6 s Lissajous flight (300 steps of 0.02 s, N = 10, Q = diag(100 x3, 50 x6, 1 x3), R = I4,
0 <= u <= 6 N, |Theta| <= pi/2) on the Sec. 5.3 test vehicle, for each of the seven prediction
models of App. A.5.4 and each configuration (QP implementation x numerics backend and
linearization method x truth sub-steps). The residual networks are the trained ones of the ``quadrotor_learning`` task when
``--learning-dir`` holds them, else freshly initialised networks of the paper's size (2 x 36, tanh:
the cost per step does not depend on the weights); AdapNN adapts with Gamma = Ts * 8 = 0.16, the release's
effective gain in this library's convention (see :class:`~fnnlib.quadrotor.mpc.models.AdaptiveNNModel`). Reported per model: median and p95 of
linearize + solve per step, the median of each part, and the whole loop's wall time (truth
simulation, model updates and bookkeeping included) as a multiple of real time (with --repeats R, the
step statistics pool all R flights and the loop time is their median).

    .venv/bin/python benchmarks/bench_flight.py [--steps 300] [--repeats 1] [--only numba]
        [--learning-dir outputs/paper/quadrotor_learning]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

from fnnlib.training import load_checkpoint
from fnnlib.quadrotor.residual import AeroResidual
from fnnlib.quadrotor.mpc import LinearizedMPC, OSQPMPC, RebuildMPC
from fnnlib.quadrotor.mpc.linearized import COSTS
from fnnlib.quadrotor.mpc import Backend, FlightTest, fly, lissajous_reference, paper_models, warm_up
from fnnlib.quadrotor.presets import (
    PAPER_BETA,
    PAPER_GAMMA,
    PAPER_HORIZON,
    PAPER_L,
    PAPER_LISSAJOUS,
    PAPER_MPC_WEIGHTS,
    PAPER_RESIDUAL_RECIPE,
    PAPER_THETA_MAX,
    PAPER_TS,
)
from fnnlib.quadrotor.system import NOMINAL, TEST_TRUTH, Quadrotor

N, TS = PAPER_HORIZON, PAPER_TS
Q, R = np.array(PAPER_MPC_WEIGHTS["Q"]), np.array(PAPER_MPC_WEIGHTS["R"])
X_LB = np.r_[np.full(6, -np.inf), np.full(3, -PAPER_THETA_MAX), np.full(3, -np.inf)]

CONFIGS = {  # name: (QP class, linearization method, truth RK4 sub-steps, backend)
    "osqp from cvxpy's canonical form, numba kernels with exact Jacobians, truth 1 RK4 step (notebook default)":
        (OSQPMPC, "exact", 1, "numba"),
    "osqp from cvxpy's canonical form, torch forward differences, truth 1 RK4 step": (OSQPMPC, "forward", 1, "torch"),
    "osqp from cvxpy's canonical form, torch central differences, truth 1 RK4 step": (OSQPMPC, "central", 1, "torch"),
    "osqp from cvxpy's canonical form, torch reverse-mode autograd, truth 1 RK4 step": (OSQPMPC, "reverse", 1, "torch"),
    "cvxpy Parameters, numba kernels, truth 1 RK4 step": (LinearizedMPC, "exact", 1, "numba"),
    "cvxpy Parameters, torch forward differences, truth 1 RK4 step": (LinearizedMPC, "forward", 1, "torch"),
    "cvxpy Parameters, torch central differences, truth 4 RK4 sub-steps (session-2 setting)":
        (LinearizedMPC, "central", 4, "torch"),
    "cvxpy problem rebuilt every step, torch forward differences, truth 1 RK4 step (the straightforward way)":
        (RebuildMPC, "forward", 1, "torch"),
}


def residuals(learning_dir: Path | None) -> tuple[torch.nn.Module, torch.nn.Module, str]:
    if learning_dir is not None and (learning_dir / "residual.pt").is_file():
        res, _ = load_checkpoint(learning_dir / "residual.pt", expected_kind="AeroResidual")
        mlp, _ = load_checkpoint(learning_dir / "mlp.pt", expected_kind="AeroResidual")
        return res.double(), mlp.double(), f"trained, from {learning_dir}"
    torch.manual_seed(0)
    shape = (PAPER_RESIDUAL_RECIPE["hidden"], PAPER_RESIDUAL_RECIPE["activation"])
    return AeroResidual(*shape).double(), AeroResidual(*shape).double(), "freshly initialised (2 x 36 tanh)"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--learning-dir", type=Path, default=Path("outputs/paper/quadrotor_learning"))
    ap.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    ap.add_argument("--repeats", type=int, default=1, help="flights per model and configuration; medians reported")
    ap.add_argument("--only", default=None, help="run only the configurations whose name contains this text")
    ap.add_argument("--cost", choices=COSTS, default="as_written",
                    help="Eq. (28)'s weighting: as written in the paper, or as flown by the release")
    args = ap.parse_args()
    residual, mlp, origin = residuals(args.learning_dir)
    truth = Quadrotor(TEST_TRUTH)
    x_r, u_r = lissajous_reference(args.steps, N, Ts=TS, params=NOMINAL, curve=PAPER_LISSAJOUS)
    print(f"residual networks: {origin}; torch threads: {torch.get_num_threads()}; {args.steps} steps of {TS} s; "
          f"cost {args.cost}")
    out: dict[str, dict[str, dict[str, float]]] = {}
    print(f"numba kernels compiled or loaded from the cache in {warm_up(residual, mlp):.1f} s (not timed below)")
    if args.repeats < 1:
        raise SystemExit("--repeats must be >= 1")
    for name, (cls, method, substeps, backend) in CONFIGS.items():
        if args.only is not None and args.only not in name:
            continue
        print(f"\n{name}")
        print(f"  {'model':8s} {'lin+solve med':>13s} {'p95':>6s} {'lin med':>8s} {'solve med':>9s} "
              f"{'loop ms/step':>12s} {'x real time':>11s} {'fallbacks':>9s}")
        rows = {}
        mpc = cls(N, Q, R, cost=args.cost, u_lb=np.zeros(4), u_ub=np.full(4, 6.0), x_lb=X_LB, x_ub=-X_LB)
        # AdapNN at the release's effective gain Ts * Gamma_rel (this library's Gamma = 8 runs away at 6 N)
        models = paper_models(residual, mlp, plant=Quadrotor(NOMINAL), L=PAPER_L, beta=PAPER_BETA, N=N,
                              Gamma=PAPER_GAMMA, Ts=TS, adapnn_gamma=TS * PAPER_GAMMA)
        test = FlightTest(truth, x_r, u_r, steps=args.steps, Ts=TS, substeps=substeps,
                          backend=Backend(backend, method if backend == "torch" else None))
        for model in models:
            runs = [fly(model, mpc, test) for _ in range(args.repeats)]
            # the first step of each flight warms caches up
            lin = 1e3 * np.concatenate([r.t_linearize[1:] for r in runs])
            sol = 1e3 * np.concatenate([r.t_solve[1:] for r in runs])
            elapsed = float(np.median([r.elapsed_s for r in runs]))
            rows[model.name] = {"step_ms_median": float(np.median(lin + sol)),
                                "step_ms_p95": float(np.percentile(lin + sol, 95)),
                                "linearize_ms_median": float(np.median(lin)), "solve_ms_median": float(np.median(sol)),
                                "loop_ms_per_step": 1e3 * elapsed / args.steps,
                                "real_time_factor": args.steps * TS / elapsed,
                                "fallbacks": max(r.n_fallbacks for r in runs)}
            v = rows[model.name]
            print(f"  {model.name:8s} {v['step_ms_median']:13.2f} {v['step_ms_p95']:6.2f} {v['linearize_ms_median']:8.2f} "
                  f"{v['solve_ms_median']:9.2f} {v['loop_ms_per_step']:12.2f} {v['real_time_factor']:11.2f} "
                  f"{v['fallbacks']:9d}")
        out[name] = rows
    if args.json is not None:
        args.json.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
