"""Serial manipulators: the robot (:class:`Robot`, from a URDF; its records are :class:`didim.Recording` with joint
columns), its closed loop and its identification (IDIM-LS and DIDIM on base parameters, :mod:`didim.methods.robot`)."""

from .chain import BaseParameters, Robot
from ..methods.robot import PayloadResult, base_parameters, didim, idim_ls, payload, simulate_robot

__all__ = ["Robot", "BaseParameters", "PayloadResult",
           "base_parameters", "didim", "idim_ls", "payload", "simulate_robot"]
