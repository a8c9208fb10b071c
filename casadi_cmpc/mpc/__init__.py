"""Contractive MPC controllers and closed-loop simulation."""

from .contractive import ContractiveMPC, MPCResult
from .simulate import Trajectory, simulate

__all__ = ["ContractiveMPC", "MPCResult", "Trajectory", "simulate"]
