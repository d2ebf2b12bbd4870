# %% [markdown]
# # Model predictive control of a quadrotor under uncertainty (Sec. 5.2.2, App. A.5.3-A.5.4, A.9; Fig. 7, S8, S14)
#
# A quadrotor tracks a Lissajous trajectory with MPC (Eq. (28): horizon N = 10, Ts = 0.02 s,
# Q = diag(100 x3, 50 x6, 1 x3), thrust box, |Theta| <= pi/2). At every step the prediction model is
# linearized along the previous plan and the time-varying QP is solved (OSQP, warm-started, the problem
# written once in cvxpy). Seven prediction models are compared on a test vehicle the models have never seen:
# +0.5 kg mass, +2e-3 kg m^2 x/y inertia, drag diag(0.6, 0.6, 0.15) instead of the training diag(0.7, 0.7, 0.2),
# and a 0.3 N force on every axis. Claims **Q3** (tracking), **Q4** (first-step acceleration prediction) and
# **Q5** (AdapFNN, Eqs. (29)-(30), Theorem 2). The residual networks and the MLPs come from the
# `quadrotor_learning` task, one of each per seed.
#
# Eq. (28) is flown with two weightings: **as written** in the paper (R = I on every input
# u_0..u_{N-1}, Q_N = Q) and **as flown** by the authors' release (Q on x_1..x_{N-1}, no weight on x_N, only the
# last input penalised, so the inputs are in effect free). Each gets its own verdict lines.

# %% tags=["parameters"]
profile = "paper"
out_dir = "outputs/manual/quadrotor_mpc"
upstream_dirs = {"quadrotor_learning": "outputs/manual/quadrotor_learning"}
# the settings and their paper values, from fnnbook.tasks.quadrotor_mpc (written by `make notebooks`)
steps = 300
N = 10
Ts = 0.02
Q = [100.0, 100.0, 100.0, 50.0, 50.0, 50.0, 50.0, 50.0, 50.0, 1.0, 1.0, 1.0]
R = [1.0, 1.0, 1.0, 1.0]
costs = ["as_written", "as_flown"]
u_max = [4.0, 6.0]
u_max_judged = 6.0
theta_max = 1.5707963267948966
L = 3.0
beta = 0.1
Gamma = 8.0
Gamma_adapnn_grid = [0.04, 0.16, 0.64, 2.56]
Gamma_rtol = 0.05
validation_flights = 2
validation_steps = 300
validation_waypoints = 4
validation_seed = 1000
truth_mass = 1.33
truth_inertia = [0.005, 0.005, 0.004]
truth_drag = [0.6, 0.6, 0.15]
disturbance = [0.3, 0.3, 0.3]
disturbance_draws = 5
disturbance_spread = 0.5
disturbance_seed = 11
truth_substeps = 1
solver = "OSQP"
qp = "osqp"
linearize_method = "forward"
backend = "numba"
transient_s = 1.0
validation_vehicles = 4
validation_vehicle_seed = 1001

# %%

from fnnbook.tasks.quadrotor_mpc import QuadrotorMPCSettings
settings = QuadrotorMPCSettings.from_namespace(globals())  # checked as `fnn-pipeline check` checks them

# %% tags=["hide-input"]
from functools import partial
from pathlib import Path

import numpy as np

from fnnbook.results import headline_number, verdict_from_checks, write_results
from fnnlib.plotting import new_figure, save_figure
from fnnlib.training import load_checkpoint, load_seed_checkpoints
import fnnlib.quadrotor.mpc as M
from fnnbook.params import upstream_parameters
from fnnbook.rules import quadrotor as rules
from fnnlib.quadrotor.mpc import randomized_vehicles, validation_references
from fnnlib.quadrotor.presets import PAPER_FLIGHT_DATA, PAPER_LISSAJOUS, PAPER_THRUST_MAX, VALIDATION_RANDOMIZATION
from fnnlib.quadrotor.system import NOMINAL, TRAINING_TRUTH, Quadrotor

# %%
up = Path(upstream_dirs["quadrotor_learning"])
residual, meta_res = load_checkpoint(up / "residual.pt", expected_kind="AeroResidual")
mlp, meta_mlp = load_checkpoint(up / "mlp.pt", expected_kind="AeroResidual")
residual, mlp = residual.double(), mlp.double()  # the kept ones, picked on quadrotor_learning's selection flights
members, mlps = ([(seed, net.double()) for seed, net, _ in  # (int seed, network), checked against the run record
                  load_seed_checkpoints(up, stem, expected_kind="AeroResidual", run=upstream_parameters(up))]
                 for stem in ("residual", "mlp"))
