"""Dynamical systems: the spiral (Eq. 26); the thrown object and quadrotor come later."""

from fnnlib.systems.base import DynamicalSystem
from fnnlib.systems.noise import add_measurement_noise
from fnnlib.systems.spiral import Spiral

__all__ = ["DynamicalSystem", "Spiral", "add_measurement_noise"]
