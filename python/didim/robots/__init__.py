"""Serial manipulators: the robot (:class:`Robot`, from a URDF), its records (:class:`RobotRecording`), its closed
loop and its identification (IDIM-LS and DIDIM on base parameters, :mod:`didim.robots.identify`)."""

from .chain import Robot
from .record import RobotRecording, load_joint_controllers
from .identify import BaseParameters, PayloadResult, RobotResult, base_parameters, didim, idim_ls, payload, simulate_robot

__all__ = ["Robot", "RobotRecording", "load_joint_controllers", "BaseParameters", "PayloadResult", "RobotResult",
           "base_parameters", "didim", "idim_ls", "payload", "simulate_robot"]
