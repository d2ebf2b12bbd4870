"""Observers behind one interface: the linear feedback of Eqs. (7)-(8) (its kernel in :mod:`fnnlib.feedback`), the neural
feedback of Sec. 4, and the Luenberger and Kalman baselines (KF, EKF, UKF) on the learned model with a constant-disturbance state (S11)."""

from fnnlib.observers.augmented import (
    AugmentedObserver,
    DisturbanceEstimate,
    augmented_matrices,
    constant_gain_filter,
    rollout_corrected,
)
from fnnlib.observers.interface import Observer, ObserverReport, evaluate_observer, metrics_table
from fnnlib.observers.kalman import ExtendedKalmanObserver, KalmanObserver, SteadyState, steady_state_gain
from fnnlib.observers.linear import LinearFeedback
from fnnlib.observers.luenberger import LuenbergerObserver, linear_feedback_gain, place_observer_gain
from fnnlib.observers.neural import NeuralFeedbackObserver, feedback_rollout
from fnnlib.observers.tuning import disturbance_drift_variance
from fnnlib.observers.unscented import UnscentedKalmanObserver

__all__ = ["AugmentedObserver", "DisturbanceEstimate", "ExtendedKalmanObserver", "KalmanObserver", "LinearFeedback",
           "LuenbergerObserver", "NeuralFeedbackObserver", "Observer", "ObserverReport", "SteadyState", "UnscentedKalmanObserver",
           "augmented_matrices", "constant_gain_filter", "disturbance_drift_variance", "evaluate_observer", "feedback_rollout", "linear_feedback_gain",
           "metrics_table", "place_observer_gain", "rollout_corrected", "steady_state_gain"]
