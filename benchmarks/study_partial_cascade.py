"""The cascade with partial measurements against the open-loop rollout from the same observer and the EKF / UKF.

The plant of the public-API trial: a forced Duffing oscillator, x'' = -0.3 x' - x - 0.5 x^3 + u, position only,
with measurement noise and 20 % of the samples lost. A neural ODE f(t, x, u) (2-50-50-2 with one input) is
trained on simulated full-state trajectories, so its coordinates are the plant's. Settings are chosen on a
calibration record (600 samples); the error is scored on a separate test record against the true state: the
mean N-step error after the first quarter (the start-up). Columns:

* cascade, hand gains: the observer, then the full-state layers with L from a sweep on the calibration record
  (L = 0 included: the feedback switched off);
* cascade, tuned gains: ``tune_gains`` on the calibration record (observer fixed, start-up not scored);
* open loop: the Euler rollout of the model from the same observer's latest estimate (L = 0 after it);
* EKF, UKF: rollouts from their filtered state, on the same model;
* and the error of the measured component (position) alone, for the cascade and open loop;
* the cascade's gains chosen on two calibration records instead of one (the second drawn apart);
* guarded: the same candidates kept only where they beat the feedback switched off (L = 0, i.e. open loop from
  the observer) on the calibration record beyond the spread over its windows (``fnnlib.choose_gain``);
* eight more test records (drawn apart): each estimator's mean over them and on how many of them the cascade is
  no worse than open loop (one test record is one unit; the plant's records differ in their forcing);
* the hand gain chosen (guarded) on four calibration records instead of one, judged on the eight test records
  and on eight fresh ones drawn apart (the fresh ones judged nothing else: the number of calibration records
  was set after the first eight had been seen).

    .venv/bin/python benchmarks/study_partial_cascade.py [--iterations 300]
"""

from __future__ import annotations

import argparse
import json

import torch

import fnnlib as F
from fnnlib.feedback import cascade_sweep, Gains
from fnnlib.metrics import n_step_errors
from fnnlib.models.neural_ode import init_parameters
from fnnlib.seeding import make_generator
from fnnlib.training import QUICK_RECIPE

F64 = torch.float64
TS = 0.05
C = torch.tensor([[1.0, 0.0]], dtype=F64)


