# %% [markdown]
# # Quick start: your own system, learned from a partly measured log with gaps
#
# A damped cart driven by a known force, $\dot p = v$, $\dot v = -k p - c v + u$. Only the position is
# measured, with noise, and some samples are lost. Nothing else is known: a neural ODE $f(t, x, u)$ with two
# states is **learned from the position log alone**, each training segment starting at the feedback
# observer's estimate (Eqs. (7)-(8) on the model itself). Its cascade gains are then tuned on the same
# record, and it predicts $N$ samples ahead on a fourth, beside the open-loop rollout from the same
# observer and an extended and an unscented Kalman filter on the same learned model. Every line is
# `fnnlib`'s public API.

# %% tags=["parameters"]
profile = "paper"
out_dir = "outputs/manual/quick_start"
# the settings and their paper values, from fnnbook.tasks.quick_start (written by `make notebooks`)
T = 300
Ts = 0.1
N = 10
noise_std = 0.02
drop = 0.2
train_iterations = 200
tune_iterations = 30

# %% tags=["remove-input"]
from fnnbook.tasks.quick_start import QuickStartSettings
settings = QuickStartSettings.from_namespace(globals())  # checked as `fnn-pipeline check` checks them

# %%
import torch

import fnnlib as F
from fnnbook.results import write_results
from fnnlib.metrics import n_step_errors
from fnnlib.models.neural_ode import init_parameters
from fnnlib.plotting import new_figure, save_figure
from fnnlib.seeding import make_generator


# %%
class Cart(F.DynamicalSystem):  # the plant: x = (position, velocity), u = force; the model never sees it
    n, m = 2, 1

    def __call__(self, t, x, u):
        return torch.stack([x[:, 1], -2.0 * x[:, 0] - 0.5 * x[:, 1] + u[:, 0]], -1)


gen, f64 = make_generator(0), torch.float64
C = torch.tensor([[1.0, 0.0]], dtype=f64)  # y = C x: the position only
t = torch.arange(T, dtype=f64) * Ts
u = torch.sin(0.8 * t)[None, :, None] * (1 + torch.rand(4, 1, 1, generator=gen, dtype=f64))  # four records
x = Cart().simulate(torch.randn(4, 2, generator=gen, dtype=f64), t, u)  # the truth, never given to the model
y = F.add_measurement_noise(x @ C.T, noise_std, gen)  # noisy position logs (4, T, 1) ...
y[torch.rand(y.shape, generator=gen) < drop] = float("nan")  # ... with lost samples

# %%
A_guess = torch.tensor([[0.0, 1.0], [-1.0, 0.0]], dtype=f64)  # a rough guess (an undamped unit oscillator)
L_y = F.place_observer_gain(torch.eye(2, dtype=f64) + Ts * A_guess, Ts * C, [0.8, 0.85])  # the observer's gain
model = init_parameters(F.NeuralODE(2, (16, 16), "tanh", n_input=1).double(), gen)
F.train_from_outputs(model, y[:2], C, F.OutputRecipe(iterations=train_iterations, L=L_y.tolist()), Ts=Ts, u=u[:2])
observer = F.MeasuredFeedback(model, Ts, L=L_y, measurement=F.Measurement(C=C), allow_unstable=True)  # layer 0

# %%
tuned = F.tune_gains(model, y[2], Ts, N, F.TuneRecipe(L0=1.0, beta0=0.05, settle=T // 4, iterations=tune_iterations,
                     lr=0.2), u=u[2], observer=observer)  # the gains tuned on a third log, after the start-up
preds = {"open loop": observer.predict(y[3], N, u[3]),
         "feedback, tuned": F.cascade_predict(model, y[3], Ts, N, tuned.schedule(), u=u[3], observer=observer)}
A = F.model_jacobian(model, torch.zeros(2, dtype=f64), torch.zeros(1, dtype=f64))
for name, kf in [("EKF", F.ExtendedKalmanObserver), ("UKF", F.UnscentedKalmanObserver)]:
    preds[name] = kf(model, Ts, n=2, cov=F.Covariances([1e-6, 1e-6, 1e-3], noise_std ** 2), C=C, disturbance=[1],
                     A=A).predict(y[3], N, u[3])
errors = {k: float(n_step_errors(z @ C.T, x[3] @ C.T, N)[T // 4:].mean()) for k, z in preds.items()}

# %% [markdown]
# `errors` is the mean error of the position predicted $N$ samples ahead on the fourth record, against the true
# position (after a quarter of the record, the start-up). The learned model's second state is its own
# coordinate for the velocity, so the comparison is made on what is measured. Which estimator wins is printed
# below, with the tuned gain and decay rate.

# %% tags=["nbval-check-output"]
best = min(errors, key=errors.get)
print(f"lowest N-step error: {best} ({errors[best]:.4g}); the tuned feedback: {errors['feedback, tuned']:.4g}")
print(f"tuned L = {[round(v, 3) for v in tuned.L.tolist()]}, beta = {tuned.beta:.3f}")

# %% [markdown]
# The fourth record: the true position, the lost and noisy samples the model was given, and the predictions
# made $N$ samples earlier.

# %%
fig, ax = new_figure()
ax.plot(t, x[3, :, 0], color="black", lw=1.5, label="true position")
ax.plot(t, y[3, :, 0], ".", color="grey", ms=3, label="measured (noisy, gaps)")
for name in ("open loop", "feedback, tuned"):
    ax.plot(t[N:], preds[name][: T - N, 0], lw=1, label=f"{name}, {N} samples ahead")
ax.set(xlabel="time [s]", ylabel="position")
ax.legend(fontsize=8, ncol=2)
figure = save_figure(fig, out_dir, "quick_start_prediction")

# %%
results_file = write_results(out_dir, task="quick_start", profile=profile, claims=[],
                               metrics={"errors": errors, "L": tuned.L.tolist(), "beta": tuned.beta})