if disturbance_draws != len(members) or [s for s, _ in mlps] != [s for s, _ in members]:
    raise ValueError(f"one drawn disturbance per trained network: disturbance_draws = {disturbance_draws} must equal the "
                     f"{len(members)} networks of quadrotor_learning (seeds {[s for s, _ in members]}; MLP seeds "
                     f"{[s for s, _ in mlps]})")

# %%
setup = M.flight_tests(M.FlightSettings.of(settings.as_dict()))  # the test vehicle: the paper's force, then one per unit
test_params, forces, x_r, u_r, tests = setup.vehicle, setup.forces, setup.x_r, setup.u_r, setup.tests
numerics = M.Backend(backend, linearize_method)
models_kw = dict(plant=Quadrotor(NOMINAL), L=L, beta=beta, N=N, Gamma=Gamma, Ts=Ts)
# Eq. (28) with this run's weights; a cost variant and thrust box [0, u_max] make one MPC, |Theta| <= theta_max
make_qp = partial(M.make_mpc, qp, N, Q, R, theta_max=theta_max, solver=solver)


# %%
out = Path(out_dir)
out.mkdir(parents=True, exist_ok=True)
hover = truth_mass * NOMINAL.g / 4
need = M.thrust_needed(test_params, PAPER_LISSAJOUS, steps=steps, Ts=Ts)  # per motor, from the test mass and reference
print(f"{len(members)} trained networks and MLPs (kept: seeds {meta_res.get('seed')}, {meta_mlp.get('seed')}); "
      f"the paper's force and the drawn disturbances [N]: " + "; ".join(", ".join(f"{c:.2f}" for c in f) for f in forces))
print(f"reference thrust {float(u_r.min()):.2f}..{float(u_r.max()):.2f} N per motor (nominal vehicle); "
      f"the test vehicle needs {hover:.2f} N per motor to hover and {need['peak']:.2f} N at the reference's peak "
      f"acceleration (t = {need['t_peak']:.2f} s)")

# %% [markdown]
# ## Which thrust bound is judged
# The paper bounds each thrust by 4 N, the authors' release by 6 N. The cell above prints what the test
# vehicle needs per motor just to hover and at the Lissajous' peak acceleration, $m \max_t\lVert g e_3 - a_r(t)
# \rVert / 4$ from the test vehicle's mass and the reference (`fnnlib.quadrotor.mpc.thrust_needed`; drag and the force
# come on top): more than 4 N, so at 4 N no model can follow the reference (the 4 N table below shows every
# model far off it). A claim about which model tracks best needs flights that can track, so Q3-Q5 are judged
# at `u_max_judged` (6 N); the 4 N flights are reported as context only, count toward no verdict, and each
# claim's row states their outcome and this reason (`at_paper_setting`).
#
# `backend = "numba"` evaluates the models along the plan, their exact Jacobians and the truth's step with the
# compiled twins in `fnnlib.quadrotor.mpc.compiled`; the tests hold them to the torch reference (1e-8 m). `qp = "osqp"`
# updates OSQP from cvxpy's canonicalisation of the one cvxpy problem; `qp = "cvxpy"` solves it through cvxpy.
# A guard before every solve refuses data at or above OSQP's infinity or not finite and plans outside the
# boxes; such a step flies the previous plan for at most N steps, then the reference input, and is counted
# with its reason. A flight whose fallback share exceeds `DIVERGED_FALLBACK_SHARE` is marked DIVERGED.

