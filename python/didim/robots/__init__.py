"""Serial manipulators: the robot (:class:`Robot`, from a URDF), its records (:class:`RobotRecording`), its closed
loop and its identification (IDIM-LS and DIDIM on base parameters, :mod:`didim.robots.identify`)."""

from .chain import Robot
from .record import RobotRecording, load_joint_controllers, load_robot_record
from .identify import BaseParameters, RobotResult, base_parameters, didim, idim_ls, simulate_robot

__all__ = ["Robot", "RobotRecording", "load_joint_controllers", "load_robot_record", "BaseParameters", "RobotResult",
           "base_parameters", "didim", "idim_ls", "simulate_robot"]
