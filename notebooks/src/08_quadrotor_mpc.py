# %% [markdown]
# # Model predictive control of a quadrotor under uncertainty (Sec. 5.2.2, App. A.5.3-A.5.4, A.9; Fig. 7, S8, S14)
#
# A quadrotor tracks a Lissajous trajectory with MPC (Eq. (28): horizon N = 10, Ts = 0.02 s,
# Q = diag(100 x3, 50 x6, 1 x3), R = I4, thrust box, |Theta| <= pi/2). At every step the prediction model is
# linearized along the previous plan and the time-varying QP is solved (OSQP, warm-started, the problem set up
# once). Seven prediction models are compared on a test vehicle the models have never seen:
# +0.5 kg mass, +2e-3 kg m^2 x/y inertia, drag diag(0.6, 0.6, 0.15) instead of the training diag(0.7, 0.7, 0.2),
# and a 0.3 N force on every axis. Claims **Q3** (tracking), **Q4** (first-step acceleration prediction) and
# **Q5** (AdapFNN, Eqs. (29)-(30), Theorem 2). The residual networks come from the `quadrotor_learning` task.

# %% tags=["parameters"]
profile = "paper"
out_dir = "outputs/manual/quadrotor_mpc"
upstream_dirs = {"quadrotor_learning": "outputs/manual/quadrotor_learning"}
steps = 300
N = 10
dt = 0.02
Q = [100.0, 100.0, 100.0, 50.0, 50.0, 50.0, 50.0, 50.0, 50.0, 1.0, 1.0, 1.0]
R = [1.0, 1.0, 1.0, 1.0]
u_max = [4.0, 6.0]
theta_max = 1.5707963267948966
L = 3.0
beta = 0.1
Gamma = 8.0
Gamma_adapnn_grid = [0.25, 1.0, 4.0, 8.0]
truth_mass = 1.33
truth_inertia = [0.005, 0.005, 0.004]
truth_drag = [0.6, 0.6, 0.15]
disturbance = [0.3, 0.3, 0.3]
truth_substeps = 1
solver = "OSQP"
qp = "osqp"
linearize_method = "forward"
backend = "numba"
speed_repeats = 5
transient_s = 1.0

# %%
import fnnlib as F

F.check_notebook_settings("quadrotor_mpc", globals())  # the checks `fnn-pipeline check` runs first

# %% [tags: hide-input]
import json
from pathlib import Path

import numpy as np

import fnnlib as F
from fnnlib.mpc.compiled import warm_up
from fnnlib.mpc.experiment import (CARRYING, QP_CLASSES, FlightTest, adapnn_flights, adapnn_model, claim_checks,
                                   flight_row, make_mpc, seed_spread, speed_runs, speed_summary, spread_orderings,
                                   theorem2_check)
from fnnlib.mpc.flight import lissajous_reference, tracking_rmse
from fnnlib.mpc.models import paper_models
from fnnlib.quadrotor_presets import PAPER_LISSAJOUS
from fnnlib.systems.quadrotor import NOMINAL, TEST_TRUTH, Quadrotor

# %%
up = Path(upstream_dirs["quadrotor_learning"])
residual, meta_res = F.load_checkpoint(up / "residual.pt", expected_kind="AeroResidual")
mlp, _ = F.load_checkpoint(up / "mlp.pt", expected_kind="AeroResidual")
residual, mlp = residual.double(), mlp.double()
truth = Quadrotor(TEST_TRUTH.replace(mass=truth_mass, inertia=tuple(truth_inertia), drag=tuple(truth_drag),
                                     force_disturbance=tuple(disturbance)))
F.check_gain(L, 12, dt)  # refuse an unstable feedback gain before any flight
if not u_max or min(u_max) <= 0:
    raise ValueError(f"u_max must list positive thrust bounds, got {u_max}")
if qp not in QP_CLASSES:
    raise ValueError(f"qp must be one of {sorted(QP_CLASSES)}, got {qp!r}")
if backend not in ("torch", "numba"):
    raise ValueError(f"backend must be 'torch' or 'numba', got {backend!r}")