# %% [markdown]
# ## AdapNN's gain, chosen away from the test flight
# Convention (see `fnnlib.quadrotor.mpc.models.AdaptiveNNModel`): each step adds $\Gamma(v_{t+1} - \hat v_{t+1})\phi^\top$; the
# release steps $T_s\Gamma_{rel}\,e\,\phi^\top$, so $\Gamma = T_s\Gamma_{rel}$ and the release's 8 is 0.16 here. The
# grid `Gamma_adapnn_grid` brackets 0.16.
#
# **Protocol** (`fnnlib.quadrotor.mpc.tuning`), fixed before any flight and blind to the test vehicle:
# - *References*: `validation_flights` random minimum-snap flights drawn like the training data (App. A.5.4:
#   waypoints in the training box, speeds up to 10 m/s), with their own seed `validation_seed`.
# - *Vehicles*: `validation_vehicles` vehicles drawn by domain randomisation around the **training** vehicle, in
#   the spirit of the paper's Alg. 1 / Eq. (12) (seed `validation_vehicle_seed`): mass, each inertia and each drag
#   coefficient uniform in training value x (1 +- 0.5), and a constant force with each axis uniform in +- 0.1 x the
#   training vehicle's weight (`fnnlib.quadrotor.presets.VALIDATION_RANDOMIZATION`, whose docstring gives the
#   reasons: the relative spread of the paper's own randomised spiral cases, made symmetric). On the training
#   vehicle itself the adaptation has nothing to correct and the validation RMSE is flat over the grid, so
#   $\Gamma$ is not identifiable there.
# - *Rule*: every vehicle flies every reference at every gain, `validation_steps` steps, under each cost variant at
#   the judged bound. A gain scores the **median** of its flights' mean per-axis RMSE, a diverged flight counting
#   as worst; the lowest score wins, and gains within `Gamma_rtol` (5 %) of it are ties, broken toward the
#   **smaller gain** (a larger adaptive gain is the riskier one).
#
# Nothing of the test flight (vehicle, force, Lissajous curve) enters these flights; `tests/quadrotor/mpc/test_tuning.py`
# checks that the cell below reads none of it.

# %%
compile_s = M.warm_up(residual, mlp) if backend == "numba" else 0.0
val_vehicles = randomized_vehicles(TRAINING_TRUTH, validation_vehicles, seed=validation_vehicle_seed,
                                   **VALIDATION_RANDOMIZATION)
val_refs = validation_references(validation_flights, validation_steps, N, seed=validation_seed, Ts=Ts,
                                 n_waypoints=validation_waypoints, box=PAPER_FLIGHT_DATA["box"],
                                 max_speed=PAPER_FLIGHT_DATA["max_speed"], params=NOMINAL)
gamma_sel = {cost: M.adapnn_gain_on_validation(residual, Gamma_adapnn_grid, val_refs, val_vehicles,
                                               make_qp(cost=cost, u_max=u_max_judged), steps=validation_steps, Ts=Ts,
                                               substeps=truth_substeps, backend=numerics, rtol=Gamma_rtol)
             for cost in costs}


# %%
print(f"validation flights: {len(val_vehicles)} vehicle(s) x {len(val_refs)} reference(s); masses "
      + ", ".join(f"{v.mass:.2f}" for v in val_vehicles) + " kg; |force| "
      + ", ".join(f"{np.linalg.norm(v.force_disturbance):.2f}" for v in val_vehicles) + " N")
for cost, sel in gamma_sel.items():
    print(f"{cost}: median validation RMSE by Gamma " + ", ".join(
        f"{g}: {row['rmse']:.3f} [{min(row['rmse_per_flight']):.3f}..{max(row['rmse_per_flight']):.3f}]"
        f"{' diverged ' + str(row['diverged_flights']) + 'x' if row['diverged'] else ''}"
        f"{' ' + str(row.get('fallback_reasons')) if row.get('fallback_reasons') else ''}"
        for g, row in sel.table.items()) + f" -> Gamma = {sel.value}")

# %% [markdown]
# For context only, the oracle: every gain flown on the test flight itself (kept network, the paper's force), and
# where the test vehicle lies in the randomisation's ranges (in units of each half-width: inside when within
# +-1). Neither feeds the choice above.

# %%
oracle = {cost: M.adapnn_flights(residual, Gamma_adapnn_grid, make_qp(cost=cost, u_max=u_max_judged), tests[0])
          for cost in costs}
for cost, runs in oracle.items():
    best = min(runs, key=lambda g: M.tracking_rmse(runs[g].x, runs[g].x_ref)["mean_axis"])
    print(f"{cost}: test-flight RMSE by Gamma " + ", ".join(
        f"{g}: {M.tracking_rmse(r.x, r.x_ref)['mean_axis']:.3f} {M.fallback_note(r)}" for g, r in runs.items())
          + f" -> oracle Gamma = {best} (validation chose {gamma_sel[cost].value})")
