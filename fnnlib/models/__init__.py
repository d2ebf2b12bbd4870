"""Learned models: the neural ODE vector field and the neural feedback part (Sec. 4)."""

from fnnlib.models.feedback import NeuralFeedback
from fnnlib.models.neural_ode import ACTIVATIONS, NeuralODE, mlp

MODELS = {"NeuralODE": NeuralODE, "NeuralFeedback": NeuralFeedback}

__all__ = ["ACTIVATIONS", "MODELS", "NeuralFeedback", "NeuralODE", "mlp"]
