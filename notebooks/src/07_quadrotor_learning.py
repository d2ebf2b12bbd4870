# %% [markdown]
# # Learning a quadrotor's aerodynamic residual with external inputs (Sec. 5.2.1, App. A.1, A.5.2; Fig. A, S4-S7)
#
# A neural ODE on $(v, \Theta)$ is added to the nominal quadrotor model Eq. (27) to capture aerodynamic drag,
# $\dot v = -\tfrac1m Z_B T + g Z_E + f_{neural}(v, \Theta)$. The open-loop model is unstable, so, as in the
# paper, it is trained inside the closed loop of a differential-flatness-based controller (DFBC):
# $[x, z]_{i+1} = \Phi^d([x, z]_i, \bar\Psi_i)$, with the commands $\bar\Psi = [p, v, a, j]$ as external
# inputs, by App. A.1's training (forward rollout, explicit adjoint recursion Eq. (17), gradient Eq. (18),
# Adam over mini-batched segments, Alg. 2-3). Data: 40 minimum-snap commands of 200 nodes at 0.02 s through
# random waypoints, flown by the DFBC on a "true" vehicle with drag $R D R^\top v$. Claims **Q1** (training
# converges for 5 random initialisations), **Q2** (the model predicts all 12 states on 3 flights 2.5x longer
# than the training ones) and **Q6** (training cost).
#
# Two sets of flights 2.5x longer, each of `val_flights` flights: the **selection** flights (seed + 1) give the
# validation curves and pick the networks kept for later chapters; the **held-out** flights (seed + 2) pick
# nothing and judge Q2, for every trained network.

# %% tags=["parameters"]
profile = "paper"
out_dir = "outputs/manual/quadrotor_learning"
# the settings and their paper values, from fnnbook.tasks.quadrotor_learning (written by `make notebooks`)
seed = 0
seeds = [0, 1, 2, 3, 4]
n_flights = 40
n_nodes = 200
n_waypoints = 3
val_flights = 3
val_nodes = 500
val_waypoints = 6
Ts = 0.02
truth_drag = [0.7, 0.7, 0.2]
truth_substeps = 4
hidden = [36, 36]
activation = "tanh"
epochs = 50
segment_length = 20
batch_size = 80
lr = 0.005
val_every = 10
mlp_epochs = 300
mlp_lr = 0.001

# %%

from fnnbook.tasks.quadrotor_learning import QuadrotorLearningSettings
settings = QuadrotorLearningSettings.from_namespace(globals())  # checked as `fnn-pipeline check` checks them

# %% tags=["hide-input"]
import time
from functools import partial
from pathlib import Path

import numpy as np
import torch

from fnnbook.results import headline_number, verdict_from_checks, write_results
from fnnlib.plotting import new_figure, save_figure
from fnnlib.training import save_checkpoint
from fnnlib.quadrotor.control.dfbc import DFBC
from fnnlib.data.quadrotor import make_flights, save_flights, single_step_labels
from fnnlib.quadrotor.residual import AeroResidual
from fnnbook.rules import quadrotor as rules
from fnnlib.quadrotor.mpc import FeedbackCascadeModel, PredictionModel
from fnnlib.quadrotor.presets import (PAPER_BETA, PAPER_DFBC_GAINS, PAPER_FLIGHT_DATA, PAPER_HORIZON, PAPER_L,
                                      PAPER_MLP_RECIPE)
from fnnlib.quadrotor.system import NOMINAL, STATE_GROUPS, TRAINING_TRUTH, Quadrotor
from fnnlib.quadrotor.training import (ResidualRecipe, convergence_checks, predict_flights, state_group_errors,
                                      train_residual_ensemble, train_single_step)

# %%
recipe = ResidualRecipe(hidden=hidden, activation=activation, segment_length=segment_length, batch_size=batch_size,
                        epochs=epochs, lr=lr)  # App. A.5.2's network and Alg. 3's training, checked
truth = TRAINING_TRUTH.replace(drag=tuple(truth_drag))  # validates the drag (>= 0)
out = Path(out_dir)
out.mkdir(parents=True, exist_ok=True)
controller, model_plant = DFBC(NOMINAL, **PAPER_DFBC_GAINS), Quadrotor(NOMINAL)
draws = {"box": PAPER_FLIGHT_DATA["box"], "max_speed": PAPER_FLIGHT_DATA["max_speed"]}  # the release's waypoints

