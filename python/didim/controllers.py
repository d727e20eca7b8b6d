"""Digital position controllers of the simulated loop (run once per sample, output held).

Both estimate the velocity as the drive of the EMPS does, ``v̂[k] = (q̂[k] − q̂[k−2]) / (2T)``.
Forces are in N on the load side.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Tuple, Union

from ._errors import DataError


def _positive(name: str, value: float, allow_inf: bool = False) -> float:
    raw = value
    try:
        if isinstance(value, (bool, str, bytes, complex)):
            raise TypeError
        value = float(value)
    except (TypeError, ValueError):
        raise DataError(f"controller {name} must be a real number > 0, got {raw!r}") from None
    if math.isnan(value) or value <= 0 or (math.isinf(value) and not allow_inf):
        what = "a number > 0 (math.inf for no saturation)" if allow_inf else "a finite number > 0"
        raise DataError(f"controller {name} must be {what}, got {value}: a zero or negative gain cannot run the loop")
    return value


@dataclass(frozen=True)
class EmpsCascade:
    """The EMPS cascade as logged: ``vir = kv·(kp·(qr − q̂) − v̂)`` in V, saturated at ±vsat, force ``gtau·vir``.

    Attributes: kp (1/s), kv (V/(m/s)), gtau (N/V), vsat (V, ``math.inf`` for none).
    The defaults are the gains of the EMPS benchmark.
    """

    kp: float = 160.18
    kv: float = 243.45
    gtau: float = 35.15065188248547
    vsat: float = 10.0

    kind = "emps"

    def __post_init__(self) -> None:
        for name in ("kp", "kv", "gtau"):
            _positive(name, getattr(self, name))
        _positive("vsat", self.vsat, allow_inf=True)

    @property
    def gains(self) -> Tuple[float, ...]:
        return (self.kp, self.kv, self.gtau, self.vsat)

    @property
    def bandwidth_hz(self) -> float:
        """Approximate position-loop bandwidth, ``kp/(2π)`` (Hz)."""
        return self.kp / (2 * math.pi)


@dataclass(frozen=True)
class PD:
    """A PD in force units, ``τ = kp·(qr − q̂) − kd·v̂``, saturated at ±tau_max.

    Attributes: kp (N/m), kd (N/(m/s)), tau_max (N, ``math.inf`` for none).
    """

    kp: float
    kd: float
    tau_max: float = math.inf

    kind = "pd"

    def __post_init__(self) -> None:
        _positive("kp", self.kp)
        _positive("kd", self.kd)
        _positive("tau_max", self.tau_max, allow_inf=True)

    @property
    def gains(self) -> Tuple[float, ...]:
        return (self.kp, self.kd, self.tau_max)


Controller = Union[EmpsCascade, PD]

__all__ = ["EmpsCascade", "PD", "Controller"]
