"""Validation of options and parameters at the entry points, with messages that say what was wrong and what to do.

Every check raises :class:`DataError` (bad input) or :class:`IdentifiabilityError` (nothing to identify), never a
bare ``ValueError``/``TypeError`` from deep inside numpy or the core.
"""

from __future__ import annotations

import functools
import inspect
import math
import numbers
import warnings
from typing import Callable, Dict, Iterable, Mapping, Optional, Sequence

import numpy as np

from ._errors import DataError, IdentifiabilityError


def real_array(name: str, x, ndims: Optional[Sequence[int]] = (1,)) -> np.ndarray:
    """``x`` as a float64 array with one of the dimensions ``ndims`` (None: any), or a DataError saying what it is
    instead."""
    if x is None:
        raise DataError(f"{name} is missing (None)")
    if isinstance(x, (str, bytes)):
        raise DataError(f"{name} must be an array of real numbers, got a string")
    if np.iscomplexobj(x):
        raise DataError(f"{name} has complex values: it must be real")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            a = np.asarray(x, dtype=float)
    except (TypeError, ValueError, OverflowError, Warning) as e:
        raise DataError(f"{name} must be an array of real numbers: {e}") from None
    if ndims is not None and a.ndim not in ndims:
        want = " or ".join(f"{d}-D" for d in ndims)
        raise DataError(f"{name} must be a {want} array, got shape {a.shape}")
    return a