test_in_range = M.randomization_coordinates(test_params, TRAINING_TRUTH, **VALIDATION_RANDOMIZATION)
print("test vehicle in the validation ranges, in half-widths (outside beyond +-1): " + "; ".join(
    f"{k} " + ", ".join(f"{c:+.2f}" for c in v) + (" (outside)" if max(map(abs, v)) > 1 else "")
    for k, v in test_in_range.items()))

# %% [markdown]
# **Other baseline settings.** No other baseline setting is chosen by a flight. Nomi has none; Neural and MLP are
# trained on the training flights only (`quadrotor_learning`; the kept ones picked there on selection flights);
# FB uses the paper's $L = 3I$ and $\beta = 0.1$
# (App. A.5.3), the same as FNN; the MPC has no Kalman filter. The thrust bound judged (6 N, the release's) and the
# disturbance realisations are conditions of the test, the same for every model, not settings of a baseline.

# %% [markdown]
# ## Flights at the judged bound: independent units
# **Unit design**, fixed before any flight. Unit $k$ ($k = 1..S$, $S$ = the number of trained networks) is the
# $k$-th residual network, the $k$-th MLP (the same seed) and the $k$-th disturbance, drawn independently around
# the paper's force. Every model flies every unit once: Nomi and FB (no network) fly unit $k$'s disturbance, the
# others with their networks of unit $k$. The units share nothing random, so they are independent draws of
# everything that varies (the training seed and the disturbance), and every comparison of Q3-Q5, with or
# without a network, is paired over the same $S$ units: $n = S$, with no flight copied. (The former crossed grid,
# networks x disturbances with Nomi's flight copied for every network, had 15 entries for 3 independent
# disturbances; the cells of a crossed grid also share their network, so they are not independent either.)
#
# The table and figures below are the **paper's flight**: the kept network and MLP under the paper's force,
# flown once per model; it shows the paper's condition and counts toward no verdict.

# %%
grid = {cost: M.paired_units(members, mlps, tests=setup.unit_tests, mpc=make_qp(cost=cost, u_max=u_max_judged),
                             model_settings=models_kw, adapnn_gamma=gamma_sel[cost].value) for cost in costs}
main = {cost: {m.name: M.fly(m, make_qp(cost=cost, u_max=u_max_judged), setup.paper_test) for m in  # the paper's flight
               M.paper_models(residual, mlp, **models_kw, adapnn_gamma=gamma_sel[cost].value)} for cost in costs}
context = {M.TableKey(cost, umax): {m.name: M.fly(m, make_qp(cost=cost, u_max=umax), setup.paper_test) for m in
                                    M.paper_models(residual, mlp, **models_kw, adapnn_gamma=gamma_sel[cost].value)}
           for umax in u_max if umax != u_max_judged for cost in costs}

# %%
tables = {M.TableKey(cost, u_max_judged): fl for cost, fl in main.items()} | context
table = {k: {n: M.flight_row(r) for n, r in fl.items()} for k, fl in tables.items()}
judged = {cost: table[M.TableKey(cost, u_max_judged)] for cost in costs}  # the rows at the judged bound
for k, fl in tables.items():
    print(f"{k.label(u_max_judged):28s} RMSE mean-axis  z     acc-pred  fallbacks")
    for n, r in fl.items():
        v = table[k][n]
        print(f"  {n:8s} {v.mean_axis:20.3f} {v.z:6.3f} {v.acc_pred_rmse:8.3f} {v.fallbacks:6d} {M.fallback_note(r)}")

# %%
t_grid = np.arange(steps + 1) * Ts
for cost, fl in main.items():
    fig, axes = new_figure(1, 2)
    axes = axes[0]
    axes[0].plot(x_r[:steps + 1, 0], x_r[:steps + 1, 1], "k", lw=2, label="reference")
    for n, r in fl.items():
        mark = " DIVERGED" if r.diverged else ""
        axes[0].plot(r.x[:, 0], r.x[:, 1], lw=1, label=f"{n} ({judged[cost][n].mean_axis:.3f} m){mark}")
        axes[1].plot(t_grid, np.linalg.norm(r.x[:, :3] - r.x_ref[:, :3], axis=1), lw=1, label=n)
    axes[0].set(xlabel="x [m]", ylabel="y [m]", title=f"Lissajous tracking, {cost}, thrust <= {u_max_judged:g} N (Fig. 7)")
    axes[1].set(xlabel="t [s]", ylabel="position error [m]", yscale="log")
    axes[0].legend(fontsize=6)
    save_figure(fig, out, f"tracking_{cost}")

