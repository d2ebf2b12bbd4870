# %% [markdown]
# # Quick start: your own system, partly measured, with gaps
#
# A damped cart driven by a known force, $\dot p = v$, $\dot v = -k p - c v + u$. Only the position is
# measured, with noise, and some samples are lost. Your model `f(t, x, u)` is the cart with a damping
# that is off by 40 %. Out come feedback gains tuned on one record, the $N$-step predictions on another,
# and the comparison with an extended and an unscented Kalman filter on the same model. Every call is
# `fnnlib`'s public API; the code is the cells below: the system, its logs, then the model with its tuned
# feedback and the two filters.

# %% tags=["parameters"]
profile = "paper"
out_dir = "outputs/manual/quick_start"
T = 200
Ts = 0.05
N = 5
noise_std = 0.02
drop = 0.2
tune_iterations = 20

# %% tags=["remove-input"]
from fnnbook.settings import check_notebook_settings  # the checks `fnn-pipeline check` runs first
check_notebook_settings("quick_start", globals())

# %%
import torch

import fnnlib as F


class Cart(F.DynamicalSystem):  # your own f(t, x, u): x = (position, velocity), u = force
    n, m = 2, 1

    def __init__(self, k=2.0, c=0.5):
        self.k, self.c = k, c

    def __call__(self, t, x, u):
        return torch.stack([x[:, 1], -self.k * x[:, 0] - self.c * x[:, 1] + u[:, 0]], -1)


# %%
gen = F.make_generator(0)
C = torch.tensor([[1.0, 0.0]], dtype=torch.float64)  # y = C x: the position only
t = torch.arange(T, dtype=torch.float64) * Ts
u = torch.sin(0.8 * t)[None, :, None] + torch.randn(2, 1, 1, generator=gen, dtype=torch.float64)  # two records
x = Cart().simulate(torch.tensor([[1.0, 0.0], [-0.5, 0.5]], dtype=torch.float64), t, u)  # (2, T, 2), the truth
y = F.add_measurement_noise(x @ C.T, noise_std, gen)  # noisy logs (2, T, 1) ...
y[torch.rand(y.shape, generator=gen) < drop] = float("nan")  # ... with lost samples

# %%
model = Cart(c=0.3)  # your model: the damping is off
A = F.model_jacobian(model, torch.zeros(2, dtype=torch.float64), torch.zeros(1, dtype=torch.float64))
L0 = F.place_observer_gain(torch.eye(2, dtype=torch.float64) + Ts * A, Ts * C, [0.8, 0.85])  # a stable start
observer = F.MeasuredFeedback(model, L0, C, Ts, A=A)  # the first layer, on the position
tuned = F.tune_gains(model, y[0], Ts, N, u=u[0], observer=observer, L0=2.0, beta0=0.05, iterations=tune_iterations,
                     lr=0.5)
preds = {"open loop": observer.predict(y[1], N, u[1]),
         "feedback, tuned": F.cascade_predict(model, y[1], Ts, N, tuned.L_tensor, tuned.beta, u=u[1], observer=observer)}
Q = [1e-6, 1e-6, 1e-3]  # process noise of (position, velocity, a disturbance on the velocity)
for name, kf in [("EKF", F.ExtendedKalmanObserver), ("UKF", F.UnscentedKalmanObserver)]:
    preds[name] = kf(model, Ts, 2, Q, noise_std ** 2, C=C, disturbance=[1], A=A).predict(y[1], N, u[1])
errors = {k: float(F.n_step_errors(z, x[1], N)[T // 4:].mean()) for k, z in preds.items()}
errors

# %% [markdown]
# `errors` is the mean $N$-step error of the state on the second record (after a quarter of it, the
# start-up). Which one wins is printed below, with the tuned gain and decay rate; the results file follows.

# %% tags=["nbval-check-output"]
best = min(errors, key=errors.get)
print(f"lowest N-step error: {best} ({errors[best]:.4g}); the tuned feedback: {errors['feedback, tuned']:.4g}")
print(f"tuned L = {[round(v, 3) for v in tuned.L]}, beta = {tuned.beta:.3f}, "
      f"N-step loss {tuned.loss[0]:.4g} -> {tuned.loss[-1]:.4g}")

# %%
results_file = F.write_results(out_dir, task="quick_start", profile=profile, claims=[],
                metrics={"errors": errors, "L": tuned.L, "beta": tuned.beta})
