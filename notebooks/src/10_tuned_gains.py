# %% [markdown]
# # Gains tuned from data (claim B1)
#
# The paper picks the feedback gain $L$ and the decay rate $\beta$ of Eq. (11) by hand and names their
# choice its open problem. Here they are **learned** from training data by gradient descent on the $N$-step
# prediction error through the differentiable cascade of Sec. 3.3 (`tune_gains`), and compared with the
# paper's hand-tuned values on data the tuning never saw, in four settings:
#
# | setting | tuned on | judged on | units |
# |---|---|---|---|
# | pendulum (`own_system`) | one noisy test-pendulum trajectory per seed | another one | 5 seeds |
# | noisy spiral (S3, `own_system`) | a noisy test spiral started elsewhere | the S3 trajectory | 5 seeds |
# | bottle throws (O1) | whole **training** throws | the 9 **test** throws, 0.5 s error as in O1 | test throws |
# | quadrotor FNN-MPC (Q3) | the **training** flights, $N = 10$ | the test Lissajous on the test vehicle | networks x disturbances |
#
# Nothing is retrained or reflown where the upstream task already measured it: the hand-tuned and
# open-loop errors of the bottle come from `bottle`, the FNN (hand-tuned) and Neural (no feedback)
# flights from `quadrotor_mpc`, the pendulum and spiral numbers from `own_system`; this chapter tunes,
# then evaluates only the tuned gains, exactly as those tasks evaluate theirs.

# %% tags=["parameters"]
profile = "paper"
out_dir = "outputs/manual/tuned_gains"
data_dir = "data"
upstream_dirs = {"own_system": "outputs/manual/own_system", "bottle": "outputs/manual/bottle",
                 "quadrotor_learning": "outputs/manual/quadrotor_learning",
                 "quadrotor_mpc": "outputs/manual/quadrotor_mpc"}
bottle_data = "real"
bottle_synthetic_sizes = [21, 9, 1058]
bottle_hidden = [100, 100, 100]
bottle_activation = "relu"
bottle_iterations = 1000
bottle_batch_size = 20
bottle_batch_time = 10
bottle_lr = 0.001
bottle_method = "dopri5"
bottle_adjoint = False
bottle_L = 5.0
bottle_beta = 0.02
bottle_N = 500
bottle_tune_throws = 2
bottle_tune_iterations = 3
bottle_tune_lr = 0.3
quad_L = 3.0
quad_beta = 0.1
quad_N = 10
quad_Ts = 0.02
quad_tune_flights = 8
quad_tune_iterations = 8
quad_tune_lr = 0.2
steps = 300
Q = [100.0, 100.0, 100.0, 50.0, 50.0, 50.0, 50.0, 50.0, 50.0, 1.0, 1.0, 1.0]
R = [1.0, 1.0, 1.0, 1.0]
u_max_judged = 6.0
theta_max = 1.5707963267948966
truth_mass = 1.33
truth_inertia = [0.005, 0.005, 0.004]
truth_drag = [0.6, 0.6, 0.15]
truth_substeps = 1
solver = "OSQP"
qp = "osqp"
linearize_method = "forward"
backend = "numba"

# %%
import fnnlib as F

F.check_notebook_settings("tuned_gains", globals())  # the checks `fnn-pipeline check` runs first

# %% [tags: hide-input]
import json
import time
from pathlib import Path

import numpy as np
import torch

from fnnbook.rules import beyond as rules

out = Path(out_dir)
out.mkdir(parents=True, exist_ok=True)
up = {k: Path(v) for k, v in upstream_dirs.items()}
upstream = {k: json.loads((up[k] / "results.json").read_text()) for k in ("own_system", "bottle", "quadrotor_mpc")}
t_start = time.perf_counter()
seconds: dict[str, float] = {}

# %% [markdown]
# ## The rule (fixed before the numbers)
# `fnnbook.rules.beyond.b1`, committed before any bottle or quadrotor number of this chapter existed. Per
# setting, one error per *unit*, paired across predictors: the tuned gains must win (`paired_win`: lower in
# at least S - 1 of S units and the 90 % t-interval of the mean paired difference below 0) over the
# hand-tuned gains and, where given, over the open-loop model; where a Kalman filter is given, the tuned
# error must stay within 2x its error in all units but one. All checks true: *reproduced*; some: *partly*;
# none: *not reproduced*.

# %% [markdown]
# ## The bottle throws (the O1 setting)
# `bottle` saves one of its neural ODEs; the five are trained again here with its recipe and seeds (the
# same deterministic run: the first member is checked equal, weight for weight, to the saved one, so the
# `bottle` task's hand-tuned and open-loop errors are those of these networks). Each network's
# $L$ (diagonal, 6 entries) and $\beta$ start at the paper's $L = 5$, $\beta = 0.02$ and take
# `bottle_tune_iterations` Adam steps on the 0.5 s ($N = 500$) error from every start of
# `bottle_tune_throws` **training** throws drawn with the network's seed: the O1 error itself, on training
# data. The tuned gains are then evaluated on the 9 test throws as O1 is (every start, Euler steps of
# 1 ms, position error 0.5 s ahead); units are the test throws, each throw's error averaged over the five
# networks (O1's "per throw").