# %%
x_r, u_r = lissajous_reference(steps, N, Ts=dt, params=NOMINAL, curve=PAPER_LISSAJOUS)
test = FlightTest(truth, x_r, u_r, steps=steps, Ts=dt, substeps=truth_substeps, backend=backend,
                  linearize_method=linearize_method)
models_kw = dict(plant=Quadrotor(NOMINAL), L=L, beta=beta, N=N, Gamma=Gamma, Ts=dt)


def make_qp(umax):
    """Eq. (28) with this run's weights, thrust box [0, umax] and |Theta| <= theta_max."""
    return make_mpc(qp, N, Q, R, u_max=umax, theta_max=theta_max, solver=solver)


out = Path(out_dir)
out.mkdir(parents=True, exist_ok=True)
print(f"residual from seed {meta_res.get('seed')}; reference thrust range {float(u_r.min()):.2f}..{float(u_r.max()):.2f} N "
      f"(nominal vehicle); the test vehicle needs {truth_mass * 9.81 / 4:.2f} N per motor just to hover")

# %% [markdown]
# ## Flights
# The paper bounds each thrust by 4 N, the authors' release by 6 N. With the 1.33 kg test vehicle, hovering
# alone takes 3.26 N per motor and the Lissajous peak (13 m/s^2 sideways) about 5.5 N, so under 4 N no
# model can follow the reference; we fly both bounds and report both.
#
# `qp = "osqp"` solves the QP of Eq. (28) with OSQP directly (the problem set up once, each step only new
# numbers in a fixed sparsity pattern); `qp = "cvxpy"` solves the same QP through the cvxpy problem built once
# with Parameters. The tests hold the two to the same inputs (1e-6); the direct form skips cvxpy's per-solve
# work, ~3.5 of the ~4.5 ms a cvxpy solve takes. The truth is integrated with one RK4 step of 0.02 s
# (`truth_substeps`): against 16 sub-steps that differs by 1.3e-8 per step, far below any model error here.
#
# `backend = "numba"` evaluates the models along the plan, their exact Jacobians (forward mode through the RK4
# stages) and the truth's step with the compiled twins in `fnnlib.mpc.compiled`; `backend = "torch"` with the
# torch reference, linearizing by `linearize_method`. The tests hold the two to the same flight (1e-8 m). The
# kernels are compiled, or loaded from numba's cache, before the first flight, outside the timed loops.

# %%
compile_s = warm_up(residual, mlp) if backend == "numba" else 0.0
print(f"compiled kernels ready in {compile_s:.1f} s" if backend == "numba" else "torch backend")
flights = {}
for umax in u_max:
    mpc = make_qp(umax)
    flights[umax] = {m.name: test.fly(m, mpc, progress=True) for m in paper_models(residual, mlp, **models_kw)}
names = list(flights[u_max[0]])

# %% [markdown]
# The paper tunes AdapNN "for optimal performance": we fly it for every gain in `Gamma_adapnn_grid` and keep the
# best per thrust bound (the whole sweep is in the results).

# %%
adapnn_sweep = {}
for umax in u_max:
    runs = adapnn_flights(residual, Gamma_adapnn_grid, make_qp(umax), test)
    adapnn_sweep[str(umax)] = {g: tracking_rmse(r.x, r.x_ref)["mean_axis"] for g, r in runs.items()}
    best_g = min(runs, key=lambda g: adapnn_sweep[str(umax)][g])
    flights[umax]["AdapNN"] = runs[best_g]
    print(f"thrust <= {umax} N: AdapNN RMSE by Gamma {adapnn_sweep[str(umax)]}; keeping Gamma = {best_g}")
best_gamma = {str(umax): min(adapnn_sweep[str(umax)], key=adapnn_sweep[str(umax)].get) for umax in u_max}

