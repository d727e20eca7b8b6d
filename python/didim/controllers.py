"""Digital position controllers of the simulated loop (run once per sample, output held).

Every controller is, for the simulator, the linear two-degree-of-freedom law ``u = C_r(z)·qr − C_y(z)·qm`` of
:class:`TransferFunction`, followed by a saturation of ``u`` and a gain from ``u`` to force. :class:`EmpsCascade` and
:class:`PD` are its named forms (they estimate the velocity as the drive of the EMPS does,
``v̂[k] = (q̂[k] − q̂[k−2]) / (2T)``); :meth:`TransferFunction.cascade` builds the usual industrial cascade (P position
loop, PI velocity loop, feedforward, command filter); :func:`load_controller` reads a controller file (JSON or TOML).
Forces are in N on the load side.
"""

from __future__ import annotations

import json
import math
import os
import warnings
from dataclasses import dataclass, field
from typing import Any, Dict, Mapping, Optional, Tuple, Union

import numpy as np

from . import _checks, _core
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
        why = {"dt": "it is the sample period (s)", "vsat": "it is the command's limit",
               "saturation": "it is the command's limit", "tau_max": "it is the force's limit",
               "notch_q": "it is the notch's quality factor", "f_lp": "it is a cutoff frequency (Hz)",
               "notch_hz": "it is a frequency (Hz)", "ti": "it is the integral time (s)"}.get(
            name, "a zero or negative gain cannot run the loop")
        raise DataError(f"controller {name} must be {what}, got {value}: {why}")
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

    @property
    def force_limit(self) -> float:
        """Saturation of the force command (N), ``gtau·vsat``."""
        return self.gtau * self.vsat

    def transfer_function(self, dt: float) -> "TransferFunction":
        """The cascade as the general law at sample period ``dt`` (s): ``u = vir`` (V), gain ``gtau``."""
        h = 0.5 / _positive("dt", dt)
        return TransferFunction(b_r=(self.kv * self.kp,), a_r=(1.0,), b_y=(self.kv * (self.kp + h), 0.0, -self.kv * h),
                                a_y=(1.0,), dt=dt, saturation=self.vsat, gain=self.gtau)

    def describe(self) -> str:
        return f"EmpsCascade kp = {self.kp:g} 1/s, kv = {self.kv:g} V/(m/s), gtau = {self.gtau:.6g} N/V"

    def to_dict(self) -> Dict[str, Any]:
        return {"type": "emps", "kp": self.kp, "kv": self.kv, "gtau": self.gtau, "vsat": _json_inf(self.vsat)}


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

    @property
    def force_limit(self) -> float:
        """Saturation of the force command (N)."""
        return self.tau_max

    def transfer_function(self, dt: float) -> "TransferFunction":
        """The PD as the general law at sample period ``dt`` (s), ``u`` in N."""
        h = 0.5 / _positive("dt", dt)
        return TransferFunction(b_r=(self.kp,), a_r=(1.0,), b_y=(self.kp + self.kd * h, 0.0, -self.kd * h), a_y=(1.0,),
                                dt=dt, saturation=self.tau_max, gain=1.0)

    def describe(self) -> str:
        return f"PD kp = {self.kp:g} N/m, kd = {self.kd:g} N/(m/s)"

    def to_dict(self) -> Dict[str, Any]:
        return {"type": "pd", "kp": self.kp, "kd": self.kd, "tau_max": _json_inf(self.tau_max)}




def _json_inf(x: float):
    return None if math.isinf(x) else x


