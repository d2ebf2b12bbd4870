# %% [markdown]
# # Why D1-D4 stand where they stand: the feedback-training grid and the authors' networks (Sec. 4)
#
# In the paper profile D2 (the frozen neural ODE with its neural feedback keeps the nominal accuracy, Fig. 5b)
# and D3 (the feedback's Eq. (12) training loss converges, Fig. 5c) are not reproduced, and D4 (the neural
# feedback beats the neural ODE at the 12 S8 levels, Fig. S10) is partly reproduced. Two kinds of runs say why:
#
# * **the feedback-training grid** (the `why_feedback_point` tasks): Alg. 1 retrained with one setting changed
#   at a time around the paper profile's recipe, the claims' own rules applied at each point;
# * **the authors' networks**: the release's nominal neural ODE, neural feedback and domain-randomized neural
#   ODE judged by the same rules on the same evaluation as ours (D1, D2, D4; the release keeps no loss curve of
#   the evaluated feedback, so D3 has no authors' check).
#
# The causes (a)-(d) and the one-line summaries are computed by `fnnbook.why` from these runs.

# %% tags=["parameters"]
# None: the paper value from the presets (fnnbook.settings.NOTEBOOK_PRESETS), filled in by the runner
profile = "why"
out_dir = "outputs/manual/why_feedback"
upstream_dirs = {"spiral": "outputs/paper/spiral", "neural_feedback": "outputs/paper/neural_feedback"}
data_dir = None
x0 = None
nominal = None
n_samples = None
Ts = None
N = None
dr_omega_range = [0.8, 0.12, 3.08]
dr_eta_range = [0.04, 0.005, 0.135]
dr_eps_range = [-24.0, 2.4, 21.6]
residual_base = None
domega_range = None
deta_range = None
deps_range = None
fb_iterations = 2000
fb_lr = 0.01
fb_optimizer = "rmsprop"
refresh_every = 10
d1_factor = 1.5
d2_factor = 1.5
d3_ratio = 0.5
d3_flat = 0.1
heldout_flip = [1.0, -1.0, 1.0]
heldout_min_distance = 3.0
authors_ode = "Neural_ODE_ite400_loss0.2.pt"
authors_dr_ode = "Neural_ODE_domran.pt"
authors_feedback = "FeedbackNN_ite477_loss0.494530_conver.pt"

# %%
from fnnbook.settings import check_notebook_settings  # the checks `fnn-pipeline check` runs first
check_notebook_settings("why_feedback", globals())

# %% tags=["hide-input"]
import json
import time
from pathlib import Path

import numpy as np

import fnnlib as F
from fnnbook import why as W
from fnnbook.feedback_eval import evaluation_setup, feedback_ensemble, judge
from fnnbook.rules import sec4
from fnnlib.data import release

# %%
task_start = time.perf_counter()
out = Path(out_dir)
(out / "figures").mkdir(parents=True, exist_ok=True)
nf_dir = Path(upstream_dirs["neural_feedback"])
paper = F.read_results(nf_dir / "results.json")
point_dirs = sorted(Path(d) for k, d in upstream_dirs.items() if k.startswith("why_feedback_point"))
if not point_dirs:
    raise ValueError("no why_feedback_point folder among the upstream folders")
points = [json.loads((d / "point.json").read_text()) for d in point_dirs]
print(f"{len(points)} grid points: {[p['change'] for p in points]}")

# %% [markdown]
# ## The profile point: our paper-profile networks on the shared evaluation
# The paper profile's frozen neural ODEs, neural feedbacks and domain-randomized neural ODEs, judged again
# through `fnnbook.feedback_eval` (the evaluation every grid point and the authors' networks get). It must give
# the paper profile's checks of D1, D2 and D4 (checked below); D3 reads the paper profile's loss numbers.

# %%
def ensemble(stem, kind, build):
    folder = Path(upstream_dirs["spiral"]) if stem == "neural_ode" else nf_dir
    loaded = F.load_seed_checkpoints(folder, stem=stem, expected_kind=kind)
    return build([m for _, m, _ in loaded], [s for s, _, _ in loaded]), [s for s, _, _ in loaded]


f_ours, seeds = ensemble("neural_ode", "NeuralODE", F.NeuralODEEnsemble.from_members)
h_ours, _ = ensemble("neural_feedback", "NeuralFeedback", feedback_ensemble)
dr_ours, _ = ensemble("neural_ode_dr", "NeuralODE", F.NeuralODEEnsemble.from_members)

