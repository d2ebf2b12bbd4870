"""Dynamical systems: controlled examples (a linear plant, a pendulum), the spiral (Eq. 26), switched systems (Fig. S12) and the thrown object (the quadrotor of Eq. 27 is in :mod:`fnnlib.quadrotor.system`)."""

from fnnlib.systems.base import DynamicalSystem, StackedSystem
from fnnlib.systems.controlled import LinearSystem, Pendulum
from fnnlib.systems.noise import add_measurement_noise, add_member_noise
from fnnlib.systems.spiral import BatchedSpirals, Spiral
from fnnlib.systems.switched import SwitchedSystem

__all__ = ["DynamicalSystem", "StackedSystem", "LinearSystem", "Pendulum", "Spiral", "BatchedSpirals",
           "SwitchedSystem", "add_measurement_noise", "add_member_noise"]
