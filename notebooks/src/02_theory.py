# %% [markdown]
# # Convergence of the linear feedback: Theorem 1 and App. A.2 (Fig. S1)
#
# The feedback network of Eqs. (7)-(8) has the observation error $\tilde x = x - \hat x$ with dynamics
# Eq. (5), $\dot{\tilde x} = -L\tilde x + \Delta f$. **Theorem 1** (App. A.2.1): if
# $\|\Delta f(t)\| \le \gamma$, then $\tilde x$ enters the ball $\mathcal B_1$ of radius $\gamma/\lambda_m(L)$
# and $\dot{\tilde x} = \tilde f$ the ball $\mathcal B_2$ of radius $\gamma\lambda_M(L)/\lambda_m(L) + \gamma$
# (claim **S5**, Fig. S1). In discrete time (App. A.2.2, Eq. (25)),
# $\tilde x_k = (I - T_s L)\tilde x_{k-1} + T_s\Delta f$ is input-to-state stable when
# $\rho(I - T_s L) < 1$ and diverges otherwise (claim **S6**). Both are measured here on the spiral of
# Sec. 3 with the neural ODEs trained by the `spiral` task, one per seed of that task (loaded, never retrained;
# claim **B2**): every number below is measured once per seed, on that seed's network, and the verdicts are
# decided over the seeds. Theorem 2 (the adaptive variant, App. A.6) belongs to the quadrotor section.

# %% tags=["parameters"]
profile = "paper"
out_dir = "outputs/manual/theory"
upstream_dirs = {"spiral": "outputs/paper/spiral"}
# the settings and their paper values, from fnnbook.tasks.theory (written by `make notebooks`)
n_samples = 1000
Ts = 0.01
x0 = [9.0, 0.0]
L_sweep = [5.0, 10.0, 20.0, 40.0, 80.0]
transient_time_constants = 5.0
conservative_ratio = 2.0
seed = 0
test = [3.0, 0.05, 10.0]
L = 20.0
discrete_gains = [0.0, 5.0, 10.0, 20.0, 50.0, 100.0, 150.0, 180.0, 190.0, 195.0, 198.0, 199.0, 199.5, 200.0, 201.0,
                  202.0, 205.0, 210.0, 220.0, 250.0]
growth_threshold = 10.0
rate_tolerance = 0.005

# %%
import fnnlib as F

from fnnbook.tasks.theory import TheorySettings
settings = TheorySettings.from_namespace(globals())  # checked as `fnn-pipeline check` checks them

# %% tags=["hide-input"]
from pathlib import Path

import numpy as np
import torch

import fnnlib as F
from fnnbook.results import headline_number, write_results
from fnnlib.feedback import eval_field, observe_gains
from fnnlib.models import split_members, stack_members
from fnnlib.plotting import new_figure, save_figure
from fnnlib.seeding import seed_everything
from fnnlib.stability import (discrete_residual, divergence_transition, gain_eigen_bounds, growth_factor,
    iss_bound, observe_continuous, scaled_error_norm, theorem1_balls)
from fnnlib.systems import Spiral, StackedSystem
from fnnlib.training import load_seed_ensemble
from fnnbook.rules import sec3

# %%
out = Path(out_dir)
out.mkdir(parents=True, exist_ok=True)
seed_everything(seed)
# every seed's network of the spiral task side by side on the stacked state, in float64 throughout (the
# diverging runs reach 1e100)
ens64 = load_seed_ensemble(upstream_dirs["spiral"], dtype=torch.float64)
seeds, S = ens64.seeds, ens64.size
t = torch.arange(n_samples, dtype=torch.float64) * Ts
tn = t.numpy()
sys_test = Spiral(*test)
x = sys_test.simulate(torch.tensor(x0), t)  # (T, 2), the measured test trajectory (noise-free, as Fig. 4d-f)
xs = stack_members(x, S)  # (T, 2S): the same measurements for every seed's network
print(f"{S} networks (seeds {seeds}) from the spiral task")