# %%
tic = time.perf_counter()
train = make_flights(n_flights, n_nodes, Ts=Ts, seed=seed, truth=truth, controller=controller, n_waypoints=n_waypoints,
                     substeps=truth_substeps, **draws)
val = make_flights(val_flights, val_nodes, Ts=Ts, seed=seed + 1, truth=truth, controller=controller,
                   n_waypoints=val_waypoints, substeps=truth_substeps, **draws)  # selection: picks the kept networks
heldout = make_flights(val_flights, val_nodes, Ts=Ts, seed=seed + 2, truth=truth, controller=controller,
                       n_waypoints=val_waypoints, substeps=truth_substeps, **draws)  # held out: judges Q2 only
save_flights(out / "flights_train.npz", train, {"seed": seed, "drag": truth_drag})
save_flights(out / "flights_val.npz", val, {"seed": seed + 1, "drag": truth_drag})
save_flights(out / "flights_heldout.npz", heldout, {"seed": seed + 2, "drag": truth_drag})
print(f"flew {train.n_flights} training flights x {train.n_steps} nodes and 2 x {val.n_flights} validation flights "
      f"x {val.n_steps} nodes in {time.perf_counter() - tic:.1f} s; max thrust {float(train.u.max()):.2f} N, "
      f"max speed {float(train.x[..., 3:6].norm(dim=-1).max()):.1f} m/s")

# %%
fig, ax = new_figure(1, 1, subplot_kw={"projection": "3d"})
for k in range(train.n_flights):
    p = train.x[k, :, :3].numpy()
    ax.plot(p[:, 0], p[:, 1], -p[:, 2], lw=0.8)
ax.set(xlabel="x [m]", ylabel="y [m]", zlabel="height -z [m]", title=f"{train.n_flights} training flights")
save_figure(fig, out, "training_flights")

# %% [markdown]
# ## Training: 5 random initialisations at once (Q1, Q6)
# All initialisations train side by side in one batch: their closed loops are stacked along the state axis, so
# the loss is a sum of independent per-member losses and each member gets exactly the Adam updates it would get
# alone on the same mini-batches. Settings (the paper gives none beyond 50 epochs and Adam): segments of
# `segment_length` steps, `batch_size` segments per update, learning rate `lr`, float32; loss Eq. (13) with
# unit weights on the 12 vehicle states and zero on the 6 controller states (the authors' release).
#
# **Rule Q1** (`fnnbook.rules.quadrotor`), fixed before the run: at least 5 initialisations, and training *converges* for every initialisation when (a) its final
# training loss is at most 10 % of its initial loss and (b) the last 10 % of epochs change it by less than
# 20 %; and the initialisations agree: (c) the largest final loss is at most 2x the smallest.
#
# **Rule Q6**: the feedback part has no trainable parameter (it needs no training), counted on the feedback
# object the MPC flies (`FeedbackCascadeModel`, the paper's L, beta, N): a guarantee. The training time is judged
# against "around 30 mins" read as the band 15-60 min (a factor 2 either way: one rounded number for one laptop);
# below the band the cost beats the claim in its own direction and reads "better than claimed" (another machine
# than the paper's: a statement about the cost a reader pays, not a hardware match).

# %%
fit = train_residual_ensemble(seeds, train, recipe, controller=controller, plant=model_plant, val=val,
                              val_every=val_every)
member_loss = np.array(fit.member_loss)  # (epochs + 1, E)
val_loss = np.array(fit.val_loss)  # (len(val_epochs), E)
best = int(np.argmin(val_loss[-1]))  # picked on the selection flights only
per_model_s = fit.seconds / len(seeds)
print(f"{len(seeds)} initialisations x {epochs} epochs in {fit.seconds:.0f} s ({per_model_s:.0f} s per model, "
      f"{fit.history.n_updates} Adam updates each); kept seed {seeds[best]} (lowest loss on the selection flights)")

# %%
residual = fit.members[best].double()
save_checkpoint(out / "residual.pt", residual, {"seed": seeds[best], "epochs": epochs, "lr": lr,
                                                  "segment_length": segment_length, "val_loss": float(val_loss[-1, best])})
# every initialisation too: the MPC task flies each of them, one per independent unit
member_files = []
for e, s in enumerate(seeds):
    name = f"residual_seed{s}.pt"
    save_checkpoint(out / name, fit.members[e].double(), {"seed": s, "epochs": epochs, "lr": lr,
                                                            "val_loss": float(val_loss[-1, e])})
    member_files.append(name)

