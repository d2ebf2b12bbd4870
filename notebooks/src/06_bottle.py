# %% [markdown]
# # Trajectory prediction of a thrown irregular bottle (Sec. 5.1, Fig. 6, S2, S3)
#
# A bottle thrown by hand flies an approximately parabolic path under complicated aerodynamics. From every
# sample of each of the 9 test throws we predict the position 0.5 s ahead (500 steps of 1 ms, rolled forward)
# with three models: a quadratic drag model fitted by least squares (the model-based baseline), a neural ODE on
# the state [position, velocity] trained on the 21 training throws, and the same neural ODE with the linear
# feedback of Eqs. (7)-(8) in the cascade of Sec. 3.3 with gain decay Eq. (11) (claims **O1**, **O2**).
# The throws are the real ones recorded for EVOLVER (Jia et al., T-RO 2024), read from the data directory.

# %% tags=["parameters"]
profile = "paper"
out_dir = "outputs/manual/bottle"
data_dir = "data"
data = "real"
seed = 0
hidden = [100, 100, 100]
activation = "relu"
iterations = 1000
batch_size = 20
batch_time = 10
lr = 0.001
method = "dopri5"
adjoint = False
L = 5.0
beta = 0.02
N = 500
synthetic_sizes = [21, 9, 1058]

# %%
import fnnlib as F

F.check_notebook_settings("bottle", globals())  # the checks `fnn-pipeline check` runs first

# %% [tags: hide-input]
import time
from pathlib import Path

import numpy as np
import torch

import fnnlib as F

if data not in ("real", "synthetic"):
    raise ValueError(f"data must be 'real' or 'synthetic', got {data!r}")
if data == "real":
    train, test = F.load_bottle(data_dir)  # checks SHA-256 and shapes before any work
else:
    n_tr, n_te, n_s = synthetic_sizes
    train, test = F.synthetic_throws(n_tr, n_s, seed=seed), F.synthetic_throws(n_te, n_s, seed=seed + 1)
Ts = train.Ts
F.decayed_gains(F.check_gain(L, 6, Ts), N, beta)  # refuse an unstable gain or bad decay up front
if not 1 <= N < test.data.shape[1]:
    raise ValueError(f"need 1 <= N < {test.data.shape[1]} samples, got N={N}")

# %%
out = Path(out_dir)
out.mkdir(parents=True, exist_ok=True)
x_train, x_test = train.state.float(), test.state.float()  # (throws, T, 6)
t_test = test.t.numpy()
print(f"{data} throws: train {tuple(train.data.shape)}, test {tuple(test.data.shape)}, Ts = {Ts} s")

# %% [markdown]
# ## Models
# The drag model $\dot v = k \odot \lVert v\rVert v - g e_z$ with $k$ fitted per axis by least squares on the
# measured accelerations of the training throws; the neural ODE (MLP 3 hidden layers of 100, ReLU; Adam
# $10^{-3}$; batch 20 segments of 10 samples; 1000 iterations; dopri5 with direct back-propagation, as the
# authors' release: the paper gives no solver).

# %%
drag = F.fit_drag(train.data[..., 6:9], train.acc)
recipe = F.PAPER_BOTTLE_RECIPE.replace(iterations=iterations, batch_size=batch_size, batch_time=batch_time, lr=lr,
                                       method=method, adjoint=adjoint)
F.seed_everything(seed)
model = F.NeuralODE(6, hidden, activation)
history = F.train_neural_ode(model, train.t.float(), x_train, recipe, seed=seed)
F.save_checkpoint(out / "neural_ode.pt", model, {"seed": seed, "data": data, "final_loss": history.loss[-1]})
print(f"drag k = {drag.k.numpy().round(4)}; neural ODE trained in {history.seconds:.1f} s, "
      f"final loss {history.loss[-1]:.4f}")

# %% [markdown]
# ## 0.5 s predictions from every sample of every test throw (Fig. 6, claim O1)
# All starts of all throws in one batched pass per model; every model rolls Euler steps of 1 ms, the
# cascade's own discretisation. Error: 2-norm of the position error 0.5 s ahead.

# %%
t0 = time.perf_counter()
pred = {"drag model": F.rollout_predict(drag, x_test.double(), Ts, N).float(),
        "neural ODE": F.rollout_predict(model, x_test, Ts, N),
        "feedback": F.cascade_predict(model, x_test, Ts, N, L, beta)}
predict_s = time.perf_counter() - t0
err = {k: F.error_norm(z[:, :-N, :3], x_test[:, N:, :3]) for k, z in pred.items()}  # (throws, T - N)
summary = {k: {"mean": float(e.mean()), "std_over_throws": float(e.mean(1).std()),
               "per_throw": e.mean(1).tolist()} for k, e in err.items()}
{k: (round(v["mean"], 4), round(v["std_over_throws"], 4)) for k, v in summary.items()}

