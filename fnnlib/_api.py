"""fnnlib's public face: the method, and nothing else, loaded on first use by :mod:`fnnlib` (PEP 562).

The face holds what a user of feedback neural ODEs needs (Jia et al., ICLR 2025; equation numbers are the
paper's):

* a system to learn: :class:`DynamicalSystem` (Eq. (1)) and its noisy measurements;
* the neural ODE of Eq. (2) and its training, from full states or from measured outputs;
* the linear feedback of Eqs. (7)-(8) with the gain decay of Eq. (11), and the N-step cascade of Sec. 3.3
  beside the open-loop rollout it improves on;
* the neural feedback part learned by domain randomisation (Eq. (12), Alg. 1);
* the gain ``L`` and its checks (Theorem 1, the error dynamics of Eq. (9), Eq. (25)), its noise
  amplification, its placement, its tuning from data;
* the observers behind one interface, and the measurement helpers for ``y = C x`` or ``h(x)``;
* the option objects these take, each checked on construction: :class:`Gains` (``L``, ``beta`` of Eq. (11)),
  :class:`Measurement` (``C`` or ``h``, gaps, first estimate, sample times), :class:`Solver` (the rollout's
  integrator), :class:`Covariances` and :class:`SigmaPoints` (the Kalman baselines').

Everything else lives in a named subpackage: the paper's settings and sweeps (:mod:`fnnlib.paper`), its
systems (:mod:`fnnlib.systems`), the Sec. 5 quadrotor and MPC stack (:mod:`fnnlib.quadrotor`,
:mod:`fnnlib.quadrotor.mpc`, :mod:`fnnlib.quadrotor.control`), the authors' released networks (:mod:`fnnlib.release`), data sets
(:mod:`fnnlib.data`), metrics, checkpoints, seeding and figures (:mod:`fnnlib.metrics`,
:mod:`fnnlib.training`, :mod:`fnnlib.seeding`, :mod:`fnnlib.plotting`). The book's result types are
:mod:`fnnbook.results`.

Importing ``fnnlib`` alone loads nothing heavy; the first ``fnnlib.X`` imports this module, and with it torch.
"""

from fnnlib.feedback import (
    GainError,
    Gains,
    MeasuredFeedback,
    Measurement,
    Solver,
    TunedGains,
    TuneRecipe,
    cascade_predict,
    check_gain,
    check_measurements,
    choose_gain,
    decayed_gains,
    model_jacobian,
    noise_amplification,
    rollout_predict,
    tune_gains,
)
from fnnlib.models import NeuralFeedback, NeuralODE, NeuralODEEnsemble
from fnnlib.observers import (
    Covariances,
    ExtendedKalmanObserver,
    KalmanObserver,
    LinearFeedback,
    LuenbergerObserver,
    NeuralFeedbackObserver,
    Observer,
    SigmaPoints,
    UnscentedKalmanObserver,
    place_observer_gain,
)
from fnnlib.systems import DynamicalSystem, add_measurement_noise
from fnnlib.training import (
    FeedbackRecipe,
    ODERecipe,
    OutputRecipe,
    train_from_outputs,
    train_neural_feedback,
    train_neural_ode,
)

#: the face, grouped as the API reference groups it
__all__ = [
    # systems
    "DynamicalSystem", "add_measurement_noise",
    # the neural ODE (Eq. (2)) and its training
    "NeuralODE", "NeuralODEEnsemble", "ODERecipe", "train_neural_ode", "OutputRecipe", "train_from_outputs",
    # the feedback layer (Eqs. (7)-(8), (11)) and the cascade (Sec. 3.3)
    "LinearFeedback", "decayed_gains", "cascade_predict", "rollout_predict",
    # the neural feedback part (Eq. (12), Alg. 1)
    "NeuralFeedback", "FeedbackRecipe", "train_neural_feedback",
    # the gain and its checks (Theorem 1, Eqs. (9), (25))
    "check_gain", "GainError", "noise_amplification", "place_observer_gain",
    # tuning the gain from data
    "tune_gains", "TuneRecipe", "TunedGains", "choose_gain",
    # observers
    "Observer", "LuenbergerObserver", "KalmanObserver", "ExtendedKalmanObserver", "UnscentedKalmanObserver",
    "NeuralFeedbackObserver",
    # measurements y = C x or h(x)
    "MeasuredFeedback", "model_jacobian", "check_measurements",
    # the option objects (checked on construction)
    "Gains", "Measurement", "Solver", "Covariances", "SigmaPoints",
]
