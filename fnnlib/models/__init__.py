"""Learned models: the neural ODE vector field (feedback networks come with the observers)."""

from fnnlib.models.neural_ode import ACTIVATIONS, NeuralODE, mlp

MODELS = {"NeuralODE": NeuralODE}

__all__ = ["ACTIVATIONS", "MODELS", "NeuralODE", "mlp"]