# %% [tags: hide-input]
b_results = upstream["bottle"]
b_seeds = b_results["metrics"]["seeds"]
o1 = next(c for c in b_results["claims"] if c["id"] == "O1")["numbers"]
if bottle_data == "real":
    b_train, b_test = F.load_bottle(data_dir)
else:
    n_tr, n_te, n_s = bottle_synthetic_sizes
    b_train = F.synthetic_throws(n_tr, n_s, seed=b_seeds[0])
    b_test = F.synthetic_throws(n_te, n_s, seed=b_seeds[0] + 1)
if o1["data"] != bottle_data:
    raise ValueError(f"bottle ran on {o1['data']!r} throws, this chapter is set to {bottle_data!r}: set bottle_data")
b_Ts, bN, E = b_train.Ts, bottle_N, len(b_seeds)
x_b_train, x_b_test = b_train.state.float(), b_test.state.float()

t0 = time.perf_counter()
recipe = F.PAPER_BOTTLE_RECIPE.replace(iterations=bottle_iterations, batch_size=bottle_batch_size,
                                       batch_time=bottle_batch_time, lr=bottle_lr, method=bottle_method,
                                       adjoint=bottle_adjoint)
ens = F.NeuralODEEnsemble(6, bottle_hidden, bottle_activation, b_seeds)
F.train_neural_ode(ens, b_train.t.float(), F.stack_members(x_b_train, E), recipe, seed=b_seeds[0], progress=False)
saved, _ = F.load_checkpoint(up["bottle"] / "neural_ode.pt", expected_kind="NeuralODE")
b_nets = [ens.member(e) for e in range(E)]
same = all(torch.equal(a, b) for a, b in zip(b_nets[0].state_dict().values(), saved.state_dict().values()))
seconds["bottle_retrain"] = time.perf_counter() - t0
print(f"{E} neural ODEs trained again in {seconds['bottle_retrain']:.1f} s; the first equals bottle's saved one: {same}")

# %%
def bottle_tune(seed: int, net) -> F.TunedGains:
    """The network's (L, beta), tuned on the O1 error of training throws drawn with its seed."""
    which = torch.randperm(x_b_train.shape[0], generator=F.make_generator(seed))[:bottle_tune_throws]
    return F.tune_gains(net, x_b_train[which], b_Ts, bN, L0=bottle_L, beta0=bottle_beta,
                        iterations=bottle_tune_iterations, lr=bottle_tune_lr)


def o1_errors(pred: torch.Tensor) -> torch.Tensor:
    """Each test throw's mean 0.5 s position error (O1's error) of predictions from its first T - N starts."""
    return F.error_norm(pred[..., :3], x_b_test[:, bN:, :3].expand_as(pred[..., :3])).mean(-1)


t0 = time.perf_counter()
b_tuned = [bottle_tune(s, net) for s, net in zip(b_seeds, b_nets)]
seconds["bottle_tune"] = time.perf_counter() - t0
t0 = time.perf_counter()
starts = x_b_test[:, :-bN]  # the cascade is causal: the first T - N rows are those of the whole run
tuned_per_seed = torch.stack([o1_errors(F.cascade_predict(net, starts, b_Ts, bN, torch.tensor(r.L), r.beta))
                              for net, r in zip(b_nets, b_tuned)])  # (seeds, throws)
if same:  # the bottle task's own errors of these networks
    hand, open_loop = o1["per_throw_m"]["feedback"], o1["per_throw_m"]["neural ODE"]
else:  # another run (e.g. another thread count): measure the paper's gains on these networks too
    print("the networks differ from bottle's run: the hand-tuned and open-loop errors are measured here")
    hand = torch.stack([o1_errors(F.cascade_predict(n, starts, b_Ts, bN, bottle_L, bottle_beta)) for n in b_nets]).mean(0).tolist()
    open_loop = torch.stack([o1_errors(F.rollout_predict(n, x_b_test, b_Ts, bN)[:, :-bN]) for n in b_nets]).mean(0).tolist()
seconds["bottle_eval"] = time.perf_counter() - t0
errors = {"bottle": {"tuned": tuned_per_seed.mean(0).tolist(), "hand": hand, "open_loop": open_loop}}
tuned_values = {"bottle": [{"seed": s, "L": r.L, "beta": r.beta, "loss": r.loss} for s, r in zip(b_seeds, b_tuned)]}
print("bottle, mean 0.5 s error [m]: " + ", ".join(f"{k} {np.mean(v):.4f}" for k, v in errors["bottle"].items()))
[(np.round(r.L, 2).tolist(), round(r.beta, 4)) for r in b_tuned]