# %% [markdown]
# ## Rules, fixed before any number is computed
# **S5 (Theorem 1).** The residual bound is measured along the run,
# $\gamma = \max_k \|f(x_k) - f_{neural}(x_k)\|$ (Eq. (3), Assumption 1), with $f$ the true test spiral.
# The transient is $t < t_{tr} = $ `transient_time_constants` $/\lambda_m(L)$ (0.25 s for $L = 20$).
# *Guarantees* (Theorem 1 itself, with $\gamma$ measured on this run; they never count toward the verdict and
# a failing one stops the notebook): the continuous-time observer $\dot{\hat x} = f_{neural}(x) + L(x - \hat x)$
# integrated with the true system (Theorem 1's own setting) has (i) $\max_{t \ge t_{tr}}\|\tilde x\| \le
# \gamma/\lambda_m$ and (ii) $\max_{t \ge t_{tr}}\|\tilde f\| \le \gamma\lambda_M/\lambda_m + \gamma$.
# The feedback network of Eqs. (7)-(8) inside both balls (i)-(ii), and over `L_sweep` the measured limit of
# $\|\tilde x\|$ inside $\gamma/L$ at every gain (iv), are Eq. (25) with $\gamma$ measured on the same run: they
# are *guarantees* too (every seed), not checks; so is (v) the measured limit decreasing as $L$ grows over
# `L_sweep`, which the linear recursion of Eq. (25) implies. The *check* (`fnnbook.rules.sec3.s5`), which a run
# could fail: (iii) *conservative*: for both balls, radius / measured limit $\ge$ `conservative_ratio` for the
# feedback network, the measured limit being the maximum over the last half of the run. The paper says
# "relatively conservative" and gives no factor: `conservative_ratio` = 2 is this project's choice.
#
# **Over seeds.** Each quantity above is measured per seed (its own $\gamma$, balls, limits). Every check is a
# *threshold* check (a property of one run), so it holds when it holds in at least $S-1$ of the $S$ seeds
# (`sec3.most_seeds`); a guarantee must hold in every seed.
#
# **S6 (App. A.2).** For each scalar gain in `discrete_gains`, $\rho = |1 - T_s L|$; the feedback network runs
# with `allow_unstable=True`. A run *diverges* when its growth factor (largest $\|\tilde x\|$ in the last tenth of
# the run over the largest in the tenth before the middle) exceeds `growth_threshold` = 10: a bounded error
# gives about 1, a linear drift (the open loop, $\rho = 1$) about 2, and $\rho^k$ growth with $\rho \ge 1.01$
# over the 500 steps between the windows at least 145. *Guarantee* (Eq. (25) itself, constants measured on
# the run): every run with $\rho < 1$ stays under the ISS bound $T_s\gamma_d\sum_{j<k}\rho^j$,
# $\gamma_d = \max_k\|\Delta f_k\|$ with the discrete residual $\Delta f_k = (x_{k+1} - x_k)/T_s - f_{neural}(x_k)$
# that drives Eq. (25) exactly. *Guarantees* as well, for the same reason (with $f$ evaluated at the
# measurement the error obeys the linear recursion of Eq. (25) exactly, so each is algebra, not a finding):
# (i) every run with $\rho < 1$ is bounded (growth factor). *Reported* (neither check nor guarantee: the same
# algebra, but whether the growth-factor detector sees it depends on the record's length): (ii) every run with
# $\rho > 1$ diverges; (iii) along the sorted $\rho$ grid the classification switches once, between adjacent
# grid values $\rho_{lo} \le 1 \le \rho_{hi}$ (the largest bounded and the smallest diverging $\rho$);
# (iv) every diverging run grows per step at the rate $\rho$ (window ratio$^{1/500}$ within `rate_tolerance`
# of $\rho$). The guarantees hold in every seed. With no check a run could fail, S6 is *verified by construction*,
# never counted as reproduced.