def whole(name: str, value, *, lo: int = 0, hi: Optional[int] = None, hint: str = "") -> int:
    """An integer option within [lo, hi]."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Integral, np.integer)):
        raise DataError(f"{name} must be a whole number, got {value!r}{hint}")
    v = int(value)
    if hi is None:
        hi_cap = 2**63 - 1  # the core's integers are 64-bit: a larger value is refused here, not by an overflow
        if v > hi_cap:
            raise DataError(f"{name} must be at most {hi_cap}, got {v}{hint}")
    if v < lo or (hi is not None and v > hi):
        rng = f">= {lo}" if hi is None else f"between {lo} and {hi}"
        raise DataError(f"{name} must be {rng}, got {v}{hint}")
    return v


def real(name: str, value, unit: str = "", *, lo: Optional[float] = None, lo_open: bool = True,
         hi: Optional[float] = None, hi_open: bool = True, hint: str = "") -> float:
    """A finite real option, optionally bounded (open bounds by default)."""
    u = f" {unit}" if unit else ""
    if type(value) is float:  # the common case, without the abstract-class checks (a few µs per simulation)
        pass
    elif isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Real, np.floating, np.integer)):
        raise DataError(f"{name} must be a real number{u}, got {value!r}{hint}")
    v = float(value)
    bad = not math.isfinite(v)
    if lo is not None:
        bad = bad or (v <= lo if lo_open else v < lo)
    if hi is not None:
        bad = bad or (v >= hi if hi_open else v > hi)
    if bad:
        parts = []
        if lo is not None:
            parts.append(f"{'>' if lo_open else '>='} {lo:g}")
        if hi is not None:
            parts.append(f"{'<' if hi_open else '<='} {hi:g}")
        cond = " and ".join(f"{c}{u}" for c in parts)
        raise DataError(f"{name} must be a finite number{' ' + cond if cond else u and ' (' + unit + ')'}, got {value!r}{hint}")
    return v


def flag(name: str, value) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise DataError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def one_of(name: str, value, choices: Sequence[str]) -> str:
    if not isinstance(value, str) or value not in choices:
        raise DataError(f"{name} must be one of {', '.join(map(repr, choices))}, got {value!r}")
    return value


@functools.lru_cache(maxsize=None)
def _keyword_only(f: Callable) -> tuple:
    """The keyword-only parameters of ``f`` (read once per function: ``inspect.signature`` costs tens of µs, and the
    simulator checks its options on every call)."""
    return tuple(k for k, p in inspect.signature(f).parameters.items() if p.kind == p.KEYWORD_ONLY)


def known_options(funcs: Sequence[Callable], options: Mapping, where: str, skip: Iterable[str] = (),
                  also: Sequence[str] = ()) -> None:
    """Refuses keyword options that none of ``funcs`` takes (the functions an entry point forwards its options to),
    listing the ones they do (and ``also``, the entry point's own keywords) and suggesting the nearest name."""
    import difflib

    skip = set(skip)
    accepted = list(also)
    for f in funcs:
        for k in _keyword_only(f):
            if k not in skip and k not in accepted:
                accepted.append(k)
    unknown = [k for k in options if k not in accepted]
    if unknown:
        lower = {a.lower(): a for a in accepted}
        hints = []
        for k in unknown:
            near = ([lower[str(k).lower()]] if str(k).lower() in lower
                    else difflib.get_close_matches(str(k), accepted, n=1, cutoff=0.75))
            if near:
                hints.append(f"{k!r}: did you mean {near[0]!r}?")
        raise DataError(
            f"unknown option(s) {', '.join(map(repr, unknown))} for {where}"
            + (f" ({'; '.join(hints)})" if hints else "")
            + f"; it accepts {', '.join(accepted) or 'none'}"
        )


_SUBSTEPS_HINT = "; the simulator integrates each sample period in this many RK4 substeps (default 10)"
_RULES: Dict[str, Callable] = {
    "tol": lambda v: real("tol", v, lo=0.0, hint=" (relative tolerance of the stopping criterion)"),
    "max_iter": lambda v: whole("max_iter", v, lo=1),
    "substeps": lambda v: whole("substeps", v, lo=1, hi=100_000, hint=_SUBSTEPS_HINT),
    "coulomb_eps": lambda v: None if v is None else real("coulomb_eps", v, "m/s", lo=0.0, lo_open=False,
                                                         hint=" (0 for the hard sign, None for the record's)"),
    "divergence_factor": lambda v: real("divergence_factor", v, lo=1.0, lo_open=False),
    "xatol": lambda v: real("xatol", v, lo=0.0),
    "fatol": lambda v: real("fatol", v, lo=0.0),
    "cutoff_hz": lambda v: real("cutoff_hz", v, "Hz", lo=0.0),
    "rigid_cutoff_hz": lambda v: real("rigid_cutoff_hz", v, "Hz", lo=0.0),
    "lowpass_hz": lambda v: real("lowpass_hz", v, "Hz", lo=0.0),
    "lowpass_order": lambda v: whole("lowpass_order", v, lo=1, hi=20),
    "lambda0": lambda v: real("lambda0 (mass ratio M1/M_tot)", v, lo=0.0, hi=1.0),
    "f0": lambda v: real("f0 (initial f_n_flex)", v, "Hz", lo=0.0),
    "border": lambda v: whole("border", v, lo=0),
    "zoh_align": lambda v: flag("zoh_align", v),
}


def options(**kw) -> None:
    """Checks the common numerical options by name (tol, max_iter, substeps, coulomb_eps, cutoffs, ...)."""
    for k, v in kw.items():
        if v is not None:
            _RULES[k](v)


def is_option(name: str) -> bool:
    """Whether :func:`options` has a rule for ``name``."""
    return name in _RULES


#: Parameters whose value must be strictly positive for a simulation: masses (kg) and stiffness (N/m).
_POSITIVE = {"M": "mass", "M1": "mass", "M2": "mass", "K12": "stiffness"}
_UNIT = {"mass": "kg", "stiffness": "N/m"}


def physical(params: Mapping[str, float], where: str) -> Dict[str, float]:
    """Finite values, positive masses and stiffness; returns them as floats."""
    if not isinstance(params, Mapping):
        raise DataError(f"{where} must be a mapping name -> value, got {type(params).__name__}")
    out = {}
    for k, v in params.items():
        kind = _POSITIVE.get(k)
        if kind is not None:
            out[k] = real(f"{where}: {kind} {k}", v, _UNIT[kind], lo=0.0,
                          hint=f"; a {kind} must be positive (check the sign and the units)")
        else:
            out[k] = real(f"{where}: {k}", v)
    return out


def excitation(qr: np.ndarray, u_ext: Optional[np.ndarray], names: Sequence[str]) -> None:
    """Raises IdentifiabilityError when the record excites nothing: a constant reference and no external input."""
    if np.ptp(qr) > 0 or (u_ext is not None and np.ptp(u_ext) > 0):
        return
    why = {
        "M": "needs accelerations", "M1": "needs accelerations", "M2": "needs accelerations",
        "Fv": "needs velocities", "Fv1": "needs velocities", "Fv2": "needs velocities",
        "Fc": "needs motion in both directions", "Fc1": "needs motion in both directions",
        "Fc2": "needs motion in both directions", "K12": "needs the spring to be loaded by accelerations",
    }
    moving = [f"{n} ({why[n]})" for n in names if n in why]
    others = [n for n in names if n not in why]
    raise IdentifiabilityError(
        f"nothing is excited: the reference qr is constant ({float(qr[0]):g} m) and there is no external input, so "
        "the axis is never asked to move and the regressor has no motion in it. "
        f"Cannot be identified: {', '.join(moving)}"
        + (f"; {', '.join(others)} alone would only be the mean force" if others else "")
        + ". Record the axis following a reference that moves (back and forth, at several speeds and accelerations)"
    )


def measured_signal(name: str, norm: float, what: str) -> None:
    """The (decimated) measured signal a method fits must be neither zero nor beyond float range."""
    if norm == 0:
        raise DataError(
            f"the measured {name} is zero throughout (after the decimation of {what}): there is nothing to fit; "
            "check that the right variable was loaded as the force"
        )
    if not math.isfinite(norm):
        raise DataError(
            f"the measured {name} is too large to fit (its norm overflows): check its units (N on the load side, m)"
        )


def record_long_enough(dec, n: int, dt: float, n_params: int, blocks: int, what: str,
                       of: str = "parameters") -> None:
    """The decimation filter needs more samples than its padding, and the decimated system more rows than
    parameters; raises a DataError about the record (not about an internal array) saying how long it must be."""

    def rows(k: int) -> int:
        try:
            return len(dec(np.zeros(k))) * blocks
        except DataError:
            return -1

    m = rows(n)
    if m > n_params:
        return
    # the decimated rows alone need factor·(n_params // blocks) + 1 samples; the filter's padding may need more
    need = max(n + 1, 2, dec.factor * (n_params // blocks) + 1)
    if need <= 16 * n + 4096:  # search the shortest length that works (few doublings, then a bisection) on
        lo = n                 # small arrays only: a huge decimation factor is answered by the bound above
        while rows(need) <= n_params and need <= 64 * n + 16384:
            lo, need = need, need * 2
        while need - lo > 1:
            mid = (lo + need) // 2
            lo, need = (lo, mid) if rows(mid) > n_params else (mid, need)
    why = ("shorter than the decimation filter's zero-phase padding" if m < 0
           else f"decimated by {dec.factor}, it leaves {m} equations for {n_params} {of}")
    raise DataError(
        f"the record is too short for {what}: {n} samples ({n * dt:.4g} s), {why}; it needs at least {need} samples "
        f"({need * dt:.4g} s) with the decimation {dec.describe()}: record longer, or raise cutoff_hz (less "
        "decimation)"
    )


__all__ = ["real_array", "whole", "real", "flag", "one_of", "options", "known_options", "physical", "excitation", "measured_signal", "record_long_enough"]