# %% [markdown]
# ## The quadrotor FNN-MPC flight (the Q3 setting)
# For each of the five residual networks of `quadrotor_learning`, a diagonal $L$ (12 entries) and $\beta$
# start at the paper's $L = 3 I$, $\beta = 0.1$ and take `quad_tune_iterations` Adam steps on the
# $N = 10$-step prediction error (the MPC horizon) of `quad_tune_flights` **training** flights drawn with the
# network's seed, with the recorded thrusts as inputs. The cascade is the one inside the MPC horizon
# (`FeedbackCascadeModel`): each layer's step is the model's RK4 step $\Phi$ plus $T_s L_k(z - \hat x)$, which
# is the cascade of Sec. 3.3 with the rate $(\Phi(z, u) - z)/T_s$. FNN then flies the test Lissajous on the
# test vehicle with the tuned gains, at the judged 6 N bound, for every network and disturbance of
# `quadrotor_mpc` and each of its cost variants (Eq. (28) as written and as the release flies it: one B1
# setting each, as Q3 judges both); the 4 N bound, context only in Q3-Q5, is not flown. The hand-tuned FNN
# and the Neural model (no feedback: the open loop) are `quadrotor_mpc`'s own flights, paired entry by entry;
# one of its FNN flights is flown again first to check that the two set-ups agree. The tuning sees the
# open-loop prediction error only, never the closed loop: gains that predict better need not fly better,
# and the two cost variants close the loop differently.

# %% [tags: hide-input]
from fnnlib.data.quadrotor import load_flights
from fnnlib.mpc.compiled import warm_up
from fnnlib.mpc.experiment import FlightTest, flight_row, make_mpc
from fnnlib.mpc.flight import lissajous_reference
from fnnlib.mpc.models import FeedbackCascadeModel, PredictionModel
from fnnlib.quadrotor_presets import PAPER_LISSAJOUS
from fnnlib.systems.quadrotor import NOMINAL, TEST_TRUTH, Quadrotor

q_mpc = upstream["quadrotor_mpc"]["metrics"]
q_rmse, forces = q_mpc["paired_mean_axis_rmse_m"], q_mpc["disturbances"]
costs = list(q_rmse)
member_files = json.loads((up["quadrotor_learning"] / "results.json").read_text())["metrics"]["member_checkpoints"]
members = [(int(meta["seed"]), net.double()) for net, meta in
           (F.load_checkpoint(up["quadrotor_learning"] / f, expected_kind="AeroResidual") for f in member_files)]
flights, _ = load_flights(up["quadrotor_learning"] / "flights_train.npz")
plant = Quadrotor(NOMINAL)
test_params = TEST_TRUTH.replace(mass=truth_mass, inertia=tuple(truth_inertia), drag=tuple(truth_drag))
x_r, u_r = lissajous_reference(steps, quad_N, Ts=quad_Ts, params=NOMINAL, curve=PAPER_LISSAJOUS)
tests = [FlightTest(Quadrotor(test_params.replace(force_disturbance=tuple(f))), x_r, u_r, steps=steps, Ts=quad_Ts,
                    substeps=truth_substeps, backend=backend, linearize_method=linearize_method) for f in forces]
mpcs = {cost: make_mpc(qp, quad_N, Q, R, cost=cost, u_max=u_max_judged, theta_max=theta_max, solver=solver)
        for cost in costs}
seconds["quad_compile"] = warm_up(*[net for _, net in members]) if backend == "numba" else 0.0


def fnn_flight(net, L, beta, test: FlightTest, cost: str) -> dict:
    """FNN (residual ``net``, gains ``L``, ``beta``) flown as `quadrotor_mpc` flies it: its row of the flight table."""
    fnn = FeedbackCascadeModel(PredictionModel("Neural", plant, net, Ts=quad_Ts), L, beta, quad_N, name="FNN")
    return flight_row(test.fly(fnn, mpcs[cost]))


again = fnn_flight(members[0][1], quad_L, quad_beta, tests[0], costs[0])["mean_axis"]
if not np.isclose(again, q_rmse[costs[0]]["FNN"][0], rtol=1e-9, atol=0):
    raise ValueError(f"FNN flown again with the paper's gains gives {again:.6g} m, quadrotor_mpc measured "
                     f"{q_rmse[costs[0]]['FNN'][0]:.6g} m: this chapter's flight settings differ from that task's")