# %% [markdown]
# They are judged by D1, D2 and D4's rules on the evaluation built from this notebook's parameters; D3 takes the
# paper profile's loss numbers; every check must be the paper profile's own.

# %%
setup = evaluation_setup(globals())
ours, ours_numbers = judge(f_ours, h_ours, setup, len(seeds), loss=None, factor=d2_factor, ratio_max=d3_ratio,
                           flat=d3_flat, f_dr=dr_ours, d1_factor=d1_factor)
d3n = paper.claim("D3").numbers
ours["D3"] = sec4.d3(ratio=d3n["ratio"], trend=d3n["last_window_trend_relative"], ratio_max=d3_ratio, flat=d3_flat)
ours_numbers |= {"ratio": np.asarray(d3n["ratio"]), "last_window_trend_relative": np.asarray(d3n["last_window_trend_relative"])}
same = {cid: ours[cid].checks == paper.claim(cid).checks for cid in ("D1", "D2", "D3", "D4")}
if not all(same.values()):
    raise RuntimeError(f"the shared evaluation does not give the paper profile's checks: {same}")
print({cid: c.verdict for cid, c in ours.items()}, "= the paper profile's verdicts")

# %% [markdown]
# ## The grid: one setting changed at a time
# Each axis is named for what the paper leaves open or states (`paper`: the stated value, `None` when the
# paper is silent or says two things). The profile point (the paper profile's own run, 5 seeds) lies on every
# axis. At each point a claim *holds* when its rule's verdict there is "reproduced" (D4: the counted, strict
# reading); the numbers per seed are kept beside it.

# %%
AXES = {  # change key -> (parameter, the profile's value, what the paper says, the silence it probes)
    "optimizer": ("fb_optimizer", lambda r: r["optimizer"], None,
                  "the feedback's optimizer: Alg. 1 names Adam, App. A.3.3 (and the release) RMSprop"),
    "lr_times": ("fb_lr", lambda r: r["lr"], 0.01, "the feedback's learning rate (App. A.3.3 states 0.01)"),
    "iterations_times": ("fb_iterations", lambda r: r["iterations"], 2000,
                         "whether longer training helps (App. A.3.3 states 2000 iterations)"),
    "refresh_every": ("refresh_every", lambda r: r["refresh_every"], 1,
                      "the rollout refresh (Alg. 1 reruns the feedback at every iteration; ours every 10)"),
}
TITLES = {"optimizer": "optimizer", "lr_times": "learning rate", "iterations_times": "iterations",
          "refresh_every": "rollout refresh"}  # each grid's name in the summary line

# %% [markdown]
# The profile's recipe is the neural_feedback task's (its checkpoints record the iterations and the refresh);
# each grid point must change exactly one setting of it.

# %%
profile_recipe = {"optimizer": fb_optimizer, "lr": fb_lr, "iterations": fb_iterations, "refresh_every": refresh_every}
meta = F.load_seed_checkpoints(nf_dir, stem="neural_feedback", expected_kind="NeuralFeedback")[0][2]
if (meta["iterations"], meta["refresh_every"]) != (fb_iterations, refresh_every):
    raise ValueError(f"the neural_feedback task ran {meta['iterations']} iterations, refresh every "
                     f"{meta['refresh_every']}; this notebook was given {fb_iterations}, {refresh_every}")
for p in points:  # every point changes one setting of the profile's recipe, and only that one
    if len(p["change"]) != 1 or sum(p["recipe"][k] != v for k, v in profile_recipe.items()) != 1:
        raise ValueError(f"a grid point must change exactly one setting of {profile_recipe}: {p['recipe']}")

# %% [markdown]
# What each point measured, per claim: its rule's verdict and the per-seed numbers the figures show (D4: the S8
# levels won per seed).

# %%
def levels_won(s8):
    """Per seed: the S8 levels where the feedback is lower in both metrics (the per-seed count of Fig. S10)."""
    s8 = {k: np.asarray(v) for k, v in s8.items()}
    return ((s8["rate_neural_feedback"] < s8["rate_neural_ode"])
            & (s8["err_N_neural_feedback"] < s8["err_N_neural_ode"])).sum(-1)


def measured(results, numbers):
    """Per claim: the rule's verdict, and the per-seed numbers the figures show."""
    return {"verdict": {k: results[k]["verdict"] if isinstance(results[k], dict) else results[k].verdict
                        for k in ("D2", "D3", "D4")},
            "D2": np.asarray(numbers["rel_rmse_neural_feedback"]) / np.asarray(numbers["rel_rmse_nominal_neural_ode"]),
            "D3_ratio": np.asarray(numbers["ratio"]), "D3_trend": np.asarray(numbers["last_window_trend_relative"]),
            "D4": levels_won(numbers["s8"])}