# %% [markdown]
# ## Theorem 1 along the test spiral (Fig. S1, claim S5)
# One batched pass runs the feedback network of every seed (the stacked state); the continuous observer of
# every seed is one dopri5 integration of the stacked true system beside the stacked networks.

# %%
with torch.no_grad():
    f_true, f_nn = sys_test.rate(x), split_members(eval_field(ens64, xs), S)  # (T, 2), (S, T, 2)
gamma = (f_true - f_nn).norm(dim=-1).amax(dim=-1)  # (S,) Assumption 1, measured per seed
lam_m, lam_M = gain_eigen_bounds(L, 2)
ball1, ball2 = (torch.tensor(b, dtype=torch.float64) for b in zip(*(theorem1_balls(L, float(g), 2) for g in gamma)))
t_tr = transient_time_constants / lam_m
fb = F.LinearFeedback(ens64, Ts, gains=F.Gains(L), n=2 * S).observe(xs)
cont = observe_continuous(StackedSystem(sys_test, S), ens64, L, stack_members(torch.tensor(x0), S), t)[1]
runs = {k: (split_members(e.x_hat, S), split_members(e.f_hat, S))
        for k, e in [("feedback network", fb), ("continuous observer", cont)]}

# %%
errs = {k: ((x - xh).norm(dim=-1), (f_true - fh).norm(dim=-1)) for k, (xh, fh) in runs.items()}  # (S, T) each
after, last_half = t >= t_tr, t >= t[-1] / 2
s5 = {"seeds": seeds, "gamma": gamma.tolist(), "lambda_min": lam_m, "lambda_max": lam_M, "ball_x": ball1.tolist(),
      "ball_f": ball2.tolist(), "t_transient": t_tr}
for k, (ex, ef) in errs.items():
    key = k.split()[0]
    s5 |= {f"{key}_max_x_after_transient": ex[:, after].amax(-1).tolist(),
           f"{key}_max_f_after_transient": ef[:, after].amax(-1).tolist(),
           f"{key}_limit_x": ex[:, last_half].amax(-1).tolist(), f"{key}_limit_f": ef[:, last_half].amax(-1).tolist()}
s5["ratio_x"] = (ball1 / torch.tensor(s5["feedback_limit_x"], dtype=torch.float64)).tolist()
s5["ratio_f"] = (ball2 / torch.tensor(s5["feedback_limit_f"], dtype=torch.float64)).tolist()
s5

# %%
ests = observe_gains(ens64, xs, Ts, torch.tensor(L_sweep))  # every gain and every seed, one pass
limits = (x - split_members(ests.x_hat, S)).norm(dim=-1)[..., last_half].amax(dim=-1).T  # (gains, S)
ball_sweep = gamma[None] / torch.tensor(L_sweep, dtype=torch.float64)[:, None]  # (gains, S)
sweep_L = {"L": L_sweep, "ball_x": ball_sweep.tolist(), "limit_x": limits.tolist(),
           "ratio": (ball_sweep / limits).tolist()}
sweep_L

# %%
fig, axes = new_figure(1, 3)
styles = {"feedback network": ("-", F.plotting.COLORS["feedback"]), "continuous observer": ("--", "k")}
for j, (ylab, ball, name) in enumerate([(r"$\|\tilde x\|$", ball1, r"$\gamma/\lambda_m$"),
                                        (r"$\|\tilde f\| = \|\dot{\tilde x}\|$", ball2,
                                         r"$\gamma\lambda_M/\lambda_m + \gamma$")]):
    ax = axes[0, j]
    for e in range(S):  # one faint line per seed
        for k, (ls, color) in styles.items():
            ax.semilogy(tn, errs[k][j][e].clamp_min(1e-6), ls, color=color, lw=0.8, alpha=0.6,
                        label=k if e == 0 else None)
        ax.axhline(float(ball[e]), color="0.3", ls=":", lw=0.8, label=f"ball {name} (per seed)" if e == 0 else None)
    ax.axvline(t_tr, color="0.7", lw=0.8)
    ax.set(xlabel="t [s]", ylabel=ylab, title=f"({'ab'[j]}) L = {L:g}, {S} seeds, gamma {float(gamma.min()):.3g}-"
                                              f"{float(gamma.max()):.3g}")
    ax.legend(fontsize=7, loc="lower right")
