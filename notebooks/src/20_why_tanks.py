# %% [markdown]
# # Why B4, B5 and B6 stand where they stand: the gains, the first estimate, the overflow window, the baseline
#
# The cascaded tanks chapter (`cascaded_tanks`) judges three claims on the benchmark's validation record, each
# over its seeds by its own rule (`fnnbook.rules.tanks`): **B4** the tuned feedback cascade beats the open-loop
# rollout from the same observer's estimate at every horizon $N > 1$; **B5** the model trained through its
# observer beats the same architecture trained without feedback in free-run RMSE; **B6** the tuned gains beat
# the hand gains at every $N > 1$. Here the same rules judge the chapter's trained models again (loaded, never
# retrained) where the chapter made a choice nobody states for this plant:
#
# * **the gains** (B4): every fixed $(L, \beta)$ of Eq. (11) in `L_grid` x `beta_grid`, in place of the tuned ones;
# * **the window** (B4, B6; a reading): every target sample, or only those outside the overflow episodes and
#   the chapter's `overflow_after` samples after each (no smooth model has seen the 10 V limit);
# * **the first estimate** (B4, B6; a usage): both tanks at the first measured level (the chapter's), or the
#   least-squares state $C^+ y_0$ (the upper tank empty);
# * **the baseline's start and segment** (B5): free initial states or an encoder, over segments of each of
#   `b5_horizons` samples, each seed trained with the chapter's Adam steps and rate (these models are trained
#   here: the chapter kept one start per seed).

# %% tags=["parameters"]
profile = "why"
out_dir = "outputs/manual/why_tanks"
data_dir = "data"
upstream_dirs = {"cascaded_tanks": "outputs/manual/cascaded_tanks"}
# the settings and their paper values, from fnnbook.tasks.why_tanks (written by `make notebooks`)
L_grid = [0.005, 0.01, 0.02, 0.05]
beta_grid = [0.0, 0.1, 0.5]
windows = ["all", "outside_overflow"]
first_estimates = ["first_level", "least_squares"]
b5_starts = ["free", "encoder"]
b5_horizons = [25, 100]

# %%
from fnnbook.results import RESULTS_FILENAME, read_results
from fnnlib.data.tanks import tanks_records

from fnnbook.tasks.why_tanks import WhyTanksSettings
settings = WhyTanksSettings.from_namespace(globals())  # checked as `fnn-pipeline check` checks them

# %% tags=["hide-input"]
import dataclasses
import time
from pathlib import Path

import numpy as np

from fnnlib.tanks import evaluation as TE
from fnnbook import why as W
from fnnbook.params import upstream_parameters
from fnnbook.rules import tanks as rules

# %% tags=["hide-input"]
out = Path(out_dir)
out.mkdir(parents=True, exist_ok=True)
up = Path(upstream_dirs["cascaded_tanks"])
result, ran = read_results(up / RESULTS_FILENAME), upstream_parameters(up)
rec = tanks_records(ran["data"], data_dir=data_dir, n_samples=ran["synthetic_samples"], seed=ran["seed"],
                      noise_std=ran["synthetic_noise"])  # the chapter's records, made as it made them
s_ran = TE.TanksSettings.of(ran)  # the chapter's settings, as it ran
trained = TE.load_trained(up / "tanks_models.pt", s_ran)
Ns = [int(N) for N in ran["horizons"]]
t_start = time.perf_counter()

# %% [markdown]
# ## The rules at each point
# Each point predicts every horizon from every sample of the validation record with the loaded ensemble (one
# batched cascade per point). The chapter's own point (every sample, the first measured level) must give the
# chapter's numbers, checked first.

# %% tags=["hide-input"]
grid = [(L, b) for L in L_grid for b in beta_grid]
keep = {"all": None, "outside_overflow": TE.outside_overflow(rec, s_ran)}
errs = {(w, f): TE.judged_again(rec, trained, s_ran, first=f, keep=keep[w], grid=grid if (w, f) == ("all", "first_level")
                                else ()) for w in windows for f in first_estimates}
own, stored = errs["all", "first_level"], result.metrics["n_step"]
for col in ("open_loop", "tuned", "hand"):
    if not np.allclose([own[col][N] for N in Ns], [stored[str(N)][col] for N in Ns], rtol=1e-6, atol=1e-9):
        raise ValueError(f"the loaded models' {col} errors are not those cascaded_tanks measured")
print(f"{len(errs)} window x first-estimate points and {len(grid)} gains in {time.perf_counter() - t_start:.0f} s")


# %% [markdown]
# B4 with the cascade at each fixed $(L, \beta)$ in place of the tuned gains (`rules.b4_at`); a point holds where
# the rule reads *reproduced* (`W.reproduced`).

