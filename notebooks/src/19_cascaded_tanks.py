# %% [markdown]
# # A real plant: the cascaded tanks benchmark
#
# The paper's claim is that feedback helps a learned model on a real system it was not trained on. Here the
# system is a benchmark of nonlinear system identification that nobody on this project recorded: the
# **cascaded tanks** (M. Schoukens, P. Mattsson, T. Wigren, J.-P. Noël, Workshop on Nonlinear System
# Identification Benchmarks, 2016; data on nonlinearbenchmark.org and 4TU.ResearchData). A pump (input $u$,
# volts) fills an upper tank that drains into a lower one; only the lower level $y$ is measured (volts),
# with real sensor noise, and it saturates at 10 V when the tank overflows. Two states, one of them never
# measured, an input, noise and a hard nonlinearity: $y = C x$ with $C = [0, 1]$.
#
# The benchmark's protocol: fit on the estimation record (`uEst`, `yEst`, 1024 samples at $T_s$ = 4 s),
# judge on the validation record (`uVal`, `yVal`), tune nothing on the latter. Its metric is the RMSE of
# the **simulated** (free-run) output on the validation record, in volts. The initial state of a record is
# unknown; here every model of ours starts from the first `n_init` measured samples of the record and is
# scored on the samples after them (the variant this page uses throughout).
#
# The learned model is a two-state neural ODE $f(t, x, u)$ whose upper level is never measured: it is learned
# from `uEst` and `yEst` alone, through its feedback observer (Eqs. (7)-(8) on $y = C x$), for each of the
# `seeds`, and judged on the validation record beside a linear baseline and the published results.
#
# The data file is read from the data directory (`fnn-pipeline data fetch --tanks` gets it from the
# official archive, SHA-256 checked); without it this chapter does not run and says so.

# %% tags=["parameters"]
profile = "paper"
out_dir = "outputs/manual/cascaded_tanks"
data_dir = "data"
# the settings and their paper values, from fnnbook.tasks.cascaded_tanks (written by `make notebooks`)
data = "real"
synthetic_samples = 1024
synthetic_noise = 0.02
seed = 0
n_init = 5
arx_max_order = 4
seeds = [0, 1, 2, 3, 4]
hidden = [16, 16]
activation = "tanh"
x_center = 5.0
x_scale = 3.0
u_center = 3.0
u_scale = 2.0
rate = 0.05
observer_gain = [0.02, 0.15]
train_N = 25
train_iterations = 80
train_lr = 0.01
L_start = 0.01
beta_start = 0.1
horizons = [1, 5, 10, 25, 50]
hand_L_grid = [0.005, 0.01, 0.02, 0.05]
hand_beta_grid = [0.0, 0.1, 0.2]
kf_q = [0.0001, 0.0001]
kf_qd_grid = [1e-08, 1e-06]
kf_r = 0.0004
overflow_after = 25
overflow_gap = 3
series_N = 10
baseline_starts = ["free", "encoder"]
baseline_horizon = 100

# %% tags=["remove-input"]
from fnnbook.tasks.cascaded_tanks import CascadedTanksSettings
settings = CascadedTanksSettings.from_namespace(globals())  # checked as `fnn-pipeline check` checks them

# %% tags=["hide-input"]
from pathlib import Path

import numpy as np
from IPython.display import Markdown, display

from fnnbook.results import write_results
from fnnlib.data.tanks import simulation_rmse, tanks_records
from fnnlib.models.arx import select_arx
from fnnlib.plotting import new_figure, save_figure
from fnnlib.data.tanks import PUBLISHED_RESULTS

rec = tanks_records(data, data_dir=data_dir, n_samples=synthetic_samples, seed=seed, noise_std=synthetic_noise)
out = Path(out_dir)
out.mkdir(parents=True, exist_ok=True)
t = rec.t.numpy()
sat = {k: int(rec.saturated(k).sum()) for k in ("est", "val")}
print(f"{rec.source} records: {rec.y_est.shape[0]} samples each at Ts = {rec.Ts} s; "
      f"samples at the 10 V limit: estimation {sat['est']}, validation {sat['val']}")

# %% [markdown]
# ## The records
# The input and the measured level of both records; the samples where the level sits at the sensor's
# 10 V limit (the overflow) are marked.