ax = axes[0, 2]
for v, style, color, label in [(ball_sweep, "o:", "0.3", r"ball $\gamma/L$"),
                               (limits, "o-", F.plotting.COLORS["feedback"], "measured limit")]:
    ax.loglog(L_sweep, v.mean(1), style, color=color, label=f"{label} (mean)")
    ax.fill_between(L_sweep, v.amin(1), v.amax(1), color=color, alpha=0.25, lw=0)
ax.set_xticks(L_sweep, [f"{g:g}" for g in L_sweep], minor=False)
ax.set_xticks([], minor=True)
ax.set(xlabel="L", ylabel=r"$\|\tilde x\|$ over the last half", title=f"(c) the ball follows L (min-max of {S} seeds)")
ax.legend(fontsize=8)
fig_s1 = save_figure(fig, out, "figS1_bounds")

# %% [markdown]
# ## Discrete time: the spectral-radius boundary of Eq. (25) (App. A.2, claim S6)
# One batched pass runs the feedback network of every seed at every gain of the sweep (float64).
# $\rho(I - T_s L) = 1$ at $L = 0$ (the open loop) and at $L = 2/T_s = 200$; the grid is finer around 200.
# The ISS bound is linear in $\gamma_d$: it is computed once per gain for $\gamma_d = 1$ and scaled by each
# seed's $\gamma_d$.

# %%
gains = torch.tensor(discrete_gains, dtype=torch.float64)
rho = (1 - Ts * gains).abs()  # scalar gains: rho(I - Ts L) = |1 - Ts L|
est_d = observe_gains(ens64, xs, Ts, gains, allow_unstable=True)
err_d = scaled_error_norm(x, split_members(est_d.x_hat, S))  # (S, G, T); scaled: a 1e176 error stays finite
with torch.no_grad():
    gamma_d = discrete_residual(x.expand_as(f_nn), f_nn, Ts).norm(dim=-1).amax(dim=-1)  # (S,)
growth = growth_factor(err_d)  # (S, G)
diverges = growth > growth_threshold
steps_between = n_samples - round(0.5 * n_samples)
rate = growth ** (1 / steps_between)
iss_unit = torch.stack([iss_bound(g, Ts, 1.0, n_samples).max() for g in discrete_gains])  # gamma_d = 1
iss_max = gamma_d[:, None] * iss_unit[None]  # (S, G)

# %%
s6 = {"seeds": seeds, "L": discrete_gains, "rho": rho.tolist(), "gamma_d": gamma_d.tolist()}
s6 |= {k: v.T.tolist() for k, v in [("growth_factor", growth), ("diverges", diverges), ("max_err", err_d.amax(-1)),
                                     ("iss_bound_max", iss_max), ("measured_rate", rate)]}  # rows: gains, cols: seeds
{k: (np.round(v, 4).tolist() if k in ("rho", "growth_factor", "measured_rate") else v) for k, v in s6.items()
 if k not in ("diverges", "max_err", "iss_bound_max")}

# %%
stable, unstable = rho < 1, rho > 1
transitions = [divergence_transition(rho, diverges[e]) for e in range(S)]
switches, rho_lo, rho_hi = (list(v) for v in zip(*transitions))
for s, (n_sw, lo, hi) in zip(seeds, transitions):
    print(f"seed {s}: bounded up to rho = {lo:.4g}, diverging from rho = {hi:.4g}; class switches along rho: {n_sw}")

# %%
fig, axes = new_figure(1, 3)
ax = axes[0, 0]
for g in [100.0, 199.0, 200.0, 201.0, 210.0, 0.0]:
    if g in discrete_gains:
        i = discrete_gains.index(g)
        ax.semilogy(tn, err_d[0, i].clamp_min(1e-8), lw=1, label=f"L = {g:g} (rho = {float(rho[i]):.3g})")