# %% tags=["hide-input"]
E = len(trained["seeds"])
UNIT = "seed (one ensemble)"  # the chapter's seeds train side by side as one stacked ensemble: not independent
gain_res = [[rules.b4_at(own, Ns, f"L={L:g}, beta={b:g}") for b in beta_grid] for L in L_grid]
gain_grid = W.WhyGrid(
    axes=(W.Axis("L", L_grid, "the base gain L of the cascade for this plant is not given"),
          W.Axis("beta", beta_grid, "the decay rate beta of Eq. (11) for this plant is not given")),
    holds=W.reproduced(gain_res), n=E, title="B4: fixed gains L x beta",
    unit=UNIT,
    rule="the claim holds at a grid point when B4's rule holds there with the cascade at that fixed (L, beta) in "
         "place of the tuned gains: it wins over the open loop at every horizon N > 1, paired over the seeds",
    numbers={"checks_holding": [[int(sum(r.checks.values())) for r in row] for row in gain_res],
             "mean_ratio_longest_N": [[r.headline.value for r in row] for row in gain_res]})

# %% tags=["hide-input"]
axes = (W.Axis("window", windows, "which samples an N-step error is scored on (the overflow is a hard limit no "
               "smooth model has seen)", ours="all", kind="reading"),
        W.Axis("first_estimate", first_estimates, "the observer's first estimate of the unmeasured upper tank",
               ours="first_level", kind="usage"))
res = {c: [[f(errs[w, fe], Ns) for fe in first_estimates] for w in windows]
       for c, f in (("B4", rules.b4_at), ("B6", rules.b6_at))}
wf = {c: W.WhyGrid(axes=axes, holds=W.reproduced(res[c]), n=E,
                   title=f"{c}: window x first estimate", unit=UNIT,
                   rule=f"the claim holds at a grid point when {c}'s rule holds there (every horizon N > 1 wins, "
                        "paired over the seeds)",
                   numbers={"checks": [[r.checks for r in row] for row in res[c]],
                            "mean": [[r.numbers["mean"] for r in row] for row in res[c]]}) for c in res}
{c: g.holds.tolist() for c, g in wf.items()}

# %% [markdown]
# ## B5: the baseline's start and segment
# Each point trains the model without feedback for every seed with one start and one segment length (the
# chapter's Adam steps and rate, its seeds), and judges B5's rule against the chapter's observer-trained free runs.

# %% tags=["hide-input"]
t0 = time.perf_counter()
ours_free = result.metrics["free_run"]["observer_trained"]
b5_free = {}
for start in b5_starts:
    for H in b5_horizons:
        s_pt = dataclasses.replace(s_ran, baseline_starts=(start,), baseline_horizon=int(H))
        b5_free[start, H] = [TE.no_feedback(rec, seed, s_pt, TE.one_member(s_ran, seed), TE.LEVEL)["free_run"]
                             for seed in trained["seeds"]]
b5_res = [[rules.b5(observer_trained=ours_free, no_feedback=b5_free[a, H]) for H in b5_horizons] for a in b5_starts]
print(f"B5 baselines in {time.perf_counter() - t0:.0f} s: " + "; ".join(
    f"{a}, {H}: {np.mean(v):.3f} V" for (a, H), v in b5_free.items()) + f"; ours {np.mean(ours_free):.3f} V")

# %% tags=["hide-input"]
b5_grid = W.WhyGrid(
    axes=(W.Axis("start", b5_starts, "how the model trained without feedback gets a segment's initial state"),
          W.Axis("segment", [int(H) for H in b5_horizons], "the segment length of the training without feedback",
                 ours=int(ran["baseline_horizon"]))),
    holds=W.reproduced(b5_res), n=E, title="B5: baseline start x segment", unit=UNIT,
    rule="the claim holds at a grid point when B5's rule holds there: the observer-trained free-run RMSE wins "
         "over the baseline's, paired over the seeds",
    numbers={"no_feedback_free_run_V": [[b5_free[a, H] for H in b5_horizons] for a in b5_starts],
             "observer_trained_free_run_V": ours_free})

# %% [markdown]
# ## The whys
# Causes and summaries are computed by `fnnbook.why` from the grids above.

# %% tags=["nbval-check-output"]
ratio = np.array(gain_grid.numbers["mean_ratio_longest_N"])
i, j = np.unravel_index(ratio.argmin(), ratio.shape)
note = (f"N={max(Ns)} RMSE ratio feedback / open loop over the fixed gains: from {ratio.min():.3f} (L = {L_grid[i]:g}, "
        f"beta = {beta_grid[j]:g}) to {ratio.max():.3g}")
whys = [W.Why(claim="B4", verdict=result.claim("B4").verdict, grids=(gain_grid, wf["B4"]), note=note),
        W.Why(claim="B5", verdict=result.claim("B5").verdict, grids=(b5_grid,)),
        W.Why(claim="B6", verdict=result.claim("B6").verdict, grids=(wf["B6"],))]
W.write_whys(out, whys)
print(note)
for w in whys:
    print(f"{w.claim} ({w.verdict}): {w.summary}")
    for c in w.causes:
        print(f"  ({c.letter}) {c.name}: {c.evidence}")
print(f"total {time.perf_counter() - t_start:.0f} s")
