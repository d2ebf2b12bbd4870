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
#   ODE judged by the same rules on the same evaluation as ours (D1, D2, D4), and the release's own loss curves
#   of its feedback trainings (D3);
# * **the readings and usages the paper leaves open**, as axes of the grids, for our networks and the authors':
#   D2's window (the whole record, or after the estimate has settled, the settling time read from the data by
#   `fnnbook.rules.sec4.settling_index`); D3's readings (the loss falls and ends flat; falls; reaches the
#   release's own stopping level in the release's loss form); D4's metric (the change rate Fig. S10 shows, the
#   N-step error, both), the cascade's decay and its first estimate (the learned feedback as it is, or centred
#   so that h(0) = 0).
#
# The causes (a)-(d) and the one-line summaries are computed by `fnnbook.why` from these runs: (d) "the claim
# does not hold where tested" stands only where every reading and usage tried fails, with ours and the authors'
# networks.

# %% tags=["parameters"]
profile = "why"
out_dir = "outputs/manual/why_feedback"
upstream_dirs = {"spiral": "outputs/paper/spiral", "neural_feedback": "outputs/paper/neural_feedback"}
data_dir = None
# the settings and their paper values, from fnnbook.tasks.why_feedback (written by `make notebooks`)
n_samples = 1000
Ts = 0.01
x0 = [9.0, 0.0]
dr_omega_range = [0.8, 0.12, 3.08]
dr_eta_range = [0.04, 0.005, 0.135]
dr_eps_range = [-24.0, 2.4, 21.6]
dr_n_samples = 1000
dr_Ts = 0.02
residual_base = [2.0, 0.1, 0.0]
domega_range = [-0.72, 0.12, 0.6]
deta_range = [-0.03, 0.005, 0.025]
deps_range = [-14.4, 2.4, 12.0]
fb_iterations = 2000
fb_lr = 0.01
fb_optimizer = "rmsprop"
refresh_every = 10
d2_factor = 1.5
d3_ratio = 0.5
d3_flat = 0.1
heldout_flip = [1.0, -1.0, 1.0]
heldout_min_distance = 3.0
d1_factor = 1.5
nominal = [2.0, 0.1, 0.0]
N = 50
d4_beta = [0.0, 0.02, 0.1]
authors_ode = "Neural_ODE_ite400_loss0.2.pt"
authors_dr_ode = "Neural_ODE_domran.pt"
authors_feedback = "FeedbackNN_ite477_loss0.494530_conver.pt"

# %%
from fnnbook.tasks.why_feedback import WhyFeedbackSettings
settings = WhyFeedbackSettings.from_namespace(globals())  # checked as `fnn-pipeline check` checks them

# %% tags=["hide-input"]
import json
import time
from pathlib import Path

import numpy as np

import torch

import fnnlib as F
from fnnbook.results import read_results
from fnnlib.models import NeuralFeedbackEnsemble
from fnnlib.paper import colon_range, paired_levels, simulate_levels
from fnnlib.plotting import new_figure, save_figure
from fnnlib.systems import Spiral
from fnnlib.training import load_seed_checkpoints, load_seed_ensemble
from fnnbook import why as W
from fnnbook.feedback_eval import judge
from fnnlib.paper.feedback_eval import EvaluationSettings, evaluation_setup, rate_error_curves, release_form_loss
from fnnbook.rules import sec4
from fnnbook.rules import why_feedback as WF
from fnnlib import release

# %%
task_start = time.perf_counter()
out = Path(out_dir)
(out / "figures").mkdir(parents=True, exist_ok=True)
nf_dir = Path(upstream_dirs["neural_feedback"])
paper = read_results(nf_dir / "results.json")
point_dirs = sorted(Path(d) for k, d in upstream_dirs.items() if k.startswith("why_feedback_point"))
if not point_dirs:
    raise ValueError("no why_feedback_point folder among the upstream folders")
points = [json.loads((d / "point.json").read_text()) for d in point_dirs]
print(f"{len(points)} grid points: {[p['change'] for p in points]}")

# %% [markdown]
# ## The profile point: our paper-profile networks on the shared evaluation
# The paper profile's frozen neural ODEs, neural feedbacks and domain-randomized neural ODEs, judged again
# through `fnnlib.paper.feedback_eval` (the evaluation every grid point and the authors' networks get). It must give
# the paper profile's checks of D1, D2 and D4 (checked below); D3 reads the paper profile's loss numbers.

# %%
f_ours = load_seed_ensemble(upstream_dirs["spiral"])
seeds = f_ours.seeds
h_loaded = load_seed_checkpoints(nf_dir, stem="neural_feedback", expected_kind="NeuralFeedback")
h_ours = NeuralFeedbackEnsemble.from_members([m for _, m, _ in h_loaded], [s for s, _, _ in h_loaded])
dr_ours = load_seed_ensemble(nf_dir, "neural_ode_dr")