# %% [markdown]
# ## Why the two costs differ: Nomi's altitude
# With R = I the nominal model (0.83 kg) pays for every newton it plans above its reference input; flying the
# heavier vehicle, it trades altitude for thrust. With the release's weighting the inputs are in effect free.

# %%
fig, axes = new_figure(1, 2)
axes = axes[0]
for cost, fl in main.items():
    axes[0].plot(t_grid, fl["Nomi"].x[:, 2], lw=1, label=f"Nomi, {cost}")
    axes[1].plot(t_grid[:-1], fl["Nomi"].u.sum(axis=1), lw=1, label=f"Nomi, {cost}")
axes[0].plot(t_grid, x_r[:steps + 1, 2], "k--", lw=1, label="reference")
axes[1].plot(t_grid[:-1], u_r[:steps].sum(axis=1), "k--", lw=1, label="reference input (nominal)")
axes[0].set(xlabel="t [s]", ylabel="z [m] (z down)", title="Nomi's altitude under both costs")
axes[1].set(xlabel="t [s]", ylabel="total thrust [N]")
axes[0].legend(fontsize=7)
save_figure(fig, out, "nomi_z_costs")

# %%
z = {cost: judged[cost]["Nomi"].z for cost in costs}
share = {cost: z[cost] / judged[cost]["Nomi"].mean_axis / 3 for cost in costs}
print(" ".join(f"{cost}: Nomi's z RMSE {z[cost]:.3f} m, {100 * share[cost]:.0f} % of its summed per-axis RMSE, "
               f"mean total thrust {main[cost]['Nomi'].u.sum(axis=1).mean():.2f} N." for cost in costs)
      + f" The test vehicle needs {4 * hover:.2f} N to hover.")

# %%
for cost, fl in main.items():
    fig, axes = new_figure(1, 3, sharey=True)
    axes = axes[0]
    for c, ax in enumerate(axes):
        ax.plot(t_grid[:-1], fl["Nomi"].xdot_true[:, 3 + c], "k", lw=1.5, label="truth")
        for n in ("Nomi", "Neural", "FB", "AdapNN", "FNN"):
            ax.plot(t_grid[:-1], fl[n].xdot_pred[:, 3 + c], lw=0.9, label=n)
        ax.set(xlabel="t [s]", title=f"first-step prediction of dv{'xyz'[c]}/dt, {cost}")
    axes[0].set_ylabel("acceleration [m/s^2]")
    axes[0].legend(fontsize=6)
    save_figure(fig, out, f"acc_prediction_{cost}")

# %% [markdown]
# ## Speed
# Targets set for this reproduction (not a paper claim): the median control step (linearize + solve) at most
# 4 ms and the 6 s flight, simulation included, at least 5x faster than real time, on the 2-core CI machine.
# Per model, the step time is the median over all steps of all its unit flights at the judged bound (both costs,
# every unit; kernels compiled before) and the real-time factor the median over those
# flights; the targets are met when the worst model meets both.

# %%
timing = M.pooled_speed({n: [r for cost in costs for r in grid[cost][n]] for n in grid[costs[0]]})
speed = M.speed_summary(timing, repeats=min(v["flights"] for v in timing.values()), thrust_bound=u_max_judged, qp=qp,
                        backend=numerics, compile_s=compile_s)
for n, v in timing.items():
    print(f"  {n:8s} linearize + solve {v['step_ms_median']:.2f} ms (p95 {v['step_ms_p95']:.2f}); x real time, "
          f"median of {v['flights']} flights: {v['real_time_factor_median']:.1f}")
print(f"median linearize + solve per step: {speed['step_ms_median_best_model']:.2f} to "
      f"{speed['step_ms_median_worst_model']:.2f} ms over the models (target <= 4)")
print(f"whole flight: {speed['real_time_factor_worst_model']:.1f}x to {speed['real_time_factor_best_model']:.1f}x "
      f"faster than real time (target >= 5x); targets met: {speed['met']}")