# %% tags=["hide-input"]
fig, ax = new_figure(2, 2)
for j, (name, u, y, k) in enumerate([("estimation", rec.u_est, rec.y_est, "est"),
                                     ("validation", rec.u_val, rec.y_val, "val")]):
    ax[0, j].plot(t, u.numpy()[:, 0], lw=0.8)
    ax[0, j].set(title=f"{name} record", ylabel="pump u [V]")
    ax[1, j].plot(t, y.numpy()[:, 0], lw=0.8, color="k")
    s = rec.saturated(k).numpy()
    ax[1, j].plot(t[s], y.numpy()[s, 0], "r.", ms=3, label="at the 10 V limit")
    ax[1, j].set(xlabel="t [s]", ylabel="lower level y [V]")
    ax[1, j].legend(loc="lower right")
records_figure = save_figure(fig, out, "tanks_records")

# %% [markdown]
# ## A linear baseline measured here
# An ARX model $y_k = \sum_{i=1}^{n_a} a_i y_{k-i} + \sum_{j=0}^{n_b-1} b_j u_{k-n_k-j} + c$, fitted by least
# squares on the estimation record. Its orders ($n_a, n_b \le$ `arx_max_order`, $n_k \in \{0, 1\}$) are the
# ones whose free-run simulation of the *estimation* record is best; then it is simulated once over the
# validation record from its first `n_init` measured samples.

# %% tags=["hide-input"]
arx, arx_grid = select_arx(rec.u_est, rec.y_est, na=range(1, arx_max_order + 1), nb=range(1, arx_max_order + 1),
                           nk=(0, 1), n_init=n_init)
arx_val = arx.simulate(rec.u_val, rec.y_val, n_init=n_init)
arx_rmse = {"estimation": min(arx_grid.values()), "validation": simulation_rmse(arx_val, rec.y_val, skip=n_init)}
print(f"ARX orders na={len(arx.a)}, nb={len(arx.b)}, nk={arx.nk}; free-run RMSE: estimation "
      f"{arx_rmse['estimation']:.4f} V, validation {arx_rmse['validation']:.4f} V (samples {n_init}..{len(t) - 1})")

# %% tags=["hide-input"]
fig, ax = new_figure(1, 1)
ax.plot(t, rec.y_val.numpy()[:, 0], "k", lw=0.8, label="measured")
ax.plot(t, arx_val, lw=0.8, label=f"ARX free run ({arx_rmse['validation']:.3f} V)")
s = rec.saturated("val").numpy()
ax.plot(t[s], rec.y_val.numpy()[s, 0], "r.", ms=3, label="at the 10 V limit")
ax.set(xlabel="t [s]", ylabel="lower level y [V]", title="validation record")
ax.legend(loc="lower right")
simulation_figure = save_figure(fig, out, "tanks_free_run")

# %% [markdown]
# ## A neural ODE learned from the level, through its observer
# Each seed's model is a small MLP field in the data's volts,
# $f(t, x, u) = r\,\mathrm{MLP}((x - x_c)/x_s, (u - u_c)/u_s)$ (`fnnlib.models.scaled.ScaledField`), on the
# state $x = (x_1, x_2)$ = (upper, lower level); only $y = x_2$ is measured. It is trained on the estimation
# record through its feedback observer: Eqs. (7)-(8) with the output gain `observer_gain` estimate the hidden
# upper level from $y$, and the cascade of Sec. 3.3 (Eq. (11)) predicts `train_N` samples ahead from every
# estimate; Adam descends on the model and on the cascade's gain and decay rate together
# (`fnnlib.tune_gains(..., TuneRecipe(train_model=True), observer=...)`): the gains it ends with are the **tuned gains**.
# The **hand gains** are, per seed, the best $(L, \beta)$ of a small sweep (`hand_L_grid` x `hand_beta_grid`) by
# the `train_N`-step error on the estimation record. The seeds train as one stacked ensemble (each member
# with its own block of the observer, its own gains and decay rate; their losses add, their gradients never mix),
# which gives each seed what it would get alone, in one run.
#
# The baseline **without feedback** is the same architecture and seed trained on the same record with the same
# Adam steps and rate, its initial state per segment either a free parameter (`start="free"`) or the output of
# an encoder of the first `n_init` samples (`start="encoder"`), over segments of `baseline_horizon` samples
# (`fnnlib.training.outputs.train_from_outputs`): "feedback, or just a better initial state?". Of the starts in
# `baseline_starts`, each seed keeps the one whose free run of the *estimation* record is best; its free run of
# the validation record starts as it was trained to (the encoder, or the observer on the first `n_init`
# samples). A baseline trained on short segments of `train_N` samples with free starts simulates the long
# record poorly (above 10 V on several seeds), so the segments are longer and an encoder is tried: the comparison
# of B5 is then with a competent model trained without feedback, not a straw man. The EKF and UKF run on the
# observer-trained model with a disturbance on the lower level, its process noise the better of `kf_qd_grid`
# on the estimation record. Everything below is measured on the validation record.

