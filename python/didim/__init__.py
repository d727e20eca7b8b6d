"""didim: identify the dynamics of position-controlled drives and flexible-joint axes from the motor force alone.

The DIDIM closed-loop output-error method (Gautier, Jubien, Janot, Robet) on a Rust core: fixed-step closed-loop
simulation, parallel decimation and QR least squares. SI units on the load side everywhere.
"""

from ._errors import DataError, DidimError, DidimWarning, IdentifiabilityError, SimulationError
from .controllers import PD, EmpsCascade, TransferFunction, load_controller, load_joint_controllers
from .recording import Recording
from .formats.loaders import from_dataframe, load_mat, load_record
from .simulation import (DEFAULT_COULOMB_EPS, DEFAULT_TOL, INTEGRATORS, BatchResult, SimResult, coulomb_sign, param_names,
                         simulate_batch)
from .signal import Decimation
from .result import IdentificationResult, compare
from .api import METHODS, identify, simulate
from . import scenarios
from .doctor import Diagnosis, Finding, doctor
from .model import Model, Term
from .robots import Robot
from .result import load_result
from .check import check_controller
from .controller_fit import fit_controller
from .units import Units

__version__ = "0.1.0"

__all__ = [
    "DidimError",
    "DataError",
    "SimulationError",
    "IdentifiabilityError",
    "DidimWarning",
    "EmpsCascade",
    "PD",
    "TransferFunction",
    "load_controller",
    "Recording",
    "Robot",
    "load_joint_controllers",
    "load_mat",
    "from_dataframe",
    "load_record",
    "simulate",
    "simulate_batch",
    "SimResult",
    "BatchResult",
    "INTEGRATORS",
    "DEFAULT_TOL",
    "param_names",
    "coulomb_sign",
    "DEFAULT_COULOMB_EPS",
    "Decimation",
    "IdentificationResult",
    "compare",
    "identify",
    "METHODS",
    "scenarios",
    "doctor",
    "Diagnosis",
    "Finding",
    "Term",
    "Model",
    "load_result",
    "check_controller",
    "fit_controller",
    "Units",
]
