"""Dynamical systems: controlled examples (a linear plant, a pendulum), the spiral (Eq. 26), switched systems (Fig. S12), the thrown object and the quadrotor (Eq. 27)."""

from fnnlib.systems.base import DynamicalSystem, StackedSystem
from fnnlib.systems.controlled import LinearSystem, Pendulum
from fnnlib.systems.noise import add_measurement_noise, add_member_noise
from fnnlib.systems.quadrotor import NOMINAL, TEST_TRUTH, TRAINING_TRUTH, Quadrotor, QuadrotorParams
from fnnlib.systems.spiral import BatchedSpirals, Spiral
from fnnlib.systems.switched import SwitchedSystem

__all__ = ["NOMINAL", "TEST_TRUTH", "TRAINING_TRUTH", "DynamicalSystem", "StackedSystem", "LinearSystem", "Pendulum", "Quadrotor", "QuadrotorParams", "Spiral", "BatchedSpirals",
           "SwitchedSystem", "add_measurement_noise", "add_member_noise"]
