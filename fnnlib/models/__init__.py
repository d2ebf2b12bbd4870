"""Learned models: the neural ODE vector field, the neural feedback part (Sec. 4), the quadrotor residual."""

from fnnlib.models.ensemble import NeuralODEEnsemble, split_members, stack_members
from fnnlib.models.feedback import NeuralFeedback, NeuralFeedbackEnsemble
from fnnlib.models.neural_ode import ACTIVATIONS, NeuralODE, mlp
from fnnlib.models.residual import AdaptiveResidual, AeroResidual

#: The model classes a checkpoint may name (class name -> class); :func:`~fnnlib.training.register_model` adds one.
MODELS = {"NeuralODE": NeuralODE, "NeuralFeedback": NeuralFeedback, "AeroResidual": AeroResidual}

__all__ = ["ACTIVATIONS", "AdaptiveResidual", "AeroResidual", "MODELS", "NeuralFeedback", "NeuralFeedbackEnsemble", "NeuralODE", "NeuralODEEnsemble", "mlp", "split_members", "stack_members"]