# %% tags=["hide-input"]
from fnnlib.tanks import evaluation as TE
from fnnbook.rules import tanks as rules

runs, seconds, trained = TE.run_seeds(rec, seeds, TE.TanksSettings.of(settings.as_dict()))
TE.save_trained(out / "tanks_models.pt", trained)  # the pages that judge these models again load them
print("seconds over the seeds: " + ", ".join(f"{k} {v:.0f}" for k, v in seconds.items()))
print("no-feedback baseline per seed: " + "; ".join(
    f"{k}: {r['no_feedback']['start']} (estimation free run " + ", ".join(
        f"{a} {v:.3f} V" for a, v in r["no_feedback"]["estimation_free_run"].items()) + ")" for k, r in runs.items()))

# %% [markdown]
# ## The benchmark's metric, beside the published results
# Our numbers (measured in this run, on this split, free run from the first `n_init` samples) first, the
# neural ODE's as the mean and spread over the seeds; below them, published results on the same benchmark,
# each as its source states it, with the source and the protocol it gives. We copy no number we cannot
# point to; where a source names its metric differently from the benchmark's, the table says so. With
# synthetic records (tests, smoke profile) the published numbers do not apply and are not shown.

# %% tags=["hide-input"]
free = {k: np.array([r["free_run"][k] for r in runs.values()]) for k in ("observer_trained", "no_feedback")}
proto = f"free-run simulation RMSE, samples {n_init}..{len(t) - 1}, initial state from the first {n_init} samples"
ours = [("neural ODE trained through its observer (this run)", free["observer_trained"], proto),
        ("the same, trained without feedback (this run)", free["no_feedback"], proto),
        ("ARX, least squares (this run)", np.array([arx_rmse["validation"]]), proto + "; orders from the estimation record")]
rows = ["| model | validation error [V] | protocol / metric |", "|---|---|---|"]
rows += [f"| {m} | {v.mean():.4f}" + (f" ± {v.std(ddof=1):.4f} ({len(v)} seeds)" if len(v) > 1 else "") + f" | {p} |"
         for m, v, p in ours]
if rec.source == "real":
    rows += ["| **published** | | |"] + [f"| {r.method} ({r.reference}; [source]({r.source})) | {r.value:g} | "
                                       f"{r.protocol}; {r.metric} |" for r in PUBLISHED_RESULTS]
display(Markdown("\n".join(rows)))

# %% tags=["nbval-check-output"]
best = min(r.value for r in PUBLISHED_RESULTS)
print(f"free-run RMSE on the validation record: neural ODE through its observer {free['observer_trained'].mean():.4f} V "
      f"(best seed {free['observer_trained'].min():.4f}), ARX {arx_rmse['validation']:.4f} V"
      + (f"; the lowest published number we can cite: {best:g} V" if rec.source == "real" else " (synthetic records)"))

# %% [markdown]
# ## What feedback adds at prediction time: the N-step table
# The RMSE of $y$ predicted $N$ samples ahead from every sample of the validation record (from sample
# `n_init` on), mean over the seeds. *Open loop*: the model rolled out from its observer's estimate. *Hand*,
# *tuned*: the cascade with those gains after the observer. *EKF*, *UKF*: rollouts from the filters' state.
# The model trained without feedback: rolled out from the same observer's estimate (*with feedback*), or its
# free run (*without*).

# %% tags=["hide-input"]
cols = ["open_loop", "hand", "tuned", "ekf", "ukf", "no_feedback_observer", "no_feedback_free_run"]
nstep = {N: {c: [r["n_step"][N][c] for r in runs.values()] for c in cols} for N in horizons}
head = "| N | open loop | hand gains | tuned gains | EKF | UKF | no-feedback model, with feedback | its free run |"
rows = [head, "|" + "---|" * 8]
rows += [f"| {N} | " + " | ".join(f"{np.mean(nstep[N][c]):.4f}" for c in cols) + " |" for N in horizons]
display(Markdown("\n".join(rows)))

