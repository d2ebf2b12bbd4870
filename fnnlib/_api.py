"""fnnlib's flat public face, loaded on first use by :mod:`fnnlib` (PEP 562).

Importing ``fnnlib`` alone loads nothing heavy; the first ``fnnlib.X`` (or ``from fnnlib import X``) imports
this module, and with it torch and every subpackage. ``import fnnlib.io`` (what the pipeline's workers need)
does not.
"""


from fnnlib._threads import set_num_threads
from fnnlib.data import bottle_throws, load_bottle, synthetic_throws
from fnnlib.metrics import ahead_position_errors, ahead_position_loss, error_norm, mean_error_norm, relative_rmse, rmse, rmse_over_time
from fnnlib.stats import paired_win
from fnnlib.models import MODELS, NeuralFeedback, NeuralFeedbackEnsemble, NeuralODE, NeuralODEEnsemble, mlp, split_members, stack_members
from fnnlib.feedback import (
    NOISE_AMPLIFICATION_LIMIT,
    CascadeGains,
    MeasuredFeedback,
    check_output_gain,
    Estimate,
    GainError,
    GainWarning,
    TunedGains,
    GainSweep,
    sweep_gains,
    GainChoice,
    choose_gain,
    cascade_forward,
    noise_amplification,
    noise_amplification_exact,
    tune_gains,
    VectorField,
    cascade_depths,
    cascade_predict,
    cascade_predict_loop,
    cascade_sweep,
    check_gain,
    decayed_gains,
    eval_field,
    gain_matrix,
    observe_gains,
    rollout_depths,
    rollout_predict,
    spectral_radius,
)
from fnnlib.observers import (
    disturbance_drift_variance,
    ExtendedKalmanObserver,
    KalmanObserver,
    LinearFeedback,
    LuenbergerObserver,
    NeuralFeedbackObserver,
    Observer,
    evaluate_observer,
    linear_feedback_gain,
    place_observer_gain,
    steady_state_gain,
)
from fnnlib.plotting import new_figure, save_figure
from fnnlib.results import (RESULTS_FILENAME, ClaimResult, GuaranteeFailed, Headline, Results, headline_number,
                            read_results, verdict_from_checks, write_results)
from fnnlib.seeding import make_generator, seed_everything
from fnnlib.stability import (
    discrete_residual,
    divergence_transition,
    gain_eigen_bounds,
    growth_factor,
    iss_bound,
    observe_continuous,
    reconvergence,
    reconvergence_rows,
    scaled_error_norm,
    settling_time,
    theorem1_balls,
)
from fnnlib.sweeps import (
    colon_range,
    n_step_errors,
    offset_spirals,
    residual_level_runs,
    n_step_rmse,
    sweep_errors,
    cascade_position_errors,
    n_step_gain_sweep,
    position_gain_sweep,
    position_gain_tuning,
    level_errors,
    switched_spiral_run,
    outward_increase_fraction,
    paired_levels,
    simulate_levels,
)
from fnnlib.systems import BatchedSpirals, DynamicalSystem, LinearSystem, StackedSystem, Pendulum, Spiral, SwitchedSystem, add_measurement_noise, add_member_noise
from fnnlib.systems.projectile import fit_drag
from fnnlib.training import (
    PAPER_BOTTLE_RECIPE,
    PAPER_FEEDBACK_RECIPE,
    PAPER_SPIRAL_RECIPE,
    QUICK_RECIPE,
    CheckpointError,
    FeedbackRecipe,
    ODERecipe,
    TrainHistory,
    load_checkpoint,
    load_seed_checkpoints,
    load_seed_ensemble,
    randomized_cases,
    register_model,
    save_checkpoint,
    seed_checkpoint_name,
    train_neural_feedback,
    train_neural_ode,
)
from fnnlib.training.outputs import OutputFit, OutputRecipe, free_run, train_from_outputs
from fnnlib.models.neural_ode import init_parameters

# A real plant: measurements y = C x (or h(x)), inputs, gaps, the UKF, tuning recipes.
from fnnlib.feedback import (
    DEFAULT_TUNE_RECIPE,
    DetectabilityError,
    Gains,
    Measurement,
    Solver,
    TuneRecipe,
    check_detectable,
    check_measurements,
    model_jacobian,
    output_jacobian,
)
from fnnlib.observers import Covariances, SigmaPoints, UnscentedKalmanObserver

