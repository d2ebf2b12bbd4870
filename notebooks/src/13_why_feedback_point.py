# %% [markdown]
# # Why D2-D4: one point of the feedback-training grid (Alg. 1, Eq. (12))
#
# One point of the grid over the feedback-training settings: the paper profile's recipe (App. A.3.3: RMSprop,
# lr 0.01, batch 100, 2000 iterations; the rollout of Alg. 1 refreshed every 10 iterations) with **one**
# change (`change`): the optimizer (`optimizer`: Alg. 1 says Adam, App. A.3.3 RMSprop), the learning rate
# (`lr_times`, a factor on `fb_lr`), the iterations (`iterations_times`, a factor on `fb_iterations`) or the
# rollout refresh (`refresh_every`; Alg. 1 reruns the feedback over the cases at every iteration). The frozen
# neural ODEs are the `spiral` task's (seeds `0 .. n_seeds-1`, as in the `neural_feedback` task); the neural
# feedbacks are retrained from the same initialisations and mini-batch seeds, then judged by the rules of D2,
# D3 and D4 (`fnnbook.rules.sec4`) on the `neural_feedback` task's evaluation (`fnnlib.paper.feedback_eval`, judged by `fnnbook.feedback_eval`).
# D1 does not depend on the feedback and is not judged here.

# %% tags=["parameters"]
profile = "why"
out_dir = "outputs/manual/why_feedback_point"
upstream_dirs = {"spiral": "outputs/paper/spiral"}
# the settings and their paper values, from fnnbook.tasks.why_feedback_point (written by `make notebooks`)
n_samples = 1000
Ts = 0.01
x0 = [9.0, 0.0]
dr_omega_range = [0.8, 0.12, 3.08]
dr_eta_range = [0.04, 0.005, 0.135]
dr_eps_range = [-24.0, 2.4, 21.6]
dr_n_samples = 1000
dr_Ts = 0.02
fb_hidden = [50, 50]
fb_activation = "relu"
fb_batch_size = 100
fb_iterations = 2000
fb_lr = 0.01
fb_optimizer = "rmsprop"
refresh_every = 10
residual_base = [2.0, 0.1, 0.0]
domega_range = [-0.72, 0.12, 0.6]
deta_range = [-0.03, 0.005, 0.025]
deps_range = [-14.4, 2.4, 12.0]
d2_factor = 1.5
d3_ratio = 0.5
d3_flat = 0.1
heldout_flip = [1.0, -1.0, 1.0]
heldout_min_distance = 3.0
change = {"optimizer": "adam"}
n_seeds = 5
nominal = [2.0, 0.1, 0.0]
N = 50

# %%
from fnnbook.tasks.why_feedback_point import WhyFeedbackPointSettings
settings = WhyFeedbackPointSettings.from_namespace(globals())  # checked as `fnn-pipeline check` checks them

# %% tags=["hide-input"]
import json
import time
from pathlib import Path

import numpy as np
import torch

import fnnlib as F
from fnnlib.models import NeuralFeedbackEnsemble
from fnnlib.paper import colon_range, paired_levels, simulate_levels
from fnnlib.systems import Spiral
from fnnlib.training import load_seed_checkpoints
from fnnbook.feedback_eval import judge
from fnnlib.paper.feedback_eval import EvaluationSettings, evaluation_setup, release_form_loss
from fnnlib.io import atomic_write

# %% [markdown]
# ## The recipe at this point
# The paper profile's recipe with the one change applied; everything else as in the `neural_feedback` task.

# %%
task_start = time.perf_counter()
recipe = F.FeedbackRecipe(iterations=round(fb_iterations * change.get("iterations_times", 1)),
                          batch_size=fb_batch_size, lr=fb_lr * change.get("lr_times", 1.0),
                          optimizer=change.get("optimizer", fb_optimizer),
                          refresh_every=change.get("refresh_every", refresh_every))
# the neural_feedback task's nominal task, S8 and held-out levels
setup = evaluation_setup(EvaluationSettings.of(settings.as_dict()))
loaded = load_seed_checkpoints(Path(upstream_dirs["spiral"]), stem="neural_ode", expected_kind="NeuralODE")
if len(loaded) < n_seeds:
    raise ValueError(f"n_seeds = {n_seeds}, but the spiral task has {len(loaded)} seeds")
loaded = loaded[:n_seeds]
seeds = [s for s, _, _ in loaded]
print(f"change {change}: {recipe}; seeds {seeds}")

# %% [markdown]
# ## Alg. 1 with this recipe, the seeds side by side

# %%
cases = paired_levels(colon_range(*dr_omega_range), colon_range(*dr_eta_range), colon_range(*dr_eps_range))
t_dr = torch.arange(dr_n_samples, dtype=torch.float64) * dr_Ts
X_dr = simulate_levels([Spiral(*row) for row in cases.tolist()], torch.tensor(x0, dtype=torch.float64), t_dr,
                         exact=True).float()
f_ens = F.NeuralODEEnsemble.from_members([m for _, m, _ in loaded], seeds)
h_ens = NeuralFeedbackEnsemble(2, fb_hidden, fb_activation, seeds)
hist = F.train_neural_feedback(f_ens, h_ens, t_dr, X_dr, recipe, seed=seeds)
print(f"{len(seeds)} feedbacks: {hist.seconds:.1f} s ({hist.ms_per_iteration:.1f} ms/iteration)")

# %% [markdown]
# ## The rules of D2, D3 and D4 at this point

# %% tags=["nbval-check-output"]
results, numbers = judge(f_ens, h_ens, setup, len(seeds), loss=hist.member_loss, factor=d2_factor,
                         ratio_max=d3_ratio, flat=d3_flat)
for c in results.values():
    print(f"{c.id}: {c.verdict:15s} {c.checks}")

# %% [markdown]
# The trained feedbacks' final loss in the release's own form (the mean absolute change-rate error over the
# randomized cases, on which the release stops its training at 0.5): a reading of D3 the why tries.

# %%
numbers["release_form_final"] = release_form_loss(f_ens, h_ens, X_dr, dr_Ts, len(seeds))
print("release-form loss at the end, per seed:", np.round(numbers["release_form_final"], 3).tolist())

# %%
point = {"change": change, "recipe": {k: getattr(recipe, k) for k in
                                      ("iterations", "batch_size", "lr", "optimizer", "refresh_every")},
         "seeds": seeds, "claims": {k: c.to_json() for k, c in results.items()}, "numbers": numbers,
         "loss_mean": hist.loss, "train_seconds": hist.seconds, "task_seconds": time.perf_counter() - task_start}
Path(out_dir).mkdir(parents=True, exist_ok=True)
with atomic_write(Path(out_dir) / "point.json", "w") as fh:
    json.dump(point, fh, default=lambda v: v.tolist() if isinstance(v, np.ndarray) else float(v))
print(f"task time (after kernel start): {point['task_seconds']:.1f} s")
