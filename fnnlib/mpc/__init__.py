"""MPC of Eq. (28) (App. A.5.3): affine models of a torch step along a plan, and the linear time-varying QP."""

from fnnlib.mpc.linearize import Linearization, StepFn, linearize
from fnnlib.mpc.linearized import LinearizedMPC, MPCSolution, OSQPMPC, RebuildMPC, shift_plan

__all__ = ["Linearization", "LinearizedMPC", "MPCSolution", "OSQPMPC", "RebuildMPC", "StepFn", "linearize", "shift_plan"]