def duffing(x: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
    p, v = x[..., 0], x[..., 1]
    return torch.stack([v, -0.3 * v - p - 0.5 * p ** 3 + u[..., 0]], -1)


def simulate(x0, u, substeps=10):
    xs, x = [x0], x0
    for k in range(u.shape[-2] - 1):
        for _ in range(substeps):
            x = x + TS / substeps * duffing(x, u[..., k, :])
        xs.append(x)
    return torch.stack(xs, -2)


def forcing(B, T, gen):
    w = 0.5 + torch.rand(B, 1, 1, generator=gen, dtype=F64)
    t = torch.arange(T, dtype=F64)[None, :, None] * TS
    return torch.sin(w * t) + 0.3 * torch.sin(2.7 * w * t + 1.0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--iterations", type=int, default=300)
    args = ap.parse_args()
    torch.set_num_threads(1)
    gen = make_generator(0)
    T_train = 200
    u_tr = forcing(8, T_train, gen)
    x_tr = simulate(torch.randn(8, 2, generator=gen, dtype=F64), u_tr)
    model = init_parameters(F.NeuralODE(2, (50, 50), "tanh", n_input=1).double(), gen)
    recipe = QUICK_RECIPE.replace(iterations=args.iterations, batch_size=32, batch_time=10)
    F.train_neural_ode(model, torch.arange(T_train, dtype=F64) * TS, x_tr, recipe, seed=0, u=u_tr, progress=False)
    A = F.model_jacobian(model, torch.zeros(2, dtype=F64), torch.zeros(1, dtype=F64))
    L_y = F.place_observer_gain(torch.eye(2, dtype=F64) + TS * A, TS * C, [0.85, 0.9])
    obs = F.MeasuredFeedback(model, TS, L=L_y, measurement=F.Measurement(C=C), A=A)
    T = 600
    u = forcing(2, T, gen)
    x = simulate(0.5 * torch.randn(2, 2, generator=gen, dtype=F64), u)  # [0] calibration, [1] test
    lost = torch.rand(2, T, generator=gen) < 0.2
    gen2 = make_generator(1)  # a second calibration record, drawn apart so that the others stay as they were
    u2 = forcing(1, T, gen2)
    x2 = simulate(0.5 * torch.randn(1, 2, generator=gen2, dtype=F64), u2)
    lost2 = torch.rand(1, T, generator=gen2) < 0.2
    gen3 = make_generator(2)  # eight more test records, drawn apart
    u8 = forcing(8, T, gen3)
    x8 = simulate(0.5 * torch.randn(8, 2, generator=gen3, dtype=F64), u8)
    lost8 = torch.rand(8, T, generator=gen3) < 0.2
    gen4, gen5 = make_generator(3), make_generator(4)  # four calibration records; eight fresh test records
    u4 = forcing(4, T, gen4)
    x4 = simulate(0.5 * torch.randn(4, 2, generator=gen4, dtype=F64), u4)
    lost4 = torch.rand(4, T, generator=gen4) < 0.2
    u8b = forcing(8, T, gen5)
    x8b = simulate(0.5 * torch.randn(8, 2, generator=gen5, dtype=F64), u8b)
    lost8b = torch.rand(8, T, generator=gen5) < 0.2
    rows = []
    for N in (10, 25):
        for noise in (0.0, 0.02, 0.05):
            y = x @ C.T + noise * torch.randn(2, T, 1, generator=gen, dtype=F64)
            y[lost] = float("nan")
            settle = T // 4
            y2 = x2 @ C.T + noise * torch.randn(1, T, 1, generator=gen2, dtype=F64)
            y2[lost2] = float("nan")
            y_cal, u_cal = torch.cat([y[:1], y2]), torch.cat([u[:1], u2])

            def score(z, k=1):
                return float(n_step_errors(z, x[k], N)[settle:].mean())

            def position(z, k=1):  # the measured component only
                return float(n_step_errors(z[..., :1], x[k, :, :1], N)[settle:].mean())

            def measured_score(z, target=y[0]):  # calibration: the measured position N samples later, present ones
                e = (z[..., : T - N, :1] - target[..., N:, :]).pow(2)[..., settle:, :]
                return float(e.nan_to_num(0).sum() / (~torch.isnan(e)).sum())

            def per_start(z, target=y[0]):  # calibration: squared error of the measured position, per start
                return (z[..., : T - N, :1] - target[..., N:, :]).pow(2).sum(-1)[..., settle:]

            grid = torch.tensor([0.0, 0.25, 0.5, 1.0, 2.0, 4.0], dtype=F64)  # 0: the feedback switched off
            sweep = cascade_sweep(model, y[0], TS, N, Gains.sweep(grid, 0.05), u=u[0], observer=obs)
            L_hand = float(grid[min(range(len(grid)), key=lambda g: measured_score(sweep[g]))])
            tuned = F.tune_gains(model, y[0], TS, N,
                                 recipe=F.TuneRecipe(L0=1.0, beta0=0.05, iterations=60, lr=0.1, settle=settle),
                                 u=u[0], observer=obs)
            sweep2 = cascade_sweep(model, y_cal, TS, N, Gains.sweep(grid, 0.05), u=u_cal, observer=obs)
            L_hand2 = float(grid[min(range(len(grid)), key=lambda g: measured_score(sweep2[g], y_cal))])
            tuned2 = F.tune_gains(model, y_cal, TS, N,
                                  recipe=F.TuneRecipe(L0=1.0, beta0=0.05, iterations=60, lr=0.1, settle=settle),
                                  u=u_cal, observer=obs)
            q_d = 1e-3
            R = max(noise, 0.005) ** 2
            ekf = F.ExtendedKalmanObserver(model, TS, n=2, cov=F.Covariances([1e-6, 1e-6, q_d], R), C=C,
                                           disturbance=[1], A=A)
            ukf = F.UnscentedKalmanObserver(model, TS, n=2, cov=F.Covariances([1e-6, 1e-6, q_d], R), C=C,
                                            disturbance=[1], A=A)
            row = {"N": N, "noise": noise, "hand L": L_hand, "tuned L": [round(v, 3) for v in tuned.L.tolist()],
                   "tuned beta": round(tuned.beta, 3),
                   "cascade, hand gains": score(F.cascade_predict(model, y[1], TS, N, F.Gains(L_hand, 0.05), u=u[1],
                                                                  observer=obs)),
                   "cascade, tuned gains": score(F.cascade_predict(model, y[1], TS, N,
                                                                   tuned.schedule(), u=u[1],
                                                                   observer=obs)),
                   "open loop from the observer": score(obs.predict(y[1], N, u[1])),
                   "EKF": score(ekf.predict(y[1], N, u[1])), "UKF": score(ukf.predict(y[1], N, u[1]))}
            z_tuned_cal = F.cascade_predict(model, y[0], TS, N, tuned.schedule(), u=u[0],
                                            observer=obs)
            g_hand = F.choose_gain(per_start(sweep))
            g_tuned = F.choose_gain(torch.stack([per_start(sweep[0]), per_start(z_tuned_cal)]))
            L_guard = float(grid[g_hand.index])
            row["guarded: hand L, tuned kept"] = [L_guard, bool(g_tuned.index)]
            row["guarded: cascade hand / tuned"] = [
                round(score(F.cascade_predict(model, y[1], TS, N, F.Gains(L_guard, 0.05), u=u[1], observer=obs)), 4),
                round(score(F.cascade_predict(model, y[1], TS, N, tuned.schedule(), u=u[1],
                                              observer=obs)
                            if g_tuned.index else obs.predict(y[1], N, u[1])), 4)]
            y8 = x8 @ C.T + noise * torch.randn(8, T, 1, generator=gen3, dtype=F64)
            y8[lost8] = float("nan")

            def per_record(z):
                return n_step_errors(z, x8, N)[..., settle:].mean(-1)

            ol8 = per_record(obs.predict(y8, N, u8))
            eight = {"open loop": ol8,
                     "hand": per_record(F.cascade_predict(model, y8, TS, N, F.Gains(L_hand, 0.05), u=u8, observer=obs)),
                     "tuned": per_record(F.cascade_predict(model, y8, TS, N, tuned.schedule(),
                                                           u=u8, observer=obs)),
                     "EKF": per_record(ekf.predict(y8, N, u8))}
            y4 = x4 @ C.T + noise * torch.randn(4, T, 1, generator=gen4, dtype=F64)
            y4[lost4] = float("nan")
            sweep4 = cascade_sweep(model, y4, TS, N, Gains.sweep(grid, 0.05), u=u4, observer=obs)  # (K, 4, T, n)
            L_four = float(grid[F.choose_gain(per_start(sweep4, y4)).index])
            y8b = x8b @ C.T + noise * torch.randn(8, T, 1, generator=gen5, dtype=F64)
            y8b[lost8b] = float("nan")
            fresh_ol = n_step_errors(obs.predict(y8b, N, u8b), x8b, N)[..., settle:].mean(-1)
            fresh = n_step_errors(F.cascade_predict(model, y8b, TS, N, F.Gains(L_four, 0.05), u=u8b, observer=obs), x8b,
                                    N)[..., settle:].mean(-1)
            four = per_record(F.cascade_predict(model, y8, TS, N, F.Gains(L_four, 0.05), u=u8, observer=obs))
            row["four calibration records, guarded: L; on the eight; on eight fresh (open loop)"] = [
                L_four, [round(float(four.mean()), 4), int((four <= ol8 + 1e-12).sum())],
                [round(float(fresh.mean()), 4), int((fresh <= fresh_ol + 1e-12).sum()),
                 round(float(fresh_ol.mean()), 4)]]
            row["eight test records: mean (records no worse than open loop)"] = {
                k: [round(float(v.mean()), 4), int((v <= ol8 + 1e-12).sum())] for k, v in eight.items()}
            row["two calibration records: hand L"] = L_hand2
            row["two calibration records: cascade hand / tuned"] = [
                round(score(F.cascade_predict(model, y[1], TS, N, F.Gains(L_hand2, 0.05), u=u[1], observer=obs)), 4),
                round(score(F.cascade_predict(model, y[1], TS, N, tuned2.schedule(), u=u[1],
                                              observer=obs)), 4)]
            row["position only: cascade hand / tuned / open loop"] = [
                round(position(F.cascade_predict(model, y[1], TS, N, F.Gains(L_hand, 0.05), u=u[1], observer=obs)), 4),
                round(position(F.cascade_predict(model, y[1], TS, N, tuned.schedule(), u=u[1],
                                                 observer=obs)), 4),
                round(position(obs.predict(y[1], N, u[1])), 4)]
            rows.append(row)
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
