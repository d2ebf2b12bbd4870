"""Learned models: the neural ODE vector field, the neural feedback part (Sec. 4) (the quadrotor residual is in :mod:`fnnlib.quadrotor.residual`)."""

from fnnlib.models.ensemble import NeuralODEEnsemble, split_members, stack_members
from fnnlib.models.feedback import NeuralFeedback, NeuralFeedbackEnsemble
from fnnlib.models.neural_ode import ACTIVATIONS, NeuralODE, mlp

#: The model classes a checkpoint may name (class name -> class); :func:`~fnnlib.training.register_model` adds one.
MODELS = {"NeuralODE": NeuralODE, "NeuralFeedback": NeuralFeedback}

__all__ = ["ACTIVATIONS", "MODELS", "NeuralFeedback", "NeuralFeedbackEnsemble", "NeuralODE", "NeuralODEEnsemble", "mlp", "split_members", "stack_members"]
