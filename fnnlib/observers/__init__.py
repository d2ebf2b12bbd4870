"""Observers behind one interface: the linear feedback of Eqs. (7)-(8) with its gain checks, the neural
feedback of Sec. 4, and the Luenberger and Kalman baselines on the learned model with a constant-disturbance state (S11)."""

from fnnlib.observers.augmented import (
    DisturbanceEstimate,
    augmented_matrices,
    constant_gain_filter,
    rollout_corrected,
)
from fnnlib.observers.gains import (
    GainError,
    check_gain,
    decayed_gains,
    gain_compact,
    gain_matrix,
    spectral_radius,
)
from fnnlib.observers.interface import Observer, ObserverReport, evaluate_observer, metrics_table
from fnnlib.observers.kalman import ExtendedKalmanObserver, KalmanObserver, SteadyState, steady_state_gain
from fnnlib.observers.linear import Estimate, LinearFeedback, eval_field, feedback_layer
from fnnlib.observers.luenberger import LuenbergerObserver, linear_feedback_gain, place_observer_gain
from fnnlib.observers.neural import NeuralFeedbackObserver, feedback_rollout

__all__ = ["DisturbanceEstimate", "Estimate", "ExtendedKalmanObserver", "GainError", "KalmanObserver",
           "LinearFeedback", "LuenbergerObserver", "NeuralFeedbackObserver", "Observer", "ObserverReport", "SteadyState",
           "augmented_matrices", "check_gain", "constant_gain_filter", "decayed_gains", "eval_field",
           "evaluate_observer", "feedback_layer", "feedback_rollout", "gain_compact", "gain_matrix", "linear_feedback_gain",
           "metrics_table", "place_observer_gain", "rollout_corrected", "spectral_radius", "steady_state_gain"]
