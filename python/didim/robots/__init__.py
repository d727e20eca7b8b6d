"""Serial manipulators: the robot (:class:`Robot`, from a URDF), its records (:class:`RobotRecording`), its closed
loop and its identification (IDIM-LS and DIDIM on base parameters, :mod:`didim.robots.identify`)."""

from .chain import BaseParameters, Robot
from .record import RobotRecording, load_joint_controllers
from .identify import PayloadResult, base_parameters, didim, idim_ls, payload, simulate_robot

__all__ = ["Robot", "RobotRecording", "load_joint_controllers", "BaseParameters", "PayloadResult",
           "base_parameters", "didim", "idim_ls", "payload", "simulate_robot"]