# %% [markdown]
# ## The claims
# Each judged over the seeds by its rule, fixed before this run (`fnnbook.rules.tanks`): **B4** the tuned
# feedback cascade against the open-loop rollout at every $N$; **B5** the free-run RMSE of the model trained
# through its observer against the one trained without feedback; **B6** tuned against hand gains at every $N$.

# %% tags=["hide-input"]
b4 = rules.b4({N: {"feedback": nstep[N]["tuned"], "open_loop": nstep[N]["open_loop"]} for N in horizons})
b5 = rules.b5(observer_trained=free["observer_trained"].tolist(), no_feedback=free["no_feedback"].tolist())
b6 = rules.b6({N: {"tuned": nstep[N]["tuned"], "hand": nstep[N]["hand"]} for N in horizons})
for c in (b4, b5, b6):
    print(f"{c.id}: {c.verdict}; " + "; ".join(f"{k}: {v}" for k, v in c.checks.items()))

# %% [markdown]
# ## The overflow
# The measured level (black), the free run of the first seed, and its open-loop and tuned-feedback
# predictions `series_N` samples ahead (each drawn at the sample it predicts); the overflow episodes, where
# the level sits at the sensor's 10 V limit (runs closer than `overflow_gap` samples taken as one), are shaded. No smooth model has seen a hard limit; the table
# below gives the error during each episode and over the `overflow_after` samples after it (mean over seeds).

# %% tags=["hide-input"]
fig, ax = new_figure(1, 1)
first = runs[seeds[0]]
ax.plot(t, rec.y_val.numpy()[:, 0], "k", lw=0.9, label="measured")
for name, series in first["series"].items():
    ax.plot(t, series, lw=0.8, label={"free_run": "free run", "open_loop": f"open loop, N={series_N}",
                                      "tuned": f"tuned feedback, N={series_N}"}[name])
for a, b in first["overflow"]["episodes"]:
    ax.axvspan(t[a], t[b - 1], color="r", alpha=0.15)
ax.set(xlabel="t [s]", ylabel="lower level y [V]", title=f"validation record, seed {seeds[0]}")
ax.legend(loc="lower right", fontsize=7)
figure = save_figure(fig, out, "tanks_predictions")

# %% tags=["hide-input"]
episodes = first["overflow"]["episodes"]  # each model's error during and after each, the mean over the seeds
display(Markdown(TE.overflow_table([r["overflow"]["errors"] for r in runs.values()], episodes) if episodes
                 else "No overflow episode in this validation record."))

# %% [markdown]
# ## Why a claim does not hold, where it does not
# Computed from the numbers above: for each check that fails, the paired numbers behind it. The page *Why B4,
# B5 and B6 stand where they stand* (`why_tanks`, `make why`) judges these models again by the same rules over
# fixed gains, the scored window, the observer's first estimate and the baseline's start and segment.

# %% tags=["nbval-check-output"]
for c in (b4, b5, b6):
    failed = [k for k, v in c.checks.items() if not v]
    print(f"{c.id} {c.verdict}" + ("" if not failed else ": " + "; ".join(
        f"{k} (mean difference {c.numbers['paired'][k.split(':')[0]]['mean_diff']:+.4f} V, lower in "
        f"{c.numbers['paired'][k.split(':')[0]]['wins']} of {c.numbers['paired'][k.split(':')[0]]['seeds']} seeds)"
        if ":" in k else f"{k} (mean difference {c.numbers['paired']['mean_diff']:+.4f} V)" for k in failed)))

# %%
claims = [b4.replace(figure=figure, title="feedback beats open loop on a real plant"),
          b5.replace(figure=figure, title="training through the observer beats training without feedback"),
          b6.replace(figure=figure, title="tuned gains beat hand gains on a real plant")]
results_file = write_results(out_dir, task="cascaded_tanks", profile=profile, claims=claims, metrics={
    "data": rec.source, "n_init": n_init, "saturated_samples": sat, "arx": {
        "orders": [len(arx.a), len(arx.b), arx.nk], "rmse": arx_rmse,
        "grid": {f"{a},{b},{k}": e for (a, b, k), e in arx_grid.items()}},
    "free_run": {k: v.tolist() for k, v in free.items()}, "n_step": {str(N): v for N, v in nstep.items()},
    "runs": {str(k): {n: v for n, v in r.items() if n != "series"} for k, r in runs.items()}, "seconds": seconds,
    "published": [{"method": r.method, "value": r.value, "source": r.source} for r in PUBLISHED_RESULTS],
    "figures": [records_figure, simulation_figure, figure]})
