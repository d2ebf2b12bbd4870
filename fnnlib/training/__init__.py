"""Training neural ODEs and neural feedback parts, and saving them."""

from fnnlib.training.external import adjoint_gradient, train_with_inputs
from fnnlib.training.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from fnnlib.training.feedback import feedback_loss, train_neural_feedback
from fnnlib.training.neural_ode import TrainHistory, sample_segments, train_neural_ode

__all__ = ["CheckpointError", "adjoint_gradient", "train_with_inputs", "TrainHistory", "feedback_loss", "load_checkpoint", "sample_segments", "save_checkpoint",
           "train_neural_feedback", "train_neural_ode"]
