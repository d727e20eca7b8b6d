"""Type stubs of the compiled core (``crates/didim-py``). Use the ``didim`` package, not this module."""

from typing import Any, Dict, List, Literal, Optional, Sequence, Tuple, overload

import numpy as np
import numpy.typing as npt
from typing_extensions import final

DEFAULT_COULOMB_EPS: float
#: The shapes of the Coulomb sign through zero speed: "algebraic", "tanh", "atan", "exp".
COULOMB_LAWS: List[str]
DEFAULT_TOL: float
#: "avx2+fma" or "baseline": the build of the closed loop this processor runs (same results, different speed).
SIMULATOR_BUILD: str
#: The actuation options a Model carries, by name ("delay" in samples, "force_lag" in s).
ACTUATION: List[str]
#: The term kinds: (kind, [(hyper-parameter, SI unit, default or None)], description).
TERM_TABLE: List[Tuple[str, List[Tuple[str, str, Optional[float]]], str]]
#: Older kind names: (alias, kind, [(hyper-parameter, fixed value)]).
TERM_ALIASES: List[Tuple[str, str, List[Tuple[str, float]]]]

_F64 = npt.NDArray[np.float64]

__all__ = [
    "COULOMB_LAWS",
    "DEFAULT_COULOMB_EPS",
    "DEFAULT_TOL",
    "Decimation",
    "Problem",
    "SIMULATOR_BUILD",
    "ACTUATION",
    "Model",
    "Robot",
    "simulate_robot",
    "hold_stop",
    "lfilter",
    "applied_force",
    "TERM_ALIASES",
    "TERM_TABLE",
    "butter",
    "cheby1",
    "decimate",
    "default_factor",
    "filtfilt",
    "lstsq",
    "coulomb_sign",
    "sosfiltfilt",
]

#: Extra terms: (name, kind, dof "motor" or "load", [(hyper-parameter, value), ...]).
_Terms = Optional[Sequence[Tuple[str, str, str, Sequence[Tuple[str, float]]]]]

@final
class Model:
    def __new__(
        cls,
        kind: str,
        *,
        offset: bool = False,
        terms: _Terms = None,
        backlash_gap: Optional[float] = None,
        coulomb_eps: float = ...,
        coulomb_law: str = "algebraic",
        actuation: Optional[Sequence[Tuple[str, float]]] = None,
    ) -> "Model": ...
    @property
    def kind(self) -> str: ...
    @property
    def names(self) -> List[str]: ...
    @property
    def units(self) -> List[str]: ...
    @property
    def roles(self) -> List[str]: ...
    @property
    def ndof(self) -> int: ...
    @property
    def coulomb_eps(self) -> float: ...
    @property
    def actuation(self) -> List[Tuple[str, float]]: ...
    def regressor(self, q: _F64, qd: _F64, qdd: _F64) -> _F64: ...
    def regressor_columns(self, q: _F64, qd: _F64, qdd: _F64, cols: Sequence[int], dof: int) -> _F64: ...
    def decimated_columns(
        self, q: _F64, qd: _F64, qdd: _F64, cols: Sequence[int], dof: int, decimation: Decimation
    ) -> _F64: ...

@final
class Robot:
    @staticmethod
    def from_urdf(text: str, joints: Optional[List[str]] = None) -> "Robot": ...
    def with_inertial_params(self, params: _F64) -> "Robot": ...
    @property
    def name(self) -> str: ...
    @property
    def joint_names(self) -> List[str]: ...
    @property
    def joint_kinds(self) -> List[str]: ...
    @property
    def locked_joints(self) -> List[str]: ...
    @property
    def ndof(self) -> int: ...
    @property
    def param_names(self) -> List[str]: ...
    @property
    def inertial_params(self) -> _F64: ...
    @property
    def limits(self) -> List[Tuple[float, float, float, float]]: ...
    @property
    def gravity_vector(self) -> Tuple[float, float, float]: ...
    def rnea(self, q: _F64, v: _F64, a: _F64) -> _F64: ...
    def rnea_derivatives(self, q: _F64, v: _F64, a: _F64) -> _F64: ...
    def aba_derivatives(self, q: _F64, v: _F64, tau: _F64, armature: Optional[Sequence[float]] = None) -> _F64: ...
    def aba(self, q: _F64, v: _F64, tau: _F64, armature: Optional[Sequence[float]] = None) -> _F64: ...
    def gravity(self, q: _F64) -> _F64: ...
    def mass_matrix(self, q: _F64) -> _F64: ...
    def regressor(
        self, q: _F64, v: _F64, a: _F64, columns: Optional[Sequence[int]] = None, by_joint: bool = False
    ) -> _F64: ...

