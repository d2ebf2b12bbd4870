"""Observers behind one interface: the linear feedback of Eqs. (7)-(8) (its kernel in :mod:`fnnlib.feedback`), the neural
feedback of Sec. 4, and the Luenberger and Kalman baselines (KF, EKF, UKF) on the learned model with a constant-disturbance state (S11).

Every observer is built as ``(f, Ts, *, ...)``: the learned field and the nominal sample step by position (``Ts``
may be ``None`` for :class:`~fnnlib.feedback.measured.MeasuredFeedback` when every call gives the times), and
everything else by name: ``gains=Gains(L, beta)`` (:class:`LinearFeedback`), ``h=`` (:class:`NeuralFeedbackObserver`),
``L=`` and ``measurement=Measurement(C=..., x0=...)`` (:class:`~fnnlib.feedback.measured.MeasuredFeedback`),
``poles=`` (:class:`LuenbergerObserver`; ``LuenbergerObserver.with_gain(..., L=...)``), ``cov=Covariances(Q, R, P0)``
(the Kalman filters; ``sigma=SigmaPoints(...)`` for the UKF), and ``n=`` (default ``f.n``) for all of them.
"""

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
from fnnlib.observers.options import Covariances, SigmaPoints
from fnnlib.observers.tuning import disturbance_drift_variance
from fnnlib.observers.unscented import UnscentedKalmanObserver

__all__ = ["Covariances", "SigmaPoints", "AugmentedObserver", "DisturbanceEstimate", "ExtendedKalmanObserver", "KalmanObserver", "LinearFeedback",
           "LuenbergerObserver", "NeuralFeedbackObserver", "Observer", "ObserverReport", "SteadyState", "UnscentedKalmanObserver",
           "augmented_matrices", "constant_gain_filter", "disturbance_drift_variance", "evaluate_observer", "feedback_rollout", "linear_feedback_gain",
           "metrics_table", "place_observer_gain", "rollout_corrected", "steady_state_gain"]