# %% [markdown]
# ## Theorem 2 on the AdapFNN flights
# Layer 0 of the cascade obeys $\tilde x_{t+1} = (I - T_s L)\tilde x_t + T_s\Delta_t$ (Eq. (25)) with $\Delta_t$ the
# model's one-step residual, whatever the adaptation does to the network; Theorem 2 bounds the error by
# $\gamma/\lambda_m(L)$ with $\gamma$ the bound on the residual. We take $\gamma$ as the largest $\lVert\Delta_t\rVert$ after
# the first `transient_s` seconds of the same flight: the ball is then a guarantee, checked on every flight,
# not a check that counts.

# %%
transient = int(round(transient_s / Ts))
thm2 = {cost: [M.theorem2_check(r, L, transient) for r in g["AdapFNN"]] for cost, g in grid.items()}
thm2_paper = {cost: M.theorem2_check(fl["AdapFNN"], L, transient) for cost, fl in main.items()}  # the figure's flight
fig, ax = new_figure()
for cost, fl in main.items():
    ax.semilogy(t_grid[:-1], np.linalg.norm(fl["AdapFNN"].x_tilde, axis=1), lw=1, label=f"AdapFNN, {cost}")
    ax.axhline(thm2_paper[cost]["ball_x"], ls="--", lw=0.8, label=f"ball gamma / lambda_m(L), {cost}")
ax.axvline(transient_s, color="gray", lw=0.8)
ax.set(xlabel="t [s]", ylabel="||x - x_hat||", title=f"Observation error, thrust <= {u_max_judged:g} N (Fig. S14)")
ax.legend(fontsize=7)
save_figure(fig, out, "adapfnn")

# %% [markdown]
# ## Spread over the independent units
# One dot per unit (trained network, its MLP, one drawn disturbance); the flights themselves are deterministic.

# %%
rmse = {cost: {n: [M.tracking_rmse(r.x, r.x_ref)["mean_axis"] for r in runs] for n, runs in g.items()}
        for cost, g in grid.items()}
acc = {cost: {n: [M.acc_pred_rmse(r) for r in runs] for n, runs in g.items()} for cost, g in grid.items()}
fig, axes = new_figure(1, len(costs))
for ax, cost in zip(np.ravel(axes), costs):
    for i, n in enumerate(rmse[cost]):
        ax.plot(np.full(len(rmse[cost][n]), i), rmse[cost][n], "o", alpha=0.6)
    ax.set(xticks=range(len(rmse[cost])), xticklabels=list(rmse[cost]), ylabel="mean per-axis RMSE [m]",
           yscale="log", title=f"{cost}, {u_max_judged:g} N: {len(grid[cost].units)} independent units")
_ = save_figure(fig, out, "seed_spread")

# %% [markdown]
# ## Verdicts
# Rules (`fnnbook.rules.quadrotor`), per cost variant at the judged bound, paired over the S independent units
# (a win: in at least S - 1 of S units and the 90 % interval of the mean paired difference below 0):
# Q3: FNN beats each of the other five; Neural beats Nomi; Neural beats MLP. Q4: FNN's first-step acceleration
# prediction beats each of the other five (Fig. S8). Q5: AdapFNN within 25 % of FNN in at least S - 1 units and
# its mean RMSE >= FNN's; Theorem 2's ball is a guarantee. Each row shows its n and the outcome at the paper's
# stated setting (Eq. (28) as written, 4 N), which is not judged, with the reason.

# %% tags=["nbval-check-output"]
r3 = {c: rules.q3_tracking(rmse[c], units=grid[c].units, label=c) for c in costs}
r4 = {c: rules.q4_prediction({n: acc[c][n] for n in rules.SIX}, units=grid[c].units, label=c) for c in costs}
r5 = {c: rules.q5_adaptive(rmse[c], [t["inside_fraction"] for t in thm2[c]], label=c) for c in costs}
for q, r in (("Q3", r3), ("Q4", r4), ("Q5", r5)):
    for c in costs:
        print(f"{q} {c}: {verdict_from_checks(r[c].checks)}; " + "; ".join(
            f"{k.split(': ', 1)[1]} {'holds' if v else 'fails'}" for k, v in r[c].checks.items()))
        held = r[c].numbers.get("paired", {})
        print("   holds in " + ", ".join(f"{k}: {w['wins']}/{w['seeds']}" for k, w in held.items())
              if held else f"   AdapFNN within 25 % of FNN in {100 * r[c].numbers['within_fraction']:.0f} % of the units")