# %%
table = {str(umax): {n: flight_row(r) for n, r in fl.items()} for umax, fl in flights.items()}
for umax, rows in table.items():
    print(f"thrust <= {umax} N   RMSE mean-axis   norm  acc-pred  fallbacks  ms/step (median, p95)  flight s  x real time")
    for n, v in rows.items():
        print(f"  {n:8s} {v['mean_axis']:12.3f} {v['norm']:7.3f} {v['acc_pred_rmse']:8.3f} {v['fallbacks']:9d}"
              f"   {v['step_ms_median']:6.1f} {v['step_ms_p95']:6.1f}   {v['flight_s']:10.2f} {v['real_time_factor']:8.1f}")

# %% [markdown]
# ## Speed
# Targets set for this reproduction (not a paper claim): the median control step (linearize + solve) at most
# 4 ms and the 6 s flight, simulation included, at least 5x faster than real time, on the 2-core CI machine.
# Wall time on this machine varies from run to run (a pure-Python loop timed six times in a row spread over
# 0.60-1.06 s), so one flight per model is a noisy sample. The rule: every model is flown `speed_repeats` times
# at the largest thrust bound, kernels already compiled; per model, the step time is the median over all steps
# of all its repeats and the real-time factor the median over its repeats; the targets are met when the worst
# model meets both. The single flights above are in the table as they came. `benchmarks/bench_flight.py`
# repeats the measurement without the notebook around it, for both backends.

# %%
timed = paper_models(residual, mlp, **models_kw)
timed[names.index("AdapNN")] = adapnn_model(residual, best_gamma[str(max(u_max))], Ts=dt)  # the gain the sweep keeps
timing = speed_runs(timed, make_qp(max(u_max)), test, speed_repeats)
speed = speed_summary(timing, repeats=speed_repeats, thrust_bound=max(u_max), qp=qp, backend=backend,
                      linearize_method=linearize_method, compile_s=compile_s)
for n, v in timing.items():
    print(f"  {n:8s} linearize + solve {v['step_ms_median']:.2f} ms (p95 {v['step_ms_p95']:.2f}); "
          f"x real time, median of {int(speed_repeats)}: {v['real_time_factor_median']:.1f} "
          f"(each {', '.join(f'{f:.1f}' for f in v['real_time_factor_each'])})")
print(f"median linearize + solve per step: {speed['step_ms_median_best_model']:.2f} to "
      f"{speed['step_ms_median_worst_model']:.2f} ms over the models (target <= 4)")
print(f"whole flight: {speed['real_time_factor_worst_model']:.1f}x to {speed['real_time_factor_best_model']:.1f}x "
      f"faster than real time (target >= 5x); targets met: {speed['met']}")

# %%
t_grid = np.arange(steps + 1) * dt
for umax, fl in flights.items():
    fig, axes = F.new_figure(1, 2)
    axes = axes[0]
    axes[0].plot(x_r[:steps + 1, 0], x_r[:steps + 1, 1], "k", lw=2, label="reference")
    for n, r in fl.items():
        axes[0].plot(r.x[:, 0], r.x[:, 1], lw=1, label=f"{n} ({table[str(umax)][n]['mean_axis']:.3f} m)")
        axes[1].plot(t_grid, np.linalg.norm(r.x[:, :3] - r.x_ref[:, :3], axis=1), lw=1, label=n)
    axes[0].set(xlabel="x [m]", ylabel="y [m]", title=f"Lissajous tracking, thrust <= {umax} N (Fig. 7)")
    axes[1].set(xlabel="t [s]", ylabel="position error [m]", yscale="log")
    axes[0].legend(fontsize=6)
    F.save_figure(fig, out, f"tracking_u{umax:g}")

# %%
for umax, fl in flights.items():
    fig, axes = F.new_figure(1, 3, sharey=True)
    axes = axes[0]
    for c, ax in enumerate(axes):
        ax.plot(t_grid[:-1], fl["Nomi"].xdot_true[:, 3 + c], "k", lw=1.5, label="truth")
        for n in ("Nomi", "Neural", "FB", "FNN"):
            ax.plot(t_grid[:-1], fl[n].xdot_pred[:, 3 + c], lw=0.9, label=n)
        ax.set(xlabel="t [s]", title=f"first-step prediction of dv{'xyz'[c]}/dt")
    axes[0].set_ylabel("acceleration [m/s^2]")
    axes[0].legend(fontsize=6)
    F.save_figure(fig, out, f"acc_prediction_u{umax:g}")