profile_m = measured(ours, ours_numbers)
point_m = [measured(p["claims"], p["numbers"]) for p in points]

# %% [markdown]
# The claims' rules, as each grid states them: D2 and D3 over the seeds, D4 in its strict reading.

# %%
RULES = {"D2": f"the frozen neural ODE with the feedback is within {d2_factor:g}x the nominal model's relative RMSE "
               "in >= S-1 of S seeds (sec4.d2)",
         "D3": f"the last 10 % of the loss < {d3_ratio:g}x the first 10 % and flat (< {d3_flat:.0%} change) in >= S-1 "
               "of S seeds (sec4.d3)",
         "D4": "the feedback beats the neural ODE in rate RMSE and N-step error at every S8 level and every held-out "
               "level (sec4.d4, strict reading)"}

# %% [markdown]
# One grid per claim and changed setting: the profile point and the points that change that setting, sorted by
# the setting's value; n is the fewest seeds at a point.

# %%
def axis_grid(key, cid):
    """The 1-D grid of claim ``cid`` along one changed setting (the profile point included)."""
    name, value_of, stated, silence = AXES[key]
    at = {value_of(profile_recipe): profile_m} | {value_of(p["recipe"]): m for p, m in zip(points, point_m)
                                                  if key in p["change"]}
    values = sorted(at, key=lambda v: (isinstance(v, str), v))
    holds = np.array([at[v]["verdict"][cid] == "reproduced" for v in values])
    keys = ("D3_ratio", "D3_trend") if cid == "D3" else (cid,)
    nums = {k: [at[v][k].tolist() for v in values] for k in keys}
    n = min(len(at[v][keys[0]]) for v in values)
    axis = W.Axis(name, tuple(values), silence, paper=stated, ours=value_of(profile_recipe))
    return W.WhyGrid((axis,), holds, n, RULES[cid], numbers=nums, title=TITLES[key], unit="seed")


# %% [markdown]
# The grids of D2, D3 and D4 along every setting some point changes, and their one-line summaries.

# %%
changed = [k for k in AXES if any(k in p["change"] for p in points)]
grids = {cid: [axis_grid(k, cid) for k in changed] for cid in ("D2", "D3", "D4")}
for cid, gs in grids.items():
    print(cid, W.summary(gs))

# %% [markdown]
# ## The authors' networks on the same evaluation
# The release's nominal neural ODE `authors_ode`, the neural feedback trained against it `authors_feedback`
# (the release pairs them) and its domain-randomized neural ODE `authors_dr_ode`, read by the tested loaders
# of `fnnlib.data.release` (a refusing unpickler, pinned SHA-256). They were trained on the release's spiral,
# the transpose of Eq. (26) (`release.release_spiral`: $\omega$ negated), so they are judged on that spiral's
# nominal task, S8 and held-out levels (same parameters, metrics and rules as ours). One network of each kind:
# n = 1, so "in >= S-1 of S seeds" reads "in the run" and a win is "lower".

# %%
def authors_networks():
    """The authors' f, h and domain-randomized f, or None (with a printed line) without their release."""
    if not release.release_present(data_dir, "spiral_curve/"):  # every file there, its SHA-256 the published one
        print(f"the authors' networks are not checked (judging ours only): the release's spiral networks are not "
              f"all in data_dir = {data_dir!r} with their published SHA-256")
        return None
    return (release.load_release_spiral_ode(data_dir, authors_ode),
            release.load_release_spiral_feedback(data_dir, authors_feedback),
            release.load_release_spiral_ode(data_dir, authors_dr_ode))


def authors_checks(f, h, f_dr):
    """D1, D2, D4 with the authors' networks on the release's spiral, beside ours; and their numbers."""
    theirs, numbers = judge(f, h, evaluation_setup(globals(), release.release_spiral), 1, loss=None,
                            factor=d2_factor, ratio_max=d3_ratio, flat=d3_flat, f_dr=f_dr, d1_factor=d1_factor)
    return {cid: W.AuthorsCheck(verdict=theirs[cid].verdict, ours=ours[cid].verdict, checks=theirs[cid].checks,
                                networks=NETS[cid], n=1) for cid in NETS}, numbers


# %% [markdown]
# Each check names the networks it judged; without the release no authors' check is made.

# %%
NETS = {"D1": f"{authors_dr_ode} vs {authors_ode}", "D2": f"{authors_ode} + {authors_feedback}",
        "D4": f"{authors_ode} + {authors_feedback}"}
