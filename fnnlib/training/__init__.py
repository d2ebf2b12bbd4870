"""Training neural ODEs and saving them."""

from fnnlib.training.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from fnnlib.training.neural_ode import TrainHistory, sample_segments, train_neural_ode

__all__ = ["CheckpointError", "TrainHistory", "load_checkpoint", "sample_segments", "save_checkpoint",
           "train_neural_ode"]