def simulate_robot(
    robot: Robot,
    armature: Sequence[float],
    viscous: Sequence[float],
    coulomb: Sequence[float],
    offset: Sequence[float],
    controllers: Sequence[Tuple[str, Sequence[float]]],
    qr: _F64,
    dt: float,
    *,
    quantization: Sequence[float],
    force0: Sequence[float],
    substeps: int = 0,
    coulomb_eps: Sequence[float],
    coulomb_law: Sequence[str],
    u_ext: Optional[_F64] = None,
    delay: Optional[Sequence[int]] = None,
    force_lag: Optional[Sequence[float]] = None,
    stiffness: Optional[Sequence[float]] = None,
    damping: Optional[Sequence[float]] = None,
    terms: Optional[Sequence[Sequence[Tuple[str, Sequence[Tuple[str, float]], float]]]] = None,
    load_friction: Optional[Sequence[float]] = None,
    backlash: Optional[Sequence[float]] = None,
    directions: Optional[_F64] = None,
    dforce0: Optional[_F64] = None,
) -> Dict[str, _F64]: ...

def hold_stop(on: bool) -> None: ...
def coulomb_sign(v: _F64, eps: float = ..., law: str = "algebraic") -> _F64: ...
def lstsq(w: _F64, y: _F64, *, rank_tol: Optional[float] = None, sigma: str = "paper") -> Dict[str, Any]: ...
def butter(order: int, wn: float, *, sos: bool = False) -> Any: ...
def cheby1(order: int, rp_db: float, wn: float, *, sos: bool = False) -> Any: ...
def applied_force(force: _F64, delay: int, force_lag: float, dt: float, *, held: float = 0.0) -> _F64: ...
def lfilter(b: Sequence[float], a: Sequence[float], x: _F64, *, zi: Optional[Sequence[float]] = None) -> _F64: ...
def filtfilt(b: Sequence[float], a: Sequence[float], x: _F64, *, padlen: Optional[int] = None) -> _F64: ...
def sosfiltfilt(sos: _F64, x: _F64, *, padlen: Optional[int] = None) -> _F64: ...
def decimate(
    y: _F64,
    w: Optional[_F64] = None,
    *,
    factor: int,
    kind: str = "butter",
    order: int = 4,
    cutoff_hz: Optional[float] = None,
    fs_hz: Optional[float] = None,
    form: str = "sos",
) -> Tuple[_F64, Optional[_F64]]: ...
def default_factor(fs_hz: float, cutoff_hz: float) -> int: ...

@final
class Decimation:
    def __new__(
        cls,
        factor: int,
        *,
        kind: str = "butter",
        order: int = 4,
        cutoff_hz: Optional[float] = None,
        fs_hz: Optional[float] = None,
        form: str = "sos",
    ) -> "Decimation": ...
    def gain(self, f_rel: float) -> float: ...
    def output_len(self, n: int) -> int: ...
    def apply(self, y: _F64, w: Optional[_F64] = None) -> Tuple[_F64, Optional[_F64]]: ...

@final
class Problem:
    def __new__(
        cls,
        model: Model,
        qr: _F64,
        dt: float,
        controller: str,
        gains: Sequence[float],
        *,
        u_ext: Optional[_F64] = None,
        substeps: int = 10,
        quantization: float = 0.0,
        integrator: str = "exponential",
        tol: float = ...,
        lead: int = 0,
    ) -> "Problem": ...
    @property
    def n_params(self) -> int: ...
    @property
    def ndof(self) -> int: ...
    @property
    def n(self) -> int: ...
    def applied_force(self, force: _F64) -> _F64: ...
    def simulate(self, params: _F64) -> Dict[str, _F64]: ...
    def simulate_sensitivity(self, params: _F64) -> Dict[str, _F64]: ...
    def simulate_batch(self, params: _F64, *, states: bool = False) -> Dict[str, Any]: ...
    def squared_error(
        self, params: _F64, measured_dec: _F64, decimator: Decimation, *, output: str = "force", skip: int = 0
    ) -> float: ...
    def squared_error_batch(
        self, params: _F64, measured_dec: _F64, decimator: Decimation, *, output: str = "force", skip: int = 0
    ) -> Tuple[_F64, List[Optional[str]]]: ...
    @overload
    def didim_system(
        self, params: _F64, force: _F64, free: Sequence[int], decimator: Decimation, *, with_q: Literal[False] = ...
    ) -> Tuple[_F64, _F64, _F64]: ...
    @overload
    def didim_system(
        self, params: _F64, force: _F64, free: Sequence[int], decimator: Decimation, *, with_q: Literal[True]
    ) -> Tuple[_F64, _F64, _F64, _F64]: ...
    def linearize(
        self, params: _F64, measured: _F64, free: Sequence[int], decimator: Decimation, *, output: str = "force"
    ) -> Tuple[_F64, _F64]: ...
