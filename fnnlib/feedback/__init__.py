"""The Sec. 3 core: the feedback network of Eqs. (7)-(8), the gain decay of Eq. (11) and the cascade of Sec. 3.3.

* :mod:`~fnnlib.feedback.types`: ``VectorField``, ``Feedback``, ``Estimate``.
* :mod:`~fnnlib.feedback.options`: the option objects ``Gains`` (``L``, ``beta`` of Eq. (11)) and ``Measurement``
  (``C`` or ``h``, gaps, first estimate, sample times), each checked on construction.
* :mod:`~fnnlib.feedback.gains`: the base gain ``L`` (shapes, Theorem 1 / Eq. (25) checks).
* :mod:`~fnnlib.feedback.noise`: the cascade's noise amplification (the quick bound and the exact factor).
* :mod:`~fnnlib.feedback.decay`: Eq. (11), ``L_stack[i] = L e^{-beta i}``, and the checks on N and beta.
* :mod:`~fnnlib.feedback.layer`: Eqs. (7)-(8) along a sequence, one gain or a batch of gains.
* :mod:`~fnnlib.feedback.cascade`: the N-layer cascade (Sec. 3.3), one gain or a sweep.
* :mod:`~fnnlib.feedback.measured`: partial measurements ``y = C x``, the gain L (n x p) and its checks.
* :mod:`~fnnlib.feedback.measurement`: the one measurement model (``C`` or ``h(x)``, inputs, gaps) and its check,
  the model Jacobian, the PBH detectability test.
* :mod:`~fnnlib.feedback.gaps`: Eqs. (7)-(8) and the cascade through missing samples and with ``C``.
* :mod:`~fnnlib.feedback.tuning`: the differentiable cascade and ``tune_gains`` (L and beta learned, B1).
* :mod:`~fnnlib.feedback.rollout`: the open-loop neural ODE (Eq. (2)) it is compared to.
"""

from fnnlib.feedback.cascade import cascade_depths, cascade_predict, cascade_predict_loop, cascade_sweep, run_cascade
from fnnlib.feedback.decay import check_beta, check_betas, check_N, decay_factors, decayed_gains
from fnnlib.feedback.gains import (
    NOISE_AMPLIFICATION_LIMIT,
    GainError,
    GainWarning,
    check_gain,
    gain_batch,
    gain_compact,
    gain_matrix,
    spectral_radius,
)
from fnnlib.feedback.layer import eval_field, feedback_layer, observe_gains
from fnnlib.feedback.measured import MeasuredFeedback, check_output_gain
from fnnlib.feedback.measurement import (
    DetectabilityError,
    Measurements,
    check_detectable,
    check_measurements,
    model_jacobian,
    output_jacobian,
)
from fnnlib.feedback.noise import noise_amplification, noise_amplification_exact
from fnnlib.feedback.options import Gains, Measurement, Solver
from fnnlib.feedback.rollout import rollout_depths, rollout_predict
from fnnlib.feedback.tuning import (
    DEFAULT_TUNE_RECIPE,
    CascadeGains,
    GainChoice,
    GainSweep,
    TunedGains,
    TuneRecipe,
    cascade_forward,
    choose_gain,
    prediction_loss,
    sweep_gains,
    tune_gains,
)
from fnnlib.feedback.types import Estimate, Feedback, VectorField

__all__ = ["Gains", "Measurement", "Solver", "rollout_depths", "DEFAULT_TUNE_RECIPE", "DetectabilityError", "Measurements", "TuneRecipe", "check_detectable",
           "check_measurements", "model_jacobian", "output_jacobian", "MeasuredFeedback", "check_output_gain", "CascadeGains", "NOISE_AMPLIFICATION_LIMIT", "GainWarning", "TunedGains", "cascade_forward",
           "noise_amplification", "noise_amplification_exact", "prediction_loss", "sweep_gains", "choose_gain", "GainChoice", "tune_gains", "GainSweep", "Estimate", "Feedback", "GainError", "VectorField", "cascade_depths", "cascade_predict", "cascade_predict_loop",
           "cascade_sweep", "check_N", "check_beta", "check_betas", "check_gain", "decay_factors", "decayed_gains", "eval_field",
           "feedback_layer", "gain_batch", "gain_compact", "gain_matrix", "observe_gains", "rollout_predict",
           "run_cascade", "spectral_radius"]
