"""Observers: the linear feedback of Eqs. (7)-(8) and its gain checks."""

from fnnlib.observers.gains import (
    GainError,
    check_gain,
    decayed_gains,
    gain_compact,
    gain_matrix,
    spectral_radius,
)
from fnnlib.observers.linear import Estimate, LinearFeedback, eval_field, feedback_layer

__all__ = ["Estimate", "GainError", "LinearFeedback", "check_gain", "decayed_gains", "eval_field",
           "feedback_layer", "gain_compact", "gain_matrix", "spectral_radius"]