authors = None if (nets := authors_networks()) is None else authors_checks(*nets)
if authors is not None:
    for cid, a in authors[0].items():
        print(f"{cid}: authors' networks {a.verdict:15s} ours {a.ours:15s} {dict(a.checks)}")
    print({k: np.round(np.asarray(v), 4).tolist() for k, v in authors[1].items() if k.startswith("rel_rmse")})

# %% [markdown]
# ## One figure per why
# Per claim, the number its rule reads, per seed, at every grid point; a filled marker where the rule holds
# at the point, an open one where it fails; the rule's per-seed threshold dashed (D3: the ratio check only);
# the authors' networks as a star.

# %%
def plot_points(ax, cid, key):
    """Claim ``cid``'s number ``key`` per seed at each point of its grids, one column a point; the labels."""
    labels = []
    for g in grids[cid]:
        axis = g.axes[0]
        for i, v in enumerate(axis.values):
            vals = np.asarray(g.numbers[key][i], dtype=float)
            color = F.plotting.COLORS["feedback"]
            ax.plot(np.full(vals.size, len(labels)), vals, "o", color=color, mfc=color if g.holds[i] else "none")
            labels.append(f"{axis.name} = {v}" + (" (profile)" if v == axis.ours else ""))
    return labels


# %% [markdown]
# A claim's figure: its points, the authors' star and the rule's threshold.

# %%
def why_figure(cid, key, threshold, ylabel, theirs=None, log=False):
    fig, ax = F.new_figure()
    labels = plot_points(ax, cid, key)
    if theirs is not None:
        ax.plot([len(labels)], [theirs], "*", ms=12, color=F.plotting.COLORS["neural_ode"])
        labels.append("authors' networks (n = 1)")
    ax.axhline(threshold, ls="--", color="k", lw=0.8)
    ax.set_xticks(range(len(labels)), labels, rotation=35, ha="right", fontsize=7)
    ax.set(ylabel=ylabel, title=f"{cid} (filled: its rule holds)", yscale="log" if log else "linear")
    return F.save_figure(fig, out, f"why_{cid.lower()}")


# %%
a_num = None if authors is None else authors[1]
figs = {
    "D2": why_figure("D2", "D2", d2_factor, "rel. RMSE: feedback / alone",
                     None if a_num is None else float(a_num["rel_rmse_neural_feedback"][0]
                                                      / a_num["rel_rmse_nominal_neural_ode"][0]), log=True),
    "D3": why_figure("D3", "D3_ratio", d3_ratio, "loss: last / first 10 %"),
    "D4": why_figure("D4", "D4", len(setup.offsets) - 0.5, f"S8 levels won of {len(setup.offsets)}",
                     None if a_num is None else float(levels_won(a_num["s8"])[0])),
}

# %% [markdown]
# ## The whys
# Each claim's verdict and readings in the paper profile, its grids and the authors' check; the causes and the
# summary line follow from them (`fnnbook.why`).

# %%
NOTES = {
    "D1": "Only the authors' networks: D1 does not depend on the feedback training the grid varies.",
    "D2": "The feedback adds error on the nominal task it was not trained for; the grid says whether a training "
          "setting removes that, the authors' networks whether their training does.",
    "D3": "D3 reads the loss curve of Alg. 1; the release keeps no loss curve of the feedback evaluated here.",
    "D4": "D4's strict reading counts the zero-residual S8 level; its as-worded reading leaves it out.",
}

# %% [markdown]
# The whys, written to `whys.json`, with the causes `fnnbook.why` finds. D1 has no grid: without the release it
# has no run behind a why, and is left out (the book's row says so).

# %%
whys = []
for cid in ("D1", "D2", "D3", "D4"):
    if cid not in grids and authors is None:
        print(f"{cid}: no why written (no grid varies what it depends on, and the authors' networks are not checked)")
        continue
    c = paper.claim(cid)
    whys.append(W.Why(cid, c.verdict, grids=tuple(grids.get(cid, ())),
                      authors=None if authors is None else authors[0].get(cid),
                      readings=c.reading_verdicts(), figure=figs.get(cid), note=NOTES[cid]))
W.write_whys(out, whys)

# %% tags=["nbval-check-output"]
for w in whys:
    print(f"{w.claim} ({w.verdict}): causes {[c.letter for c in w.causes]}; Why: {w.summary}")

# %%
print(f"task time (after kernel start): {time.perf_counter() - task_start:.1f} s")