def _coefficients(name: str, value) -> Tuple[float, ...]:
    if value is None or isinstance(value, (str, bytes)) or np.iscomplexobj(value):
        raise DataError(f"controller coefficients {name} must be a list of real numbers, got {value!r}")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # e.g. numpy's ComplexWarning for complex objects
            a = np.asarray(value, dtype=float)
    except (TypeError, ValueError, OverflowError, Warning):
        raise DataError(f"controller coefficients {name} must be a list of numbers, got {value!r}") from None
    if a.ndim == 0:
        a = a.reshape(1)
    if a.ndim != 1 or a.size == 0:
        raise DataError(f"controller coefficients {name} must be a non-empty list of numbers, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise DataError(f"controller coefficients {name} must be finite, got {a.tolist()}")
    return tuple(float(x) for x in a)


#: Most coefficients of a polynomial once C_r and C_y are over a common denominator (the core's limit).
MAX_TAPS = 16


@dataclass(frozen=True)
class TransferFunction:
    """The linear two-degree-of-freedom digital controller ``u = C_r(z)·qr − C_y(z)·qm``.

    ``C_r = b_r/a_r`` and ``C_y = b_y/a_y`` have their coefficients in ascending powers of ``1/z`` (the convention of
    ``scipy.signal.lfilter``), for the sample period ``dt`` (s), which must be the record's. The force is
    ``gain·v`` (N) with ``v = u + u_ext/gain`` limited to ``±saturation`` (``math.inf`` for none); ``u`` is in the
    drive's unit (V, A, or N with ``gain = 1``). The filters start at rest: constant inputs since forever and, with
    integral action, zero command.

    Build one from coefficients, from :meth:`cascade`, :meth:`from_lti` (``scipy.signal.dlti`` or python-control's
    discrete ``TransferFunction``), or a controller file (:func:`load_controller`).
    """

    b_r: Tuple[float, ...]
    a_r: Tuple[float, ...]
    b_y: Tuple[float, ...]
    a_y: Tuple[float, ...]
    dt: float
    saturation: float = math.inf
    gain: float = 1.0
    #: The cascade's settings when built by :meth:`cascade` (kp, kv, ti, ...), as (name, value) pairs: what a user
    #: described, which the controller check (:mod:`didim.check`) varies to name a likely mistake.
    design: Optional[Tuple[Tuple[str, Any], ...]] = field(default=None, compare=False, repr=False)

    kind = "tf"

    def __post_init__(self) -> None:
        for name in ("b_r", "a_r", "b_y", "a_y"):
            object.__setattr__(self, name, _coefficients(name, getattr(self, name)))
        for name in ("a_r", "a_y"):
            if getattr(self, name)[0] == 0.0:
                raise DataError(f"controller denominator {name} starts with 0: its first coefficient (of z^0) must be "
                                "non-zero (coefficients are in ascending powers of 1/z)")
        object.__setattr__(self, "dt", _positive("dt", self.dt))
        object.__setattr__(self, "saturation", _positive("saturation", self.saturation, allow_inf=True))
        object.__setattr__(self, "gain", _positive("gain", self.gain))
        if not any(self.b_y):
            raise DataError("controller b_y is all zero: the measured position does not enter the command, so the loop "
                            "is open and cannot be simulated; give the feedback path C_y")
        order = max(len(self.b_r), len(self.a_r), len(self.b_y), len(self.a_y))
        if self.a_r != self.a_y:
            order = max(len(self.b_r) + len(self.a_y), len(self.b_y) + len(self.a_r), len(self.a_r) + len(self.a_y)) - 1
        if order > MAX_TAPS:
            raise DataError(f"the controller has {order} coefficients over the common denominator of C_r and C_y; at most "
                            f"{MAX_TAPS} are supported (order {MAX_TAPS - 1})")

    @property
    def gains(self) -> Tuple[float, ...]:
        """The core's packed form: saturation, gain, the four lengths, then the coefficients."""
        parts = (self.b_r, self.a_r, self.b_y, self.a_y)
        return (self.saturation, self.gain, *(float(len(p)) for p in parts), *(x for p in parts for x in p))

    @property
    def force_limit(self) -> float:
        """Saturation of the force command (N), ``gain·saturation``."""
        return self.gain * self.saturation

    def transfer_function(self, dt: float) -> "TransferFunction":
        if not math.isclose(dt, self.dt, rel_tol=1e-9):
            ms = " (is the record's time column in milliseconds read as seconds?)" if math.isclose(
                dt / self.dt, 1000.0, rel_tol=1e-6) else ""
            raise DataError(f"the controller is designed for a sample period of {self.dt:g} s but the record's is {dt:g} s"
                            f"{ms}: give the coefficients for the record's sample period")
        return self

    def describe(self) -> str:
        return (f"TransferFunction (order {max(len(self.a_r), len(self.a_y)) - 1} denominators, dt = {self.dt:g} s, "
                f"gain = {self.gain:.6g}, saturation = {self.saturation:g})")

    def to_dict(self) -> Dict[str, Any]:
        return {"type": "transfer_function", "dt": self.dt, "b_r": list(self.b_r), "a_r": list(self.a_r),
                "b_y": list(self.b_y), "a_y": list(self.a_y), "saturation": _json_inf(self.saturation),
                "gain": self.gain}

    def command(self, qr: np.ndarray, qm: np.ndarray, u_ext: Optional[np.ndarray] = None) -> np.ndarray:
        """The force (N) this law computes from logged ``qr`` and ``qm`` (and ``u_ext``), from rest, saturated."""
        qr = np.asarray(qr, dtype=float)
        qm = np.asarray(qm, dtype=float)
        # each branch on its own denominator (their product would hold an integrator twice, and a double pole at 1
        # turns rounding into a ramp: 0.2 % of a robot joint's force after 20 s), on the positions' departures from
        # the first reference (large absolute positions times large gains cancel digits), each from the core's rest
        # state (constant input since forever and, where the denominator integrates, zero output); a branch that
        # does not integrate adds back its static gain times that reference, so the law is unchanged
        x0 = float(qr[0]) if len(qr) else 0.0

        def run(num: np.ndarray, den: np.ndarray, x: np.ndarray) -> np.ndarray:
            n = max(len(num), len(den))
            num, den = (np.pad(c, (0, n - len(c))) / den[0] for c in (num, den))
            integrates = abs(den.sum()) <= 1e-12 * np.abs(den).sum()
            u0 = 0.0 if integrates else num.sum() * x[0] / den.sum()
            zi = np.array([(num[i + 1:] * x[0] - den[i + 1:] * u0).sum() for i in range(n - 1)])
            out = _core.lfilter(num, den, np.ascontiguousarray(x, dtype=float), zi=list(zi)) if n > 1 else num[0] * x / den[0]
            return out if integrates else out + num.sum() / den.sum() * x0

        with np.errstate(all="ignore"):
            u = run(np.array(self.b_r), np.array(self.a_r), qr - x0) - run(np.array(self.b_y), np.array(self.a_y), qm - x0)
            v = u + (0.0 if u_ext is None else np.asarray(u_ext, dtype=float) / self.gain)
            return self.gain * np.clip(v, -self.saturation, self.saturation)

    @classmethod
    def cascade(cls, *, kp: float, kv: float, dt: float, ti: Optional[float] = None, kff: float = 0.0,
                kaff: float = 0.0, f_lp: Optional[float] = None, notch_hz: Optional[float] = None,
                notch_q: float = 2.0, gain: float = 1.0, saturation: float = math.inf) -> "TransferFunction":
        """The usual industrial cascade, discretized at ``dt`` (s):

        ``u = F(z)·[kv·PI(z)·(kp·(qr − qm) + kff·D(z)·qr − D(z)·qm) + kaff·D(z)²·qr]``

        with the backward-difference velocity ``D(z) = (1 − z⁻¹)/T``, the PI ``1 + T/(ti·(1 − z⁻¹))`` (no integral
        action when ``ti`` is None), and the command filter ``F``: a first-order low-pass ``(1 − p)/(1 − p·z⁻¹)``,
        ``p = exp(−2π·f_lp·T)``, when ``f_lp`` (Hz) is given, times a notch at ``notch_hz`` (Hz, quality
        ``notch_q``, ``scipy.signal.iirnotch``) when given. Units: kp in 1/s, kv in u per (m/s), ti in s, kff without
        unit (1 = full velocity feedforward), kaff in u per (m/s²); the force is ``gain·u`` (N), limited to
        ``±gain·saturation``.
        """
        _positive("notch_q", notch_q)
        dt = _positive("dt", dt)
        kp, kv = _positive("kp", kp), _positive("kv", kv)
        for name, value in (("kff", kff), ("kaff", kaff)):
            _checks.real(f"controller {name}", value, lo=0.0, lo_open=False)
        d = np.array([1.0, -1.0]) / dt
        one = np.array([1.0])
        if ti is None:
            pi_b, pi_a = one, one
        else:
            ti = _positive("ti", ti)
            pi_b, pi_a = np.array([1.0 + dt / ti, -1.0]), np.array([1.0, -1.0])
        f_b, f_a = one, one
        if f_lp is not None:
            f_lp = _positive("f_lp", f_lp)
            p = math.exp(-2 * math.pi * f_lp * dt)
            f_b, f_a = np.array([1.0 - p]), np.array([1.0, -p])
        if notch_hz is not None:
            from scipy.signal import iirnotch

            notch_hz = _positive("notch_hz", notch_hz)
            if notch_hz >= 0.5 / dt:
                raise DataError(f"notch_hz = {notch_hz:g} Hz is at or above the Nyquist frequency {0.5 / dt:g} Hz")
            nb, na = iirnotch(notch_hz, _positive("notch_q", notch_q), fs=1.0 / dt)
            f_b, f_a = np.convolve(f_b, nb), np.convolve(f_a, na)
        # kv·PI·(kp + kff·D) on qr plus kaff·D² over the PI's denominator; kv·PI·(kp + D) on qm
        loop_r = kv * np.convolve(pi_b, _padd(kp * one, kff * d))
        b_r = _padd(loop_r, kaff * np.convolve(np.convolve(d, d), pi_a)) if kaff else loop_r
        b_y = kv * np.convolve(pi_b, _padd(kp * one, d))
        den = np.convolve(pi_a, f_a)
        design = dict(kp=kp, kv=kv, dt=dt, ti=ti, kff=kff, kaff=kaff, f_lp=f_lp, notch_hz=notch_hz, notch_q=notch_q,
                      gain=gain, saturation=saturation)
        return cls(b_r=tuple(np.convolve(b_r, f_b)), a_r=tuple(den), b_y=tuple(np.convolve(b_y, f_b)), a_y=tuple(den),
                   dt=dt, saturation=saturation, gain=gain, design=tuple(design.items()))

    @classmethod
    def from_lti(cls, c_r, c_y, *, dt: Optional[float] = None, gain: float = 1.0,
                 saturation: float = math.inf) -> "TransferFunction":
        """From two discrete systems: ``scipy.signal.dlti`` (or its ``TransferFunction``) or python-control's
        discrete ``TransferFunction``, numerator and denominator in powers of ``z``. Their sample periods must agree
        (and with ``dt`` when given)."""
        (b_r, a_r, dt_r), (b_y, a_y, dt_y) = _lti("C_r", c_r), _lti("C_y", c_y)
        periods = [x for x in (dt_r, dt_y, dt) if x is not None]
        if not periods:
            raise DataError("the systems carry no sample period: give dt")
        if any(not math.isclose(x, periods[0], rel_tol=1e-9) for x in periods):
            raise DataError(f"the sample periods disagree: C_r {dt_r}, C_y {dt_y}, dt {dt}")
        return cls(b_r=b_r, a_r=a_r, b_y=b_y, a_y=a_y, dt=periods[0], gain=gain, saturation=saturation)


def _padd(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Sum of two polynomials in 1/z of different lengths."""
    out = np.zeros(max(len(a), len(b)))
    out[: len(a)] += a
    out[: len(b)] += b
    return out


def _lti(name: str, sys) -> Tuple[Tuple[float, ...], Tuple[float, ...], Optional[float]]:
    """(b, a) in ascending powers of 1/z and the sample period of a discrete SISO system."""
    num, den = getattr(sys, "num", None), getattr(sys, "den", None)
    if num is None or den is None:
        tf = getattr(sys, "to_tf", None)
        if tf is None:
            raise DataError(f"{name} must be a scipy.signal.dlti or a python-control TransferFunction, "
                            f"got {type(sys).__name__}")
        sys = tf()
        num, den = sys.num, sys.den
    num, den = np.asarray(num, dtype=object), np.asarray(den, dtype=object)
    while num.ndim > 1 or (num.ndim == 1 and num.size == 1 and np.ndim(num[0]) > 0):  # python-control: [[array]]
        num, den = np.asarray(num[0], dtype=object), np.asarray(den[0], dtype=object)
    num, den = np.asarray(num, dtype=float).ravel(), np.asarray(den, dtype=float).ravel()
    num, den = np.trim_zeros(num, "f"), np.trim_zeros(den, "f")
    if den.size == 0:
        raise DataError(f"{name} has a zero denominator")
    if num.size > den.size:
        raise DataError(f"{name} is not causal: its numerator has a higher degree in z than its denominator")
    dt = getattr(sys, "dt", None)
    if dt is None or dt is True or dt == 0:
        if dt == 0:
            raise DataError(f"{name} is a continuous-time system: discretize it first (e.g. scipy.signal.cont2discrete)")
        dt = None
    # divide numerator and denominator by z^deg(den): coefficients in ascending powers of 1/z
    b = np.concatenate([np.zeros(den.size - num.size), num]) if num.size else np.zeros(1)
    return tuple(b), tuple(den), (float(dt) if dt is not None else None)


Controller = Union[EmpsCascade, PD, TransferFunction]

#: Keys of each controller type in a controller file.
_FILE_TYPES = {
    "transfer_function": ("dt", "b_r", "a_r", "b_y", "a_y", "saturation", "gain"),
    "emps": ("kp", "kv", "gtau", "vsat"),
    "pd": ("kp", "kd", "tau_max"),
    "cascade": ("kp", "kv", "dt", "ti", "kff", "kaff", "f_lp", "notch_hz", "notch_q", "gain", "saturation"),
}


def controller_from_dict(spec: Dict[str, Any], where: str = "controller") -> Controller:
    """A controller from its dictionary form (a controller file's content): ``type`` is ``transfer_function``,
    ``emps``, ``pd`` or ``cascade``, the other keys are the constructor's (``null`` saturation: none; keys starting
    with ``note`` or ``_`` are comments)."""
    if not isinstance(spec, dict):
        raise DataError(f"{where}: a controller is an object with a \"type\" key, got {type(spec).__name__}")
    kind = spec.get("type")
    if kind == "joints":
        raise DataError(f"{where}: a robot's controller file (one controller per joint) where one axis's controller is "
                        "expected: for a robot's record give its URDF too (CLI: --urdf ROBOT.urdf; Python: "
                        "didim.load_record(path, robot=didim.Robot.from_urdf(...)))")
    if not isinstance(kind, str) or kind not in _FILE_TYPES:
        raise DataError(f"{where}: \"type\" must be one of {', '.join(_FILE_TYPES)}, got {kind!r}")
    allowed = _FILE_TYPES[kind]
    # "units" belongs to the record the controller ran (read by the loaders: didim.units); a robot joint's "delay"
    # and "force_lag" to its drive (read by didim.load_joint_controllers)
    args = {k: v for k, v in spec.items() if k not in ("type", "units", "delay", "force_lag")
            and not k.startswith(("note", "_", "comment"))}
    unknown = sorted(set(args) - set(allowed))
    if unknown:
        raise DataError(f"{where}: unknown key(s) {', '.join(unknown)} for a {kind} controller; it takes "
                        f"{', '.join(allowed)}")
    for key in ("saturation", "vsat", "tau_max"):
        if key in args and args[key] is None:
            args[key] = math.inf
    try:
        if kind == "transfer_function":
            missing = [k for k in ("dt", "b_r", "a_r", "b_y", "a_y") if k not in args]
            if missing:
                raise DataError(f"{where}: a transfer_function controller needs {', '.join(missing)}")
            return TransferFunction(**args)
        if kind == "emps":
            return EmpsCascade(**args)
        if kind == "pd":
            return PD(**args)
        return TransferFunction.cascade(**args)
    except TypeError as e:
        raise DataError(f"{where}: {e}") from None
    except DataError as e:  # a field's own check: say which file (and joint) holds it
        if where == "controller" or str(e).startswith(where):
            raise
        raise DataError(f"{where}: {e}") from None


def in_units(c: Controller, dt: float, position_factor: float, force_factor: float) -> Controller:
    """The controller ``c`` (designed on positions and a force in a record's own units) acting on SI positions and
    giving an SI force: with ``q_SI = position_factor·q`` and ``F_SI = force_factor·F``, ``C_r`` and ``C_y`` are
    divided by ``position_factor`` and the gain multiplied by ``force_factor``; the same law, the same command."""
    if position_factor == 1.0 and force_factor == 1.0:
        return c
    tf = c.transfer_function(dt)
    if tf.design is not None:  # the cascade's own settings in SI: kv and kaff per (m/s), (m/s²); the force gain
        d = dict(tf.design)
        d.update(kv=d["kv"] / position_factor, kaff=d["kaff"] / position_factor, gain=d["gain"] * force_factor)
        return TransferFunction.cascade(**d)
    return TransferFunction(tuple(b / position_factor for b in tf.b_r), tf.a_r, tuple(b / position_factor for b in tf.b_y),
                            tf.a_y, tf.dt, tf.saturation, tf.gain * force_factor)


def _spec(path) -> Any:
    from .formats._io import check_input

    if isinstance(path, Mapping):  # a controller file's content, given in Python
        return "the controllers' mapping", dict(path)
    p = check_input(path, "controller file")
    ext = os.path.splitext(str(p))[1].lower()
    try:
        with open(p, "rb") as f:
            raw = f.read()
        if ext == ".toml":
            import tomllib

            return p, tomllib.loads(raw.decode("utf-8"))
        return p, json.loads(raw.decode("utf-8"))
    except RecursionError:
        raise DataError(f"{p}: not a controller file (nested too deeply)") from None
    except (UnicodeDecodeError, ValueError) as e:
        kind = "TOML" if ext == ".toml" else "JSON"
        raise DataError(f"{p}: not a readable {kind} controller file ({e}); it should hold an object like "
                        '{"type": "transfer_function", "dt": ..., "b_r": [...], "a_r": [...], "b_y": [...], '
                        '"a_y": [...], "saturation": ..., "gain": ...}') from None


def controller_file_units(path: Union[str, "os.PathLike[str]"]):
    """The ``"units"`` a controller file declares for its record (:func:`didim.units.parse`), or None."""
    from .units import parse

    p, spec = _spec(path)
    if not isinstance(spec, dict) or spec.get("units") is None:
        return None
    try:
        return parse(spec["units"])
    except DataError as e:
        raise DataError(f"{p}: {e}") from None


def load_controller(path: Union[str, "os.PathLike[str]"]) -> Controller:
    """A controller from a JSON (``.json``) or TOML (``.toml``) file with the fields of :func:`controller_from_dict`,
    e.g. ``{"type": "transfer_function", "dt": 0.001, "b_r": [...], "a_r": [...], "b_y": [...], "a_y": [...],
    "saturation": 10, "gain": 35.15}``; an optional ``"units"`` (``"deg"``, ``{"position": "counts", "counts_per":
    1048576, "per": "rev"}``) says what units its record's positions and force are in (:mod:`didim.units`)."""
    p, spec = _spec(path)
    return controller_from_dict(spec, str(p))


def load_joint_controllers(path) -> Tuple[Controller, ...]:
    """One controller per joint from a JSON or TOML file ``{"type": "joints", "joints": [c_1, ..., c_n]}`` whose
    entries are single-axis controllers (:func:`didim.load_controller`'s form), in the robot's joint order."""
    p, spec = _spec(path)
    if not isinstance(spec, dict) or spec.get("type") != "joints" or not isinstance(spec.get("joints"), list):
        raise DataError(f"{p}: a robot's controller file is {{\"type\": \"joints\", \"joints\": [one controller per "
                        f"joint]}}, got type {spec.get('type') if isinstance(spec, dict) else type(spec).__name__!r}")
    if not spec["joints"]:
        raise DataError(f"{p}: \"joints\" is empty: give one controller per joint")
    return tuple(controller_from_dict(c, f"{p}: joint {i + 1}") for i, c in enumerate(spec["joints"]))


def load_joint_drives(path) -> Tuple[Tuple[int, ...], Tuple[float, ...]]:
    """Each joint's actuation delay (samples) and force lag (s) from the entries of a robot's controller file
    (``"delay"``, ``"force_lag"``; 0 where absent): the drive between the controller's command and the force on the
    joint, which the closed loop simulates and the least squares regress on (:func:`applied_force`)."""
    from . import _checks

    p, spec = _spec(path)
    entries = spec.get("joints") if isinstance(spec, dict) and isinstance(spec.get("joints"), list) else []
    delay, lag = [], []
    for i, e in enumerate(entries):
        e = e if isinstance(e, dict) else {}
        delay.append(_checks.whole(f"{p}: joint {i + 1}'s delay", e.get("delay", 0), hint=" (samples)"))
        lag.append(_checks.real(f"{p}: joint {i + 1}'s force_lag", e.get("force_lag", 0.0), "s", lo=0.0,
                                lo_open=False))
    return tuple(delay), tuple(lag)



__all__ = ["EmpsCascade", "PD", "TransferFunction", "Controller", "load_controller", "controller_from_dict", "in_units",
           "controller_file_units", "load_joint_controllers", "load_joint_drives"]
