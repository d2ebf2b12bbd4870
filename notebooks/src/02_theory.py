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
# Sec. 3 with the neural ODE trained by the `spiral` task (loaded, never retrained). Theorem 2 (the adaptive
# variant, App. A.6) belongs to the quadrotor section.

# %% tags=["parameters"]
# None: the paper value from fnnlib's presets (fnnlib.settings.NOTEBOOK_PRESETS), filled in by the runner
profile = "paper"
out_dir = "outputs/manual/theory"
upstream_dirs = {"spiral": "outputs/paper/spiral"}
seed = 0
n_samples = None
Ts = None
test = None
x0 = None
L = None
L_sweep = [5.0, 10.0, 20.0, 40.0, 80.0]
transient_time_constants = 5.0
conservative_ratio = 2.0
discrete_gains = [0.0, 5.0, 10.0, 20.0, 50.0, 100.0, 150.0, 180.0, 190.0, 195.0, 198.0, 199.0, 199.5, 200.0,
                  201.0, 202.0, 205.0, 210.0, 220.0, 250.0]
growth_threshold = 10.0
rate_tolerance = 0.005

# %%
import fnnlib as F

F.check_notebook_settings("theory", globals())  # the checks `fnn-pipeline check` runs first

# %% [tags: hide-input]
import copy
from pathlib import Path

import numpy as np
import torch

import fnnlib as F
from fnnbook.rules import sec3

F.check_gain(L, 2, Ts)  # Theorem 1 needs a positive-definite L; refuse a bad one before any work
for g in L_sweep:
    F.check_gain(g, 2, Ts)

# %%
out = Path(out_dir)
out.mkdir(parents=True, exist_ok=True)
F.seed_everything(seed)
model, meta = F.load_checkpoint(Path(upstream_dirs["spiral"]) / "neural_ode.pt", expected_kind="NeuralODE")
model64 = copy.deepcopy(model).double()  # float64 throughout: the diverging runs below reach 1e100
t = torch.arange(n_samples, dtype=torch.float64) * Ts
tn = t.numpy()
sys_test = F.Spiral(*test)
x = sys_test.simulate(torch.tensor(x0), t)  # (T, 2), the measured test trajectory (noise-free, as Fig. 4d-f)

# %% [markdown]
# ## Rules, fixed before any number is computed
# **S5 (Theorem 1).** The residual bound is measured along the run,
# $\gamma = \max_k \|f(x_k) - f_{neural}(x_k)\|$ (Eq. (3), Assumption 1), with $f$ the true test spiral.
# The transient is $t < t_{tr} = $ `transient_time_constants` $/\lambda_m(L)$ (0.25 s for $L = 20$).
# *Guarantees* (Theorem 1 itself, with $\gamma$ measured on this run; they never count toward the verdict and
# a failing one stops the notebook): the continuous-time observer $\dot{\hat x} = f_{neural}(x) + L(x - \hat x)$
# integrated with the true system (Theorem 1's own setting) has (i) $\max_{t \ge t_{tr}}\|\tilde x\| \le
# \gamma/\lambda_m$ and (ii) $\max_{t \ge t_{tr}}\|\tilde f\| \le \gamma\lambda_M/\lambda_m + \gamma$.
# *Checks* (`fnnbook.rules.sec3.s5`): (i)-(ii) for the feedback network of Eqs. (7)-(8), the Euler
# discretisation the theorem does not cover exactly; (iii) *conservative*: for both balls, radius / measured
# limit $\ge$ `conservative_ratio` for the feedback network, the measured limit being the maximum over the last
# half of the run; (iv) over `L_sweep`, the measured limit of $\|\tilde x\|$ is inside $\gamma/L$ at every gain,
# and (v) it decreases as $L$ grows.
#
# **S6 (App. A.2).** For each scalar gain in `discrete_gains`, $\rho = |1 - T_s L|$; the feedback network runs
# with `allow_unstable=True`. A run *diverges* when its growth factor (largest $\|\tilde x\|$ in the last tenth of
# the run over the largest in the tenth before the middle) exceeds `growth_threshold` = 10: a bounded error
# gives about 1, a linear drift (the open loop, $\rho = 1$) about 2, and $\rho^k$ growth with $\rho \ge 1.01$
# over the 500 steps between the windows at least 145. *Guarantee* (Eq. (25) itself, constants measured on
# the run): every run with $\rho < 1$ stays under the ISS bound $T_s\gamma_d\sum_{j<k}\rho^j$,
# $\gamma_d = \max_k\|\Delta f_k\|$ with the discrete residual $\Delta f_k = (x_{k+1} - x_k)/T_s - f_{neural}(x_k)$
# that drives Eq. (25) exactly. *Checks* (`fnnbook.rules.sec3.s6`): (i) every run with $\rho < 1$ is bounded
# (growth factor); (ii) every run with
# $\rho > 1$ diverges; (iii) along the sorted $\rho$ grid the classification switches once, between adjacent
# grid values $\rho_{lo} \le 1 \le \rho_{hi}$ (the largest bounded and the smallest diverging $\rho$);
# (iv) every diverging run grows per step at the rate $\rho$ (window ratio$^{1/500}$ within `rate_tolerance`
# of $\rho$).