# %% [markdown]
# Each claim joins its cost variants (`rules.join_costs`), with the flights at the other bounds as context (reported,
# never judged), and says what the paper's stated setting gives and why it is not judged there
# (`rules.unjudged_bound_note`).

# %%
context_numbers = {"context_4N_mean_axis": {k.label(u_max_judged): {n: round(v.mean_axis, 4) for n, v in rows.items()}
                                            for k, rows in table.items() if k.u_max != u_max_judged}}
merged = partial(rules.join_costs, numbers=context_numbers)
S = len(grid[costs[0]].units)  # the independent units of every comparison
paper_rows = table.get(M.TableKey("as_written", PAPER_THRUST_MAX))  # the paper's stated setting: R = I, 4 N (or None)
at_paper = partial(rules.unjudged_bound_note, paper_rows, need=need, u_max=PAPER_THRUST_MAX,
                   setting="the paper's setting (Eq. (28) as written, R = I)",
                   flown="kept network, the paper's force, one flight per model")

# %%
q3 = merged(r3, figure=f"figures/tracking_{costs[-1]}.png",
            headline=headline_number(f"FNN tracking RMSE, {costs[-1]}, {u_max_judged:g} N", rmse[costs[-1]]["FNN"], unit="m"),
            paper="FNN-MPC tracks best of Nomi, Neural, MLP, FB, AdapNN, FNN; Neural < Nomi; MLP worse than Neural (Fig. 7)",
            title="MPC tracking with the feedback model", n=S, at_paper_setting=at_paper(metric="mean_axis", unit="m", compare=("FNN", "Nomi")),
            rule=f"paired wins over {S} independent units per cost at {u_max_judged:g} N")

# %%
claims = [
    q3,
    merged(r4, figure=f"figures/acc_prediction_{costs[-1]}.png",
           headline=headline_number(f"FNN first-step acceleration RMSE, {costs[-1]}", acc[costs[-1]]["FNN"], unit="m/s^2"),
           paper="the first-step acceleration prediction is best with the feedback model (Fig. S8)",
           title="First-step prediction", n=S, at_paper_setting=at_paper(metric="acc_pred_rmse", unit="m/s^2", compare=("FNN", "Nomi")),
           rule=f"FNN paired-beats the other five over {S} independent units per cost"),
    merged(r5, figure="figures/adapfnn.png",
           headline=headline_number(f"AdapFNN / FNN RMSE, {costs[-1]}", np.divide(rmse[costs[-1]]["AdapFNN"], rmse[costs[-1]]["FNN"])),
           paper="AdapFNN is comparable to FNN with a slightly larger RMSE (Fig. S14, Theorem 2)",
           title="Adaptive feedback network", n=S, at_paper_setting=at_paper(metric="mean_axis", unit="m", compare=("AdapFNN", "FNN")),
           rule=f"within 25 % in >= S - 1 of S = {S} independent units and mean >= FNN's; Theorem 2 ball a guarantee"),
]

# %%
gamma_protocol = {"rule": f"lowest median validation RMSE (diverged = worst); ties within {Gamma_rtol:g} "
                          "relative go to the smaller gain",
                  "randomization": dict(VALIDATION_RANDOMIZATION), "references": len(val_refs),
                  "vehicles": [{"mass": v.mass, "inertia": v.inertia, "drag": v.drag,
                                "force": v.force_disturbance} for v in val_vehicles],
                  "test_vehicle_in_ranges": test_in_range}

# %%
write_results(out, task="quadrotor_mpc", profile=profile, claims=claims,
                metrics={"table": M.flight_table_json(table, u_max_judged), "speed": speed, "disturbances": forces,
                         "units": list(grid[costs[0]].units), "thrust_needed_per_motor": need,
                         "adapnn_gamma": {c: {"chosen": s.value, "validation": s.table} for c, s in gamma_sel.items()},
                         "adapnn_gamma_protocol": gamma_protocol,
                         "adapnn_oracle_sweep": {c: {g: M.flight_row(r).to_dict() for g, r in runs.items()}
                                                 for c, runs in oracle.items()},
                         "paired_mean_axis_rmse_m": rmse, "paired_acc_pred_rmse": acc})
for c in claims:
    print(c.id, c.verdict, c.checks)
