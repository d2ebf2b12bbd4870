"""Dynamical systems: the spiral (Eq. 26) and switched systems (Fig. S12); the thrown object and quadrotor come later."""

from fnnlib.systems.base import DynamicalSystem
from fnnlib.systems.noise import add_measurement_noise
from fnnlib.systems.spiral import Spiral
from fnnlib.systems.switched import SwitchedSystem

__all__ = ["DynamicalSystem", "Spiral", "SwitchedSystem", "add_measurement_noise"]