# %% [markdown]
# ## Theorem 1 along the test spiral (Fig. S1, claim S5)

# %%
with torch.no_grad():
    f_true, f_nn = sys_test.rate(x), F.eval_field(model64, x)
gamma = float((f_true - f_nn).norm(dim=-1).max())  # Assumption 1, measured
lam_m, lam_M = F.gain_eigen_bounds(L, 2)
ball1, ball2 = F.theorem1_balls(L, gamma, 2)
t_tr = transient_time_constants / lam_m
runs = {"feedback network": F.LinearFeedback(model64, L, Ts, 2).observe(x),
        "continuous observer": F.observe_continuous(sys_test, model64, L, torch.tensor(x0), t)[1]}

# %%
errs = {k: ((x - e.x_hat).norm(dim=-1), (f_true - e.f_hat).norm(dim=-1)) for k, e in runs.items()}
after, last_half = t >= t_tr, t >= t[-1] / 2
s5 = {"gamma": gamma, "lambda_min": lam_m, "lambda_max": lam_M, "ball_x": ball1, "ball_f": ball2, "t_transient": t_tr}
for k, (ex, ef) in errs.items():
    key = k.split()[0]
    s5 |= {f"{key}_max_x_after_transient": float(ex[after].max()),
           f"{key}_max_f_after_transient": float(ef[after].max()),
           f"{key}_limit_x": float(ex[last_half].max()), f"{key}_limit_f": float(ef[last_half].max())}
s5["ratio_x"] = ball1 / s5["feedback_limit_x"]
s5["ratio_f"] = ball2 / s5["feedback_limit_f"]
s5

# %%
ests = F.observe_gains(model64, x, Ts, torch.tensor(L_sweep))  # the feedback network at every gain, one pass
limits = (x - ests.x_hat).norm(dim=-1)[:, last_half].amax(dim=-1)
sweep_L = {"L": L_sweep, "ball_x": [gamma / g for g in L_sweep], "limit_x": limits.tolist(),
           "ratio": [gamma / g / float(m) for g, m in zip(L_sweep, limits)]}
sweep_L

# %%
fig, axes = F.new_figure(1, 3)
styles = {"feedback network": ("-", F.plotting.COLORS["feedback"]), "continuous observer": ("--", "k")}
for j, (ylab, ball, name) in enumerate([(r"$\|\tilde x\|$", ball1, r"$\gamma/\lambda_m$"),
                                        (r"$\|\tilde f\| = \|\dot{\tilde x}\|$", ball2,
                                         r"$\gamma\lambda_M/\lambda_m + \gamma$")]):
    ax = axes[0, j]
    for k, (ls, color) in styles.items():
        ax.semilogy(tn, errs[k][j].clamp_min(1e-6), ls, color=color, lw=1.2, label=k)
    ax.axhline(ball, color="0.3", ls=":", label=f"ball {name}")
    ax.axvline(t_tr, color="0.7", lw=0.8)
    ax.set(xlabel="t [s]", ylabel=ylab, title=f"({'ab'[j]}) L = {L:g}, gamma = {gamma:.3g}")
    ax.legend(fontsize=7, loc="lower right")

# %%
ax = axes[0, 2]
ax.loglog(L_sweep, sweep_L["ball_x"], "o:", color="0.3", label=r"ball $\gamma/L$")
ax.loglog(L_sweep, sweep_L["limit_x"], "o-", color=F.plotting.COLORS["feedback"], label="measured limit")
ax.set_xticks(L_sweep, [f"{g:g}" for g in L_sweep], minor=False)
ax.set_xticks([], minor=True)
ax.set(xlabel="L", ylabel=r"$\|\tilde x\|$ over the last half", title="(c) the ball is regulated by L")
ax.legend(fontsize=8)
fig_s1 = F.save_figure(fig, out, "figS1_bounds")

# %% [markdown]
# ## Discrete time: the spectral-radius boundary of Eq. (25) (App. A.2, claim S6)
# One batched pass runs the feedback network at every gain of the sweep (float64). $\rho(I - T_s L) = 1$ at
# $L = 0$ (the open loop) and at $L = 2/T_s = 200$; the grid is finer around 200.

# %%
gains = torch.tensor(discrete_gains, dtype=torch.float64)
rho = (1 - Ts * gains).abs()  # scalar gains: rho(I - Ts L) = |1 - Ts L|
est_d = F.observe_gains(model64, x, Ts, gains, allow_unstable=True)
err_d = F.scaled_error_norm(x, est_d.x_hat)  # (G, T); scaled so that a 1e176 error does not square to inf
with torch.no_grad():
    gamma_d = float(F.discrete_residual(x, f_nn, Ts).norm(dim=-1).max())