# %% [markdown]
# They are judged by D1, D2 and D4's rules on the evaluation built from this notebook's parameters; D3 takes the
# paper profile's loss numbers; every check must be the paper profile's own.

# %%
th = WF.Thresholds(d2_factor=d2_factor, d3_ratio=d3_ratio, d3_flat=d3_flat, d1_factor=d1_factor)
setup = evaluation_setup(EvaluationSettings.of(settings.as_dict()))
ours, ours_numbers = judge(f_ours, h_ours, setup, len(seeds), loss=None, factor=d2_factor, ratio_max=d3_ratio,
                           flat=d3_flat, f_dr=dr_ours, d1_factor=d1_factor)
d3n = paper.claim("D3").numbers
ours["D3"] = sec4.d3(ratio=d3n["ratio"], trend=d3n["last_window_trend_relative"], ratio_max=d3_ratio, flat=d3_flat)
ours_numbers |= {"ratio": np.asarray(d3n["ratio"]), "last_window_trend_relative": np.asarray(d3n["last_window_trend_relative"])}

# %% [markdown]
# D3's release-form reading needs our feedback's loss in the release's form, on the randomized training cases.

# %%
cases = paired_levels(colon_range(*dr_omega_range), colon_range(*dr_eta_range), colon_range(*dr_eps_range))
t_dr = torch.arange(dr_n_samples, dtype=torch.float64) * dr_Ts
X_dr = simulate_levels([Spiral(*row) for row in cases.tolist()], torch.tensor(x0, dtype=torch.float64), t_dr,
                         exact=True).float()
ours_numbers["release_form_final"] = release_form_loss(f_ours, h_ours, X_dr, dr_Ts, len(seeds))
same = {cid: ours[cid].checks == paper.claim(cid).checks for cid in ("D1", "D2", "D3", "D4")}
if not all(same.values()):
    raise RuntimeError(f"the shared evaluation does not give the paper profile's checks: {same}")
print({cid: c.verdict for cid, c in ours.items()}, "= the paper profile's verdicts")

# %% [markdown]
# ## The grid: one setting changed at a time
# Each axis is named for what the paper leaves open or states (`WF.AXES`; `paper`: the stated value, `None` when
# the paper is silent or says two things). The profile point (the paper profile's own run, 5 seeds) lies on every
# axis. At each point a claim *holds* when its rule's verdict there is "reproduced" (D4: the counted, strict
# reading); the numbers per seed are kept beside it. The profile's recipe is the neural_feedback task's (its
# checkpoints record the iterations and the refresh); each grid point must change exactly one setting of it.

# %%
profile_recipe = {"optimizer": fb_optimizer, "lr": fb_lr, "iterations": fb_iterations, "refresh_every": refresh_every}
meta = h_loaded[0][2]
if (meta["iterations"], meta["refresh_every"]) != (fb_iterations, refresh_every):
    raise ValueError(f"the neural_feedback task ran {meta['iterations']} iterations, refresh every "
                     f"{meta['refresh_every']}; this notebook was given {fb_iterations}, {refresh_every}")
for p in points:  # every point changes one setting of the profile's recipe, and only that one
    if len(p["change"]) != 1 or sum(p["recipe"][k] != v for k, v in profile_recipe.items()) != 1:
        raise ValueError(f"a grid point must change exactly one setting of {profile_recipe}: {p['recipe']}")

# %% [markdown]
# What each point measured, per claim (`WF.measured`): its counted verdict (D4: as worded), D2 over the whole record
# and after the estimate has settled, D3 in each reading, and the per-seed numbers the figures show (D4: the S8
# levels won per seed). Then one grid per claim and changed setting (`WF.setting_grid`): the profile point and the
# points that change that setting, sorted by the setting's value (D2 crossed with the window, D3 with its
# readings); n is the fewest seeds at a point. The unit: the S seeds are S initialisations of one ensemble,
# trained side by side on shared mini-batches of the same randomized cases and judged on one nominal trajectory:
# they share the data and the batches, not the weights. Their spread is that of the initialisation alone.

# %%
profile_m = WF.measured(ours, ours_numbers, th)
point_m = [WF.measured(p["claims"], p["numbers"], th) for p in points]
changed = [k for k in WF.AXES if any(k in p["change"] for p in points)]
grids = {cid: [WF.setting_grid(k, cid, profile_recipe=profile_recipe, profile=profile_m, points=points,
                               point_measured=point_m, th=th) for k in changed] for cid in ("D2", "D3", "D4")}
for cid, gs in grids.items():
    print(cid, W.summary(gs))