# %%
def quad_tune(seed: int, net) -> F.TunedGains:
    """The network's (L, beta), tuned on the N-step error of training flights drawn with its seed."""
    model = PredictionModel("Neural", plant, net, Ts=flights.Ts)
    which = torch.randperm(flights.n_flights, generator=F.make_generator(seed))[:quad_tune_flights]
    x, u = flights.x[which, :-1, :12], flights.u[which]  # vehicle states and the thrusts applied, (K, T, 12), (K, T, 4)

    def step_rate(t, z, uu):  # the Euler step of the cascade becomes the model's RK4 step Phi, as in the MPC
        return (model.phi(z, uu) - z) / flights.Ts

    return F.tune_gains(step_rate, x, flights.Ts, quad_N, u=u, L0=quad_L, beta0=quad_beta,
                        iterations=quad_tune_iterations, lr=quad_tune_lr)


t0 = time.perf_counter()
q_tuned = [quad_tune(s, net) for s, net in members]
seconds["quad_tune"] = time.perf_counter() - t0
t0 = time.perf_counter()
tuned_flights = {}
for cost in costs:  # (network, disturbance) with the disturbance fastest, as quadrotor_mpc pairs them
    rows = [fnn_flight(net, torch.tensor(r.L), r.beta, t, cost) for (_, net), r in zip(members, q_tuned) for t in tests]
    tuned_flights[cost] = [{k: row[k] for k in ("fallbacks", "fallback_reasons", "diverged")} for row in rows]
    errors[f"quadrotor {cost}"] = {"tuned": [row["mean_axis"] for row in rows],
                                   "hand": q_rmse[cost]["FNN"], "open_loop": q_rmse[cost]["Neural"]}
seconds["quad_fly"] = time.perf_counter() - t0
tuned_values["quadrotor"] = [{"seed": s, "L": r.L, "beta": r.beta, "loss": r.loss} for (s, _), r in zip(members, q_tuned)]
print(", ".join(f"{k}: " + ", ".join(f"{p} {np.mean(v):.4f} m" for p, v in e.items())
                for k, e in errors.items() if k.startswith("quadrotor")))
print("tuned flights with fallbacks: " + ", ".join(f"{cost} {sum(f['fallbacks'] > 0 for f in fl)}, diverged "
                                                    f"{sum(f['diverged'] for f in fl)}" for cost, fl in tuned_flights.items()))
[(np.round(r.L, 2).tolist(), round(r.beta, 3)) for r in q_tuned]

# %% [markdown]
# ## The pendulum and the noisy spiral (from `own_system`)
# Units: the 5 seeds of that chapter; predictors: open loop, hand-picked, tuned, Kalman.

# %%
own = upstream["own_system"]["metrics"]["b1"]
for k in ("pendulum", "spiral"):
    errors[k], tuned_values[k] = own["errors"][k], own["tuned"][k]
{k: {p: round(float(np.mean(v)), 4) for p, v in errors[k].items()} for k in ("pendulum", "spiral")}

# %% [markdown]
# ## Errors per unit
# One panel per setting: each unit's error with the hand-tuned gains (x) against the tuned ones (y);
# points below the diagonal are units where the tuned gains predict (or fly) better.

# %%
fig, axes = F.new_figure(1, len(errors))
for ax, (name, e) in zip(np.ravel(axes), errors.items()):
    ax.plot(e["hand"], e["tuned"], "o", color=F.plotting.COLORS["feedback"])
    lim = [min(e["hand"] + e["tuned"]), max(e["hand"] + e["tuned"])]
    ax.plot(lim, lim, "k--", lw=0.8)
    ax.set(xlabel="hand-tuned", ylabel="tuned", title=name)
fig_b1 = F.save_figure(fig, out, "b1_tuned_vs_hand")

# %% [markdown]
# ## Verdict

# %% [tags: nbval-check-output]
rule = rules.b1(errors)
paired = rules.b1_paired(errors)
claims = [F.claim_result("B1", **rule, figure=fig_b1, title="L and beta tuned from data",
                         numbers={"errors": errors, "paired": paired, "tuned": tuned_values,
                                  "bottle_tuned_per_seed": tuned_per_seed.tolist(),
                                  "bottle_networks_as_in_bottle": same, "quadrotor_tuned_flights": tuned_flights},
                         headline=F.headline_number("bottle 0.5 s error, tuned / hand-tuned gains",
                                                    float(np.mean(errors["bottle"]["tuned"]) /
                                                          np.mean(errors["bottle"]["hand"]))),
                         paper="no number: the paper names the choice of gains as its open problem")]
for name, ok in rule["checks"].items():
    print(f"{name:50s} {'holds' if ok else 'fails'}")
for c in claims:
    print(f"{c['id']}: {c['verdict']}")

# %%
seconds["total"] = time.perf_counter() - t_start
F.write_results(out, task="tuned_gains", profile=profile, claims=claims, metrics={"seconds": seconds})
{k: round(v, 1) for k, v in seconds.items()}