# %%
fig, axes = new_figure(1, 2)
axes = axes[0]
for e, s in enumerate(seeds):
    axes[0].semilogy(np.arange(epochs + 1), member_loss[:, e], label=f"seed {s}")
    axes[1].semilogy(fit.val_epochs, val_loss[:, e], "o-", label=f"seed {s}")
axes[0].set(xlabel="epoch", ylabel="training loss (per segment)", title="Training curves (Fig. A, right)")
axes[1].set(xlabel="epoch", ylabel="validation loss (per flight)",
            title=f"{val.n_flights} selection flights, 2.5x longer")
axes[0].legend(fontsize=7)
save_figure(fig, out, "training_curves")

# %% [markdown]
# ## The MLP baseline (App. A.5.4)
# A feed-forward network of the same size trained single-step: labels are the finite-difference acceleration
# minus the nominal model's, $(v_{i+1} - v_i)/T_s - a_{nom}(x_i, u_i)$, on the same flights (mean squared
# error, Adam). One MLP per seed, like the residual networks (seed $s$ draws its initial weights and its
# mini-batches), so the MPC comparison has one MLP per independent unit; the one kept for single flights is
# picked by its single-step error on the selection flights.

# %%
x_ss, y_ss = single_step_labels(train, model_plant)
x_sel, y_sel = single_step_labels(val, model_plant)
mlps, mlp_loss, mlp_sel_mse = [], [], []
tic = time.perf_counter()
for s in seeds:
    torch.manual_seed(s)
    net = AeroResidual(hidden, activation).double()
    mlp_loss.append(train_single_step(net, x_ss, y_ss, epochs=mlp_epochs, batch_size=PAPER_MLP_RECIPE["batch_size"],
                                      lr=mlp_lr, seed=s))
    with torch.no_grad():
        mlp_sel_mse.append(float(torch.mean((net(x_sel) - y_sel) ** 2)))
    mlps.append(net)
mlp_s = time.perf_counter() - tic

# %%
best_mlp = int(np.argmin(mlp_sel_mse))
mlp_files = []
for e, s in enumerate(seeds):
    meta = {"seed": s, "mlp_epochs": mlp_epochs, "mlp_lr": mlp_lr, "final_mse": mlp_loss[e][-1],
            "selection_mse": mlp_sel_mse[e]}  # the run record's names, checked when loaded
    save_checkpoint(out / f"mlp_seed{s}.pt", mlps[e], meta)
    mlp_files.append(f"mlp_seed{s}.pt")
    if e == best_mlp:
        save_checkpoint(out / "mlp.pt", mlps[e], meta)
print(f"{len(seeds)} MLPs in {mlp_s:.1f} s; single-step MSE " + ", ".join(
    f"seed {s}: {loss[0]:.3f} -> {loss[-1]:.4f}" for s, loss in zip(seeds, mlp_loss))
      + f" (m/s^2)^2; kept seed {seeds[best_mlp]} (lowest on the selection flights)")

# %% [markdown]
# ## Validation on 3 held-out flights 2.5x longer (Q2, Figs. S4-S7)
# Each held-out flight is re-flown by the model from its first state, driven only by the recorded commands
# (the closed loop with the model in place of the vehicle, no correction from measurements for 10 s).
# Errors per state group: RMSE of the group's error norm over the RMS norm of its flown values, over all the
# held-out flights; every trained network is judged, the nominal model (no residual) and the kept MLP are
# predicted the same way. These flights chose nothing: the kept network and MLP were picked on the selection
# flights.
#
# **Rule Q2**, fixed before the run: (a) the learned model's relative RMSE is at most 10 % for every group
# (p, v, Theta, omega), i.e. all 12 states are predicted, in at least S - 1 of the S trained networks; (b) it
# is below the nominal model's for p and for v, paired over the S networks (`fnnlib.stats.paired_win`: lower
# for S - 1 of S and the 90 % interval of the mean difference below 0). The unit is the trained network: the
# nominal model has no network and one error on these flights, the same for every unit.

# %%
true = heldout.x[..., :12]
# the closed loop with a residual (None: nominal) re-flown on the held-out flights: (K, T + 1, 18)
held_out = partial(predict_flights, flights=heldout, controller=controller, plant=model_plant)
pred_members = [held_out(m.double())[..., :12] for m in fit.members]  # every trained network
pred = {"neural ODE": pred_members[best], "nominal": held_out(None)[..., :12],
        "MLP": held_out(mlps[best_mlp])[..., :12]}  # the kept ones
rel = {"neural ODE": [state_group_errors(x, true) for x in pred_members]} | {
    name: state_group_errors(pred[name], true) for name in ("nominal", "MLP")}