# %% [markdown]
# ## The authors' networks on the same evaluation
# The release's nominal neural ODE `authors_ode`, the neural feedback trained against it `authors_feedback`
# (the release pairs them) and its domain-randomized neural ODE `authors_dr_ode`, read by the tested loaders
# of `fnnlib.release` (a refusing unpickler, pinned SHA-256). They were trained on the release's spiral,
# the transpose of Eq. (26) (`release.release_spiral`: $\omega$ negated), so they are judged on that spiral's
# nominal task, S8 and held-out levels (same parameters, metrics and rules as ours). One network of each kind:
# n = 1, so "in >= S-1 of S seeds" reads "in the run" and a win is "lower". Each check names the networks it
# judged; without the release no authors' check is made.

# %%
nets = release.load_release_spiral_networks(data_dir, authors_ode, authors_feedback, authors_dr_ode)
NETS = {"D1": f"{authors_dr_ode} vs {authors_ode}", "D2": f"{authors_ode} + {authors_feedback}",
        "D4": f"{authors_ode} + {authors_feedback}"}
authors, setup_theirs = None, evaluation_setup(EvaluationSettings.of(settings.as_dict()), release.release_spiral)
if nets is None:
    print(f"the authors' networks are not checked (judging ours only): the release's spiral networks are not "
          f"all in data_dir = {data_dir!r} with their published SHA-256")
else:
    authors = WF.authors_checks(*nets, setup_theirs, ours, NETS, th)
    for cid, a in authors[0].items():
        print(f"{cid}: authors' networks {a.verdict:15s} ours {a.ours:15s} {dict(a.checks)}")
    print({k: np.round(np.asarray(v), 4).tolist() for k, v in authors[1].items() if k.startswith("rel_rmse")})

# %% [markdown]
# ## The readings and usages, for our networks and the authors'
# D2's window for the authors' network (one network, n = 1), beside ours in the grids above.

# %%
authors_grids = {"D2": [], "D3": [], "D4": []}
if authors is not None:
    authors_grids["D2"].append(WF.window_grid(authors[1], th, units=1, unit="network", networks="authors",
                                              title="authors' networks: window"))
    print(W.summary(authors_grids["D2"]))

# %% [markdown]
# D3 on the release's own loss curves: one curve per feedback training of the release (`release.SPIRAL_LOSS_NAMES`,
# each the run that saved a `FeedbackNN_ite<K>` network; `load_present_feedback_losses`), in the release's loss
# form (the mean absolute change-rate error over the cases), each cut where it fell below the release's stopping
# level 0.5. Every reading of D3 is applied to them (n = the curves, trained separately).

# %%
curves = release.load_present_feedback_losses(data_dir)
missing = [n for n in release.SPIRAL_LOSS_NAMES if n not in curves]
if missing:
    print(f"{len(missing)} of the release's {len(release.SPIRAL_LOSS_NAMES)} loss curves are not in "
          f"data_dir = {data_dir!r}: {missing}")
if curves:
    authors_grids["D3"].append(WF.curves_grid(curves, th))
    print(W.summary(authors_grids["D3"]))
    print({n: (len(c), round(float(c[-1]), 4)) for n, c in curves.items()})

# %% [markdown]
# D4 over its metric and the cascade's usage, for our paper-profile networks and the authors' (`WF.usage_grid`):
# the metric (`rate`: the change rate Fig. S10 and the release's test compare; `err_N`: the N-step error of the
# cascade; `both`: the paper profile's rule), the cascade's decay `d4_beta` (Sec. 4 states none; 0 is the paper
# profile's, 0.02 the spiral's of Sec. 3.3, 0.1 the quadrotor's) and its first estimate (each layer starts at its
# input; the learned feedback as it is, or centred so that h(0) = 0 there).

# %%
usage = {"ours": WF.usage_grid(f_ours, h_ours, len(seeds), setup, th, betas=d4_beta, unit=WF.UNIT, networks="ours",
                               title="metric x usage")}
if nets is not None:
    usage["authors"] = WF.usage_grid(nets[0], nets[1], 1, setup_theirs, th, betas=d4_beta, unit="network",
                                     networks="authors", title="authors' networks: metric x usage")
    authors_grids["D4"].append(usage["authors"])
for k, g in usage.items():
    print(k, W.summary([g]))

# %% [markdown]
# ## Where the error lives: the per-time change-rate error on the nominal task
# ours (mean over seeds) and the authors', with and without the feedback; the settling time of each feedback
# (`sec4.settling_index`) dashed.

# %%
runs = {"ours": rate_error_curves(f_ours, h_ours, setup, len(seeds))}
if nets is not None:
    runs["authors'"] = rate_error_curves(nets[0], nets[1], setup_theirs, 1)
settle = {who: sec4.settling_index(c["neural_feedback"]) * setup.Ts for who, c in runs.items()}
print({who: np.round(ts, 2).tolist() for who, ts in settle.items()}, "settling times (s)")