# %% [markdown]
# ## Theorem 2 on the AdapFNN flight
# Layer 0 of the cascade obeys $\tilde x_{t+1} = (I - T_s L)\tilde x_t + T_s\Delta_t$ (Eq. (25)) with $\Delta_t$ the
# model's one-step residual, whatever the adaptation does to the network; Theorem 2 bounds the error by
# $\gamma/\lambda_m(L)$ with $\gamma$ the bound on the residual. We take $\gamma$ as the largest $\lVert\Delta_t\rVert$ after
# the first `transient_s` seconds and check how often $\lVert\tilde x_t\rVert$ stays in the ball there.
#
# **Rules**, fixed before the run (each evaluated at every thrust bound; a claim's verdict follows from all of
# its checks):
# * Q3: FNN has the lowest mean per-axis RMSE of the six models (Nomi, Neural, MLP, FB, AdapNN, FNN);
#   Neural < Nomi; MLP > Neural.
# * Q4: the lowest first-step acceleration-prediction RMSE of the six belongs to a feedback model (FB or FNN),
#   and FNN's is below Neural's.
# * Q5: AdapFNN is comparable to FNN (RMSE within 25 %) and slightly larger (>= FNN); Theorem 2's ball
#   holds for >= 95 % of the AdapFNN flight after the transient.

# %%
thm2 = {str(umax): theorem2_check(fl["AdapFNN"], L, int(round(transient_s / dt))) for umax, fl in flights.items()}
for umax, fl in flights.items():
    fig, ax = F.new_figure()
    ax.semilogy(t_grid[:-1], np.linalg.norm(fl["AdapFNN"].x_tilde, axis=1), label="AdapFNN ||x - x_hat||")
    ax.semilogy(t_grid[:-1], np.linalg.norm(fl["FNN"].x_tilde, axis=1), label="FNN ||x - x_hat||", alpha=0.7)
    ax.axhline(thm2[str(umax)]["ball_x"], color="k", ls="--", label="Theorem 2 ball gamma / lambda_m(L)")
    ax.axvline(transient_s, color="gray", lw=0.8)
    ax.set(xlabel="t [s]", title=f"Observation error, thrust <= {umax} N (Fig. S14)")
    ax.legend(fontsize=7)
    F.save_figure(fig, out, f"adapfnn_u{umax:g}")
for umax, v in thm2.items():
    print(f"thrust <= {umax} N: gamma = {v['gamma']:.2f}, ball gamma/lambda_m(L) = {v['ball_x']:.2f}, "
          f"max ||x_tilde|| after {transient_s} s = {v['max_error']:.2f}, inside {100 * v['inside_fraction']:.0f} %")

# %% [markdown]
# ## Spread over the trained networks
# The flights above use the residual network with the lowest validation loss. The four models that carry it
# (Neural, AdapNN, FNN, AdapFNN) are flown again with every initialisation trained by `quadrotor_learning`
# (AdapNN at the gain kept above); Nomi and FB do not use it and MLP is one network, so their flights are the
# ones above. This is spread over training seeds only: the flight itself is deterministic (the member that
# is also `residual.pt` reproduces the flights above exactly). The verdicts below use the flights above, as
# the rules say; the fractions here show how often each ordering holds over seeds.

# %%
member_files = json.loads((up / "results.json").read_text()).get("metrics", {}).get("member_checkpoints")
if not member_files:
    raise FileNotFoundError(f"{up / 'results.json'} lists no member_checkpoints: rerun quadrotor_learning")
members = [(str(meta["seed"]), net.double()) for net, meta in
           (F.load_checkpoint(up / fname, expected_kind="AeroResidual") for fname in member_files)]
spread = seed_spread(members, mlp, u_max=u_max, make_qp=make_qp, test=test, model_settings=models_kw,
                     adapnn_gamma=best_gamma)
