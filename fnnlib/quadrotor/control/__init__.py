"""Quadrotor control: differential flatness (zero yaw) and the DFBC of App. A.5."""

from fnnlib.quadrotor.control.dfbc import DFBC
from fnnlib.quadrotor.control.flatness import flat_reference, flat_to_input, flat_to_state, split_flat, state_to_flat

__all__ = ["DFBC", "flat_reference", "flat_to_input", "flat_to_state", "split_flat", "state_to_flat"]