# %%
fig, ax = new_figure()
t_nom = np.arange(setup.x_nom.shape[0]) * setup.Ts
for (who, c), ls in zip(runs.items(), ("-", ":")):
    ax.plot(t_nom, c["neural_ode"].mean(0), ls, color=F.plotting.COLORS["neural_ode"], label=f"{who}: neural ODE")
    ax.plot(t_nom, c["neural_feedback"].mean(0), ls, color=F.plotting.COLORS["feedback"], label=f"{who}: + feedback")
    ax.axvline(float(np.median(settle[who])), ls="--", color="k", lw=0.6)
ax.set(xlabel="t (s)", ylabel="||f_hat - f|| / RMS ||f||", yscale="log", title="D2: per-time change-rate error")
ax.legend(fontsize=7)
curve_fig = save_figure(fig, out, "why_d2_per_time")

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
            ok = g.holds[i] if g.holds.ndim == 1 else g.holds[i, 0]  # 2-D: the paper profile's reading
            ax.plot(np.full(vals.size, len(labels)), vals, "o", color=color, mfc=color if ok else "none")
            labels.append(f"{axis.name} = {v}" + (" (profile)" if v == axis.ours else ""))
    return labels


# %%
def plot_why(cid, key, threshold, ylabel, theirs=None, log=False):
    """A claim's figure: its points, the authors' star and the rule's threshold."""
    fig, ax = new_figure()
    labels = plot_points(ax, cid, key)
    if theirs is not None:
        ax.plot([len(labels)], [theirs], "*", ms=12, color=F.plotting.COLORS["neural_ode"])
        labels.append("authors' networks (n = 1)")
    ax.axhline(threshold, ls="--", color="k", lw=0.8)
    ax.set_xticks(range(len(labels)), labels, rotation=35, ha="right", fontsize=7)
    ax.set(ylabel=ylabel, title=f"{cid} (filled: its rule holds)", yscale="log" if log else "linear")
    return save_figure(fig, out, f"why_{cid.lower()}")


# %%
a_num = None if authors is None else authors[1]
figs = {
    "D2": plot_why("D2", "D2", d2_factor, "rel. RMSE: feedback / alone",
                   None if a_num is None else float(a_num["rel_rmse_neural_feedback"][0]
                                                    / a_num["rel_rmse_nominal_neural_ode"][0]), log=True),
    "D3": plot_why("D3", "D3_ratio", d3_ratio, "loss: last / first 10 %"),
    "D4": plot_why("D4", "D4", len(setup.offsets) - 0.5, f"S8 levels won of {len(setup.offsets)}",
                   None if a_num is None else float(WF.levels_won(a_num["s8"])[0])),
}

# %% [markdown]
# ## The whys
# Each claim's verdict and readings in the paper profile, its grids and the authors' check; the causes and the
# summary line follow from them (`fnnbook.why`).

# %%
steps = torch.tensor([r[1] for r in (dr_omega_range, dr_eta_range, dr_eps_range)], dtype=torch.float64)
near = float(torch.cdist(torch.tensor([nominal], dtype=torch.float64) / steps, cases / steps).min())
by_opt = {v: float(np.median(g.numbers["D2"][i])) for g in grids["D2"] if g.axes[0].name == "fb_optimizer"
          for i, v in enumerate(g.axes[0].values)}
NOTES = {
    "D1": "Only the authors' networks: D1 does not depend on the feedback training the grid varies.",
    "D2": f"The nominal spiral lies {near:.1f} training steps from the nearest randomized case (almost one of "
          "them); the per-time error curve shows where the feedback's error lives (the start-up transient, before "
          "the settling time). Median per-seed ratio feedback / alone by optimizer: "
          + ", ".join(f"{k}: {v:.2f}" for k, v in by_opt.items()) + ".",
    "D3": "The release keeps the loss curves of its feedback trainings (spiral_curve/trained_model/iteration_*.txt); "
          "they are cut where the loss fell below 0.5, so a flat end cannot be asked of them.",
    "D4": "Counted: the as-worded reading (the levels with a residual). The paper profile's usage (no decay, the "
          "learned h as it is, both metrics) is one point of the metric x usage grid.",
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
    extra = ([usage["ours"]] if cid == "D4" else []) + authors_grids.get(cid, [])
    whys.append(W.Why(cid, WF.counted(c, cid), grids=tuple(grids.get(cid, ())) + tuple(extra),
                      authors=None if authors is None else authors[0].get(cid),
                      readings=c.reading_verdicts(), figure=curve_fig if cid == "D2" else figs.get(cid),
                      note=NOTES[cid]))
W.write_whys(out, whys)

# %% tags=["nbval-check-output"]
for w in whys:
    print(f"{w.claim} ({w.verdict}): causes {[c.letter for c in w.causes]}; Why: {w.summary}")

# %%
print(f"task time (after kernel start): {time.perf_counter() - task_start:.1f} s")