__all__ = [
    "CascadeGains", "GainWarning", "MeasuredFeedback", "check_output_gain", "LinearSystem", "NOISE_AMPLIFICATION_LIMIT", "Pendulum", "QUICK_RECIPE",
    "TunedGains", "cascade_depths", "cascade_forward", "noise_amplification", "noise_amplification_exact", "paired_win", "randomized_cases", "register_model", "disturbance_drift_variance",
    "tune_gains", "GainSweep", "sweep_gains", "GainChoice", "choose_gain",
    "ExtendedKalmanObserver", "KalmanObserver", "LuenbergerObserver", "Observer", "evaluate_observer",
    "linear_feedback_gain", "place_observer_gain", "steady_state_gain",
    "discrete_residual", "gain_eigen_bounds", "growth_factor", "iss_bound", "observe_continuous", "reconvergence", "reconvergence_rows",
    "settling_time", "theorem1_balls", "divergence_transition", "scaled_error_norm", "cascade_sweep", "colon_range", "n_step_errors", "observe_gains",
    "outward_increase_fraction", "paired_levels", "simulate_levels", "SwitchedSystem",
    "NeuralFeedback", "NeuralFeedbackObserver", "train_neural_feedback", "FeedbackRecipe", "ODERecipe",
    "PAPER_BOTTLE_RECIPE", "PAPER_FEEDBACK_RECIPE", "PAPER_SPIRAL_RECIPE",
    "fit_drag", "bottle_throws", "load_bottle", "synthetic_throws",
    "CheckpointError", "DynamicalSystem", "Estimate", "GainError", "LinearFeedback", "MODELS", "NeuralODE",
    "NeuralODEEnsemble", "NeuralFeedbackEnsemble", "split_members", "stack_members",
    "Spiral", "BatchedSpirals", "StackedSystem", "TrainHistory", "add_measurement_noise", "add_member_noise", "cascade_predict",
    "cascade_predict_loop",
    "check_gain", "ClaimResult", "GuaranteeFailed", "Headline", "Results", "RESULTS_FILENAME", "headline_number", "decayed_gains", "error_norm", "ahead_position_errors", "ahead_position_loss", "eval_field", "VectorField", "gain_matrix", "load_checkpoint", "load_seed_checkpoints", "load_seed_ensemble", "seed_checkpoint_name",
    "make_generator", "mean_error_norm", "mlp", "new_figure", "read_results", "relative_rmse", "save_figure",
    "rollout_depths", "rollout_predict", "rmse", "rmse_over_time", "offset_spirals", "residual_level_runs", "n_step_rmse", "sweep_errors", "cascade_position_errors", "n_step_gain_sweep", "position_gain_sweep", "position_gain_tuning", "level_errors", "switched_spiral_run", "save_checkpoint", "seed_everything", "set_num_threads", "spectral_radius",
    "train_neural_ode", "verdict_from_checks", "write_results",
    "OutputFit", "OutputRecipe", "free_run", "train_from_outputs", "init_parameters",
]

# -- the paper authors' released networks, read safely and mapped onto the models above (fnnlib.data.release)
from fnnlib.data.release import (
    ReleaseError,
    UnsafePickleError,
    load_release_bottle_ode,
    load_release_losses,
    load_release_mlp,
    load_release_residual,
    load_release_spiral_feedback,
    load_release_spiral_ode,
    read_pickled_module,
    release_spiral,
)

__all__ += [
    "ReleaseError", "UnsafePickleError", "load_release_bottle_ode", "load_release_losses", "load_release_mlp",
    "load_release_residual", "load_release_spiral_feedback", "load_release_spiral_ode", "read_pickled_module",
    "release_spiral",
]

__all__ += [  # a real plant
    "DEFAULT_TUNE_RECIPE", "DetectabilityError", "Gains", "Measurement", "Solver", "TuneRecipe", "Covariances", "SigmaPoints", "UnscentedKalmanObserver", "check_detectable",
    "check_measurements", "model_jacobian", "output_jacobian",
]

# A real benchmark: the cascaded tanks (its records, a synthetic twin, its metric) and a linear ARX baseline.
from fnnlib.data.tanks import TanksRecords, load_tanks, simulation_rmse, synthetic_tanks, tanks_records
from fnnlib.models.arx import ARXModel, fit_arx, select_arx
from fnnlib.systems.tanks import CascadedTanks

__all__ += [
    "ARXModel", "CascadedTanks", "TanksRecords", "fit_arx", "load_tanks", "select_arx", "simulation_rmse",
    "synthetic_tanks", "tanks_records",
]
