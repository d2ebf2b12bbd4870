"""Training neural ODEs and neural feedback parts, and saving them."""

from fnnlib.training.external import InputRecipe, adjoint_gradient, train_with_inputs
from fnnlib.training.checkpoint import (
    CheckpointError,
    load_checkpoint,
    load_seed_checkpoints,
    load_seed_ensemble,
    register_model,
    save_checkpoint,
    seed_checkpoint_name,
)
from fnnlib.training.feedback import (
    PAPER_FEEDBACK_RECIPE,
    FeedbackRecipe,
    feedback_loss,
    randomized_cases,
    train_neural_feedback,
)
from fnnlib.training.neural_ode import PAPER_BOTTLE_RECIPE, PAPER_SPIRAL_RECIPE, QUICK_RECIPE, ODERecipe, TrainHistory, sample_segments, train_neural_ode
from fnnlib.training.outputs import OutputFit, OutputRecipe, free_run, train_from_outputs

__all__ = ["CheckpointError", "adjoint_gradient", "train_with_inputs", "TrainHistory", "feedback_loss", "load_checkpoint", "load_seed_checkpoints", "load_seed_ensemble", "seed_checkpoint_name", "sample_segments", "save_checkpoint",
           "train_neural_feedback", "train_neural_ode", "FeedbackRecipe", "ODERecipe", "PAPER_BOTTLE_RECIPE", "PAPER_FEEDBACK_RECIPE",
           "PAPER_SPIRAL_RECIPE", "QUICK_RECIPE", "randomized_cases", "register_model", "InputRecipe",
           "OutputFit", "OutputRecipe", "free_run", "train_from_outputs"]