for s, r in zip(seeds, rel["neural ODE"]):
    print(f"neural ODE seed {s}: " + "  ".join(f"{g}: {100 * v:5.2f} %" for g, v in r.items()))
for name in ("nominal", "MLP"):
    print(f"{name:17s}: " + "  ".join(f"{g}: {100 * v:5.2f} %" for g, v in rel[name].items()))

# %%
labels = {"p": ["x", "y", "z"], "v": ["vx", "vy", "vz"], "Theta": ["roll", "pitch", "yaw"], "omega": ["wx", "wy", "wz"]}
t_val = np.arange(heldout.n_steps + 1) * Ts
for k in range(heldout.n_flights):
    fig, axes = new_figure(4, 3, sharex=True)
    for r, (g, sl) in enumerate(STATE_GROUPS.items()):
        for c in range(3):
            ax = axes[r, c]
            ax.plot(t_val, true[k, :, sl][:, c].numpy(), color="k", lw=1.2, label="flown")
            ax.plot(t_val, pred["neural ODE"][k, :, sl][:, c].numpy(), "--", lw=1.0, label="neural ODE")
            ax.plot(t_val, pred["nominal"][k, :, sl][:, c].numpy(), ":", lw=1.0, label="nominal")
            ax.set_ylabel(labels[g][c])
    axes[-1, 1].set_xlabel("t [s]")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(f"Held-out flight {k + 1}: all 12 states, kept network (seed {seeds[best]}) (Figs. S5-S7)")
    save_figure(fig, out, f"validation_flight_{k + 1}")

# %% [markdown]
# ## Verdicts

# %% tags=["nbval-check-output"]
final, first = member_loss[-1], member_loss[0]
feedback = FeedbackCascadeModel(PredictionModel("Neural", model_plant, residual, Ts=Ts), PAPER_L, PAPER_BETA, PAPER_HORIZON)
n_feedback_params = rules.count_trainable(t for t in vars(feedback).values() if isinstance(t, torch.Tensor))
r1, r2 = rules.q1_convergence(member_loss), rules.q2_prediction(rel["neural ODE"], rel["nominal"], units=seeds)
r6 = rules.q6_training_cost(n_feedback_params, per_model_s * 50 / epochs)
for q, r in (("Q1", r1), ("Q2", r2), ("Q6", r6)):
    print(q, verdict_from_checks(r.checks), r.checks)

# %%
q1 = r1.replace(figure="figures/training_curves.png",
               numbers={"seeds": seeds, "initial_loss": first.tolist(), "val_loss_final": val_loss[-1].tolist(), **r1.numbers},
               headline=headline_number("final / initial training loss", final / first),
               paper="training converges for 5-6 random initialisations (Fig. A)", title="Training converges")

# %%
q2 = r2.replace(figure="figures/validation_flight_1.png",
               numbers={**r2.numbers, "MLP (kept)": rel["MLP"], "seeds": seeds},
               headline=headline_number("neural ODE relative RMSE of p, held-out flights",
                                          [r["p"] for r in rel["neural ODE"]]),
               paper="the learned model predicts all 12 states on 3 flights 2.5x longer than training (Figs. S4-S7)",
               rule=f"{r2.rule} (over {r2.n} trained networks, on {heldout.n_flights} held-out flights)",
               title="Long-horizon prediction")

# %%
claims = [
    q1,
    q2,
    r6.replace(figure="figures/training_curves.png",
               numbers={**r6.numbers, "seconds_all_members": round(fit.seconds, 1), "members": len(seeds),
                        "ms_per_update": round(fit.history.ms_per_update, 1), "updates": fit.history.n_updates},
               headline=headline_number("training time per model, 50 epochs (authors: 30 min)", per_model_s * 50 / epochs, unit="s"),
               paper="linear feedback needs no training; about 30 min for 50 epochs on a 14-core laptop",
               title="Training cost"),
]

# %%
write_results(out, task="quadrotor_learning", profile=profile, claims=claims,
                metrics={"best_seed": seeds[best], "best_mlp_seed": seeds[best_mlp],
                         "mlp_final_mse": [loss[-1] for loss in mlp_loss], "mlp_selection_mse": mlp_sel_mse,
                         "mlp_seconds": round(mlp_s, 1), "epochs": epochs, "member_checkpoints": member_files,
                         "mlp_checkpoints": mlp_files})
for c in claims:
    print(c.id, c.verdict, c.checks)