# %%
colors = {"drag model": "luenberger", "neural ODE": "neural_ode", "feedback": "feedback"}
fig, ax = F.new_figure()
for name, e in err.items():
    mu, sd = e.mean(0).numpy(), e.std(0).numpy()
    c = F.plotting.COLORS[colors[name]]
    ax.plot(t_test[N:], mu, color=c, label=name)
    ax.fill_between(t_test[N:], mu - sd, mu + sd, color=c, alpha=0.2)
ax.set(xlabel="t [s] (time of the predicted position)", ylabel="0.5 s position error [m]",
       title="Fig. 6: mean ± std over test throws")
ax.legend()
fig_6 = F.save_figure(fig, out, "fig6_bottle_errors")

# %% [markdown]
# ## Predicted positions and learned accelerations of all test throws (Figs. S2, S3, claim O2)
# The feedback network's corrected change rate $\hat f$ (Eq. (7)) holds a learned acceleration in its
# velocity part; it is compared with the measured one and with the open-loop neural ODE's.

# %%
est = F.LinearFeedback(model, L, Ts, 6).observe(x_test)
with torch.no_grad():
    acc_nn = F.eval_field(model, x_test)[..., 3:]
acc_fb, acc_meas = est.f_hat[..., 3:], test.acc.float()
acc_rmse = {"neural ODE": F.rmse(acc_nn, acc_meas), "feedback": F.rmse(acc_fb, acc_meas)}

# %%
n_throws = x_test.shape[0]
fig, axes = F.plotting.trajectory_grid(n_throws)
for i, ax in enumerate(axes):
    for j in range(3):
        ax.plot(t_test, x_test[i, :, j], color=F.plotting.COLORS["truth"], lw=1)
        ax.plot(t_test[N:], pred["feedback"][i, :-N, j], "--", color=F.plotting.COLORS["feedback"], lw=1)
    ax.set(title=f"test throw {i + 1}", xlabel="t [s]", ylabel="position [m]")
fig_s2 = F.save_figure(fig, out, "figS2_positions")

# %%
fig, axes = F.plotting.trajectory_grid(n_throws)
for i, ax in enumerate(axes):
    for j in range(3):
        ax.plot(t_test, acc_meas[i, :, j], color=F.plotting.COLORS["truth"], lw=1)
        ax.plot(t_test, acc_nn[i, :, j], ":", color=F.plotting.COLORS["neural_ode"], lw=1)
        ax.plot(t_test, acc_fb[i, :, j], "--", color=F.plotting.COLORS["feedback"], lw=1)
    ax.set(title=f"test throw {i + 1}", xlabel="t [s]", ylabel="acceleration [m/s²]")
fig_s3 = F.save_figure(fig, out, "figS3_accelerations")
acc_rmse

# %% [markdown]
# ## Verdicts
# - **O1**: on the mean over the test throws of the 0.5 s position error, feedback < neural ODE (i) and
#   neural ODE < drag model (ii).
# - **O2**: (i) the feedback network's learned accelerations are closer to the measured ones (RMSE over all
#   samples of the test throws) than the neural ODE's; (ii) its predicted positions "almost overlap" the truth:
#   the mean 0.5 s position error is below 10 % of the mean distance flown in 0.5 s.

# %% [tags: nbval-check-output]
travel = float(F.error_norm(x_test[:, N:, :3], x_test[:, :-N, :3]).mean())
m = {k: v["mean"] for k, v in summary.items()}
per_throw = {f"per_throw_{k}": summary[name]["per_throw"] for k, name in
             [("feedback", "feedback"), ("neural_ode", "neural ODE"), ("drag", "drag model")]}
claims = [
    F.claim_result("O1", checks={"feedback<neural_ode": m["feedback"] < m["neural ODE"],
                                 "neural_ode<drag": m["neural ODE"] < m["drag model"]},
                   numbers={"mean_error_m": m, "std_over_throws_m": {k: v["std_over_throws"] for k, v in
                                                                     summary.items()},
                            **per_throw, "data": data},
                   rule="mean 0.5 s position error over the test throws: feedback < neural ODE < drag model",
                   figure=fig_6)]

# %%
claims += [
    F.claim_result("O2", checks={"feedback_acc_closer": acc_rmse["feedback"] < acc_rmse["neural ODE"],
                                 "positions_overlap": m["feedback"] < 0.1 * travel},
                   numbers={"acc_rmse": acc_rmse, "mean_travel_0.5s_m": travel,
                            "feedback_mean_error_m": m["feedback"], "data": data},
                   rule="feedback acceleration RMSE < neural ODE's; mean feedback error < 10 % of the distance "
                        "flown in 0.5 s", figure=fig_s2),
]

# %%
F.write_results(out, task="bottle", profile=profile, claims=claims,
                metrics={"train_seconds": history.seconds, "predict_seconds": predict_s, "drag_k": drag.k})
for c in claims:
    print(f"{c['id']}: {c['verdict']:15s} {c['checks']}")
