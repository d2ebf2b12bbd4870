"""The settings of ``notebooks/18_why_quadrotor``: the aggregate of the quadrotor's why grid."""

from __future__ import annotations

from dataclasses import dataclass

from fnnbook.tasks._base import TaskSettings

__all__ = ["WhyQuadrotorSettings"]


@dataclass(frozen=True, kw_only=True)
class WhyQuadrotorSettings(TaskSettings, notebook="why_quadrotor"):
    """No settings of its own: its grid points' run records carry them."""