kept = str(meta_res.get("seed"))  # the network of the flights above flies the same flights
for u, per_model in spread.items():
    for name, by_seed in per_model.items():
        assert kept not in by_seed or abs(by_seed[kept] - table[u][name]["mean_axis"]) < 1e-9
orderings = spread_orderings(spread, table)

# %%
for u, per_model in spread.items():
    print(f"thrust <= {u} N, {len(per_model['FNN'])} seeds:")
    for n, by_seed in per_model.items():
        v = np.array(list(by_seed.values()))
        print(f"  {n:8s} mean {v.mean():.3f}  std {v.std(ddof=1) if v.size > 1 else 0.0:.3f}  min {v.min():.3f}  "
              f"max {v.max():.3f}")
    print("  fraction of seeds where " + "; ".join(f"{k}: {v:.1f}" for k, v in orderings[u].items()))

# %%
fig, axes = F.new_figure(1, len(u_max))
for ax, u in zip(np.ravel(axes), spread):  # one panel per thrust bound (a lone Axes when there is one)
    for i, n in enumerate(CARRYING):
        ax.plot(np.full(len(spread[u][n]), i), list(spread[u][n].values()), "o", alpha=0.7)
    for n, style in (("Nomi", ":"), ("MLP", "-."), ("FB", "--")):
        ax.axhline(table[u][n]["mean_axis"], color="k", ls=style, lw=0.8, label=n)
    ax.set(xticks=range(len(CARRYING)), xticklabels=CARRYING, ylabel="mean per-axis RMSE [m]", yscale="log",
           title=f"thrust <= {u} N: one dot per trained network")
    ax.legend(fontsize=7)
_ = F.save_figure(fig, out, "seed_spread")

# %% [markdown]
# ## Verdicts

# %% [tags: nbval-check-output]
q3, q4, q5 = claim_checks(table, thm2)
rmse_numbers = {u: {n: round(v["mean_axis"], 4) for n, v in rows.items()} for u, rows in table.items()}
acc_numbers = {u: {n: round(v["acc_pred_rmse"], 4) for n, v in rows.items()} for u, rows in table.items()}


def over_seeds(*keys):
    """The fractions of ``orderings`` for ``keys``, per thrust bound."""
    return {u: {k: o[k] for k in keys} for u, o in orderings.items()}


# %%
claims = [
    F.claim_result("Q3", checks=q3, figure=f"figures/tracking_u{u_max[0]:g}.png",
                   numbers={"mean_axis_rmse_m": rmse_numbers,
                            "over_seeds_fraction": over_seeds("FNN best of the six", "FNN < Neural", "Neural < Nomi")},
                   rule="FNN lowest mean per-axis RMSE of the six; Neural < Nomi; MLP > Neural (every thrust bound)"),
    F.claim_result("Q4", checks=q4, figure=f"figures/acc_prediction_u{u_max[0]:g}.png",
                   numbers={"acc_pred_rmse": acc_numbers},
                   rule="lowest first-step acceleration RMSE of the six is FB or FNN; FNN < Neural"),
    F.claim_result("Q5", checks=q5, figure=f"figures/adapfnn_u{u_max[0]:g}.png",
                   numbers={"mean_axis_rmse_m": {u: {n: rmse_numbers[u][n] for n in ("FNN", "AdapFNN")} for u in rmse_numbers},
                            "theorem2": thm2,
                            "over_seeds_fraction": over_seeds("AdapFNN >= FNN", "AdapFNN within 25 % of FNN")},
                   rule="AdapFNN within 25 % of FNN and >= FNN; Theorem 2 ball holds >= 95 % after the transient"),
]

# %%
F.write_results(out, task="quadrotor_mpc", profile=profile, claims=claims,
                metrics={"table": table, "adapnn_gamma_sweep": adapnn_sweep, "speed": speed,
                         "seed_spread": {"mean_axis_rmse_m": spread, "orderings_fraction": orderings}})
for c in claims:
    print(c["id"], c["verdict"], c["checks"])