ax.set(xlabel="t [s]", ylabel=r"$\|\tilde x_k\|$", title=f"(a) observer error, Eq. (25) (seed {seeds[0]})")
ax.legend(fontsize=7)
ax = axes[0, 1]
for e in range(S):  # every seed's runs
    d = diverges[e]
    ax.semilogy(rho[~d], growth[e][~d], "o", color=F.plotting.COLORS["luenberger"], alpha=0.6,
                label="bounded" if e == 0 else None)
    ax.semilogy(rho[d], growth[e][d], "s", color=F.plotting.COLORS["feedback"], alpha=0.6,
                label="diverges" if e == 0 else None)
ax.axhline(growth_threshold, color="0.5", ls=":")
ax.axvline(1.0, color="k", lw=0.8)
ax.set(xlabel=r"$\rho(I - T_s L)$", ylabel="growth factor", title=f"(b) divergence starts at rho = 1 ({S} seeds)")
ax.legend(fontsize=8)
ax = axes[0, 2]
for e in range(S):
    ax.semilogy(rho[stable], err_d[e].amax(-1)[stable], "o", color=F.plotting.COLORS["feedback"], alpha=0.6,
                label=r"max $\|\tilde x_k\|$" if e == 0 else None)
    ax.semilogy(rho[stable], iss_max[e][stable], "x", color="0.3", alpha=0.6,
                label=r"ISS bound $T_s\gamma_d\sum\rho^j$" if e == 0 else None)
ax.set(xlabel=r"$\rho < 1$", ylabel="error", title=f"(c) bounded runs vs the ISS bound ({S} seeds)")
ax.legend(fontsize=8)
fig_s6 = save_figure(fig, out, "figA2_discrete_stability")

# %% [markdown]
# ## Verdicts
# The rules are the ones stated at the top (`fnnbook.rules.sec3`, tested in `tests/rules/test_sec3.py`); each
# check is computed from the numbers above, one per seed, and holds when it holds in at least $S-1$ of the $S$
# seeds; a guarantee must hold in every seed. The headline is the mean ± standard deviation over the seeds.

# %%
fb, ct = "feedback", "continuous"
s6_rule = sec3.s6(rho=rho.tolist(), diverges=s6["diverges"], max_err=s6["max_err"], iss_bound=s6["iss_bound_max"],
                  switches=switches, rho_lo=rho_lo, rho_hi=rho_hi, rate=s6["measured_rate"],
                  rate_tolerance=rate_tolerance)

# %% tags=["nbval-check-output"]
claims = [
    sec3.s5(ball_x=s5["ball_x"], ball_f=s5["ball_f"],
            feedback_x=s5[f"{fb}_max_x_after_transient"],
            feedback_f=s5[f"{fb}_max_f_after_transient"],
            continuous_x=s5[f"{ct}_max_x_after_transient"],
            continuous_f=s5[f"{ct}_max_f_after_transient"], ratio_x=s5["ratio_x"],
            ratio_f=s5["ratio_f"], L_sweep=L_sweep, limit_x=sweep_L["limit_x"],
            ball_x_sweep=sweep_L["ball_x"], conservative_ratio=conservative_ratio).replace(
        numbers=s5 | {"L_sweep": sweep_L}, figure=fig_s1,
        headline=headline_number("ball / measured limit of |x~|", s5["ratio_x"])),
    s6_rule.replace(numbers=s6_rule.numbers | s6 | {"transition": [rho_lo, rho_hi], "class_switches": switches},
                    figure=fig_s6),
]

# %%
write_results(out, task="theory", profile=profile, claims=claims,
                metrics={"seeds": seeds, "gamma": gamma.tolist(), "gamma_d": gamma_d.tolist(),
                         "ratio_x": s5["ratio_x"], "ratio_f": s5["ratio_f"]})
for c in claims:
    print(f"{c.id}: {c.verdict:15s} {c.checks}")
