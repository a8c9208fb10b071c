"""Contractive MPC controllers and closed-loop simulation."""

from .contractive import Certificate, ContractiveMPC, MPCResult
from .simulate import Trajectory, simulate

__all__ = ["Certificate", "ContractiveMPC", "MPCResult", "Trajectory", "simulate"]