growth = F.growth_factor(err_d)
diverges = growth > growth_threshold
steps_between = n_samples - round(0.5 * n_samples)
rate = growth ** (1 / steps_between)
iss_max = torch.stack([F.iss_bound(g, Ts, gamma_d, n_samples).max() for g in discrete_gains])

# %%
s6 = {"L": discrete_gains, "rho": rho.tolist(), "growth_factor": growth.tolist(), "diverges": diverges.tolist(),
      "max_err": err_d.amax(-1).tolist(), "iss_bound_max": iss_max.tolist(), "gamma_d": gamma_d,
      "measured_rate": rate.tolist()}
{k: (np.round(v, 4).tolist() if isinstance(v, list) else v) for k, v in s6.items() if k != "diverges"}

# %%
stable, unstable = rho < 1, rho > 1
switches, rho_lo, rho_hi = F.divergence_transition(rho, diverges)
print(f"bounded up to rho = {rho_lo:.4g}, diverging from rho = {rho_hi:.4g}; class switches along rho: {switches}")

# %%
fig, axes = F.new_figure(1, 3)
ax = axes[0, 0]
for g in [100.0, 199.0, 200.0, 201.0, 210.0, 0.0]:
    if g in discrete_gains:
        i = discrete_gains.index(g)
        ax.semilogy(tn, err_d[i].clamp_min(1e-8), lw=1, label=f"L = {g:g} (rho = {float(rho[i]):.3g})")
ax.set(xlabel="t [s]", ylabel=r"$\|\tilde x_k\|$", title="(a) observer error, Eq. (25)")
ax.legend(fontsize=7)

# %%
ax = axes[0, 1]
ax.semilogy(rho[~diverges], growth[~diverges], "o", color=F.plotting.COLORS["luenberger"], label="bounded")
ax.semilogy(rho[diverges], growth[diverges], "s", color=F.plotting.COLORS["feedback"], label="diverges")
ax.axhline(growth_threshold, color="0.5", ls=":")
ax.axvline(1.0, color="k", lw=0.8)
ax.set(xlabel=r"$\rho(I - T_s L)$", ylabel="growth factor", title="(b) divergence starts at rho = 1")
ax.legend(fontsize=8)
ax = axes[0, 2]
ax.semilogy(rho[stable], err_d.amax(-1)[stable], "o", color=F.plotting.COLORS["feedback"],
            label=r"max $\|\tilde x_k\|$")
ax.semilogy(rho[stable], iss_max[stable], "x", color="0.3", label=r"ISS bound $T_s\gamma_d\sum\rho^j$")
ax.set(xlabel=r"$\rho < 1$", ylabel="error", title="(c) bounded runs vs the ISS bound")
ax.legend(fontsize=8)
fig_s6 = F.save_figure(fig, out, "figA2_discrete_stability")

# %% [markdown]
# ## Verdicts
# The rules are the ones stated at the top; each check is computed from the numbers above.

# %% [tags: nbval-check-output]
fb, ct = "feedback", "continuous"
claims = [
    F.claim_result("S5", **sec3.s5(ball_x=ball1, ball_f=ball2, feedback_x=s5[f"{fb}_max_x_after_transient"],
                                   feedback_f=s5[f"{fb}_max_f_after_transient"],
                                   continuous_x=s5[f"{ct}_max_x_after_transient"],
                                   continuous_f=s5[f"{ct}_max_f_after_transient"], ratio_x=s5["ratio_x"],
                                   ratio_f=s5["ratio_f"], L_sweep=L_sweep, limit_x=sweep_L["limit_x"],
                                   ball_x_sweep=sweep_L["ball_x"], conservative_ratio=conservative_ratio),
                   numbers=s5 | {"L_sweep": sweep_L}, figure=fig_s1,
                   headline=F.headline_number("ball / measured limit of |x~| (one network)", s5["ratio_x"])),
    F.claim_result("S6", **sec3.s6(rho=rho.tolist(), diverges=diverges.tolist(), max_err=err_d.amax(-1).tolist(),
                                   iss_bound=iss_max.tolist(), switches=switches, rho_lo=rho_lo, rho_hi=rho_hi,
                                   rate=rate.tolist(), rate_tolerance=rate_tolerance),
                   numbers=s6 | {"transition": [rho_lo, rho_hi], "class_switches": switches}, figure=fig_s6),
]

# %%
F.write_results(out, task="theory", profile=profile, claims=claims,
                metrics={"gamma": gamma, "gamma_d": gamma_d, "ratio_x": s5["ratio_x"], "ratio_f": s5["ratio_f"]})
for c in claims:
    print(f"{c['id']}: {c['verdict']:15s} {c['checks']}")
