"""Contractive MPC controllers and closed-loop simulation."""

from .contractive import ContractiveMPC, MPCResult
from .quasi import QuasiMultiStepMPC
from .sequence import SetSequenceMPC
from .simulate import Trajectory, simulate

__all__ = ["ContractiveMPC", "MPCResult", "QuasiMultiStepMPC", "SetSequenceMPC", "Trajectory",
           "simulate"]
