"""The controller from the log, when nobody knows it: the linear two-degree-of-freedom law
``u = C_r(z)·qr − C_y(z)·qm`` fitted by least squares on the logged force.

An industrial drive's velocity loop, filters and feedforward are firmware settings nobody wrote down; if the drive
logs the reference, the position and the force command, the linear part of its controller is in the log. With a
common denominator ``A(z)`` (monic, order n) the law is linear in its coefficients,

    A(z)·F[k] = B_r(z)·qr[k − d] − B_y(z)·qm[k − d],

so the coefficients come from one least-squares problem per order n and pure delay d (the equation error), on the
samples whose window holds no saturated force (the law's own output is clipped there, its state is not). The order
and the delay are chosen on held-out samples: the law is replayed from rest on the whole log (as the closed loop
runs it) and compared with the last ``holdout`` share of the force; the smallest order within ``ORDER_MARGIN`` of the
best is kept. A force that no such law explains (a nonlinear feedforward, a measured current rather than the
command) is refused with the numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

from ._errors import DataError
from .check import CHECK_TOLERANCE, mismatch
from .controllers import TransferFunction

#: Orders of the common denominator tried, and pure delays (samples).
MAX_ORDER = 6
DELAYS = (0, 1, 2)
#: The smallest order whose held-out replay error is within this factor of the best (or below the floor) is kept.
ORDER_MARGIN = 1.1
#: A held-out replay error below this share of the force is rounding: every order at or above the law's own fits so.
ROUNDING_FLOOR = 1e-6
#: A force value repeated at the record's extreme on at least this share of the samples is a saturation plateau.
PLATEAU_SHARE = 0.002


@dataclass
class ControllerFit:
    """A controller fitted from a log: ``controller`` (a :class:`TransferFunction` giving the force, gain 1),
    ``order`` and ``delay`` (samples) chosen on held-out samples, ``heldout_error`` (‖F − F_law‖/‖F‖ on them),
    ``error`` on the whole log, ``saturation`` detected (N or N·m; inf when the force never plateaus), and
    ``tried``: (order, delay, held-out error) of every candidate."""

    controller: TransferFunction
    order: int
    delay: int
    heldout_error: float
    error: float
    saturation: float
    tried: List[Tuple[int, int, float]] = field(default_factory=list)

    def summary(self) -> str:
        parts = [f"controller fitted from the log: order {self.order}"
                 + (f", a pure delay of {self.delay} sample{'s' if self.delay > 1 else ''}" if self.delay else ""),
                 "integral action" if _has_integrator(self.controller) else "no integral action",
                 ("the reference and the position enter differently (C_r ≠ C_y: a feedforward, or a derivative on "
                  "the position only)") if _has_feedforward(self.controller) else "C_r = C_y (no feedforward)",
                 (f"saturation ±{self.saturation:.4g}" if math.isfinite(self.saturation) else "no saturation seen"),
                 f"its law gives the logged force within {100 * self.error:.3g} % ({100 * self.heldout_error:.3g} % "
                 "on the held-out samples)"]
        return "; ".join(parts)

    def to_dict(self) -> Dict[str, Any]:
        return {**self.controller.to_dict(), "note": self.summary()}


def _has_integrator(tf: TransferFunction) -> bool:
    return bool(abs(sum(tf.a_y)) < 1e-6 * sum(abs(a) for a in tf.a_y))


def _has_feedforward(tf: TransferFunction) -> bool:
    br, by = np.array(tf.b_r), np.array(tf.b_y)
    return bool(np.linalg.norm(br - by) > 1e-6 * np.linalg.norm(by))


def _plateau(f: np.ndarray) -> float:
    """The saturation level when the force sits at its extreme on a plateau, else inf."""
    top = float(np.max(np.abs(f)))
    if not top > 0:
        return math.inf
    at = np.abs(np.abs(f) - top) <= 1e-9 * top
    return top if np.count_nonzero(at) >= max(3, PLATEAU_SHARE * len(f)) else math.inf


def _lagged(x: np.ndarray, lags: range) -> np.ndarray:
    """Columns x[k − j] for j in lags (the first samples repeat x[0], the law's rest state)."""
    n = len(x)
    out = np.empty((n, len(lags)))
    for c, j in enumerate(lags):
        out[j:, c] = x[:n - j] if j else x
        out[:j, c] = x[0]
    return out


def _fit(qr, qm, f, rows, na, nb, d, integral) -> Optional[Tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Equation-error least squares with a denominator of order ``na``, numerators of ``nb + 1`` taps and a delay of
    ``d`` samples on ``rows``: (b_r, b_y, a) or None. The law is regressed on the tracking error ``qr − qm`` (through
    C_y) and the reference (through the feedforward C_r − C_y): the two positions themselves are nearly the same
    column (the axis tracks its reference), which leaves the least squares ill-conditioned. With ``integral`` the
    denominator holds the integrator ``1 − z⁻¹`` exactly and the feedforward has no gain at rest (a constant reference
    gives a constant command): the law is regressed on the differenced force and reference. Replayed from rest, an
    integrator only estimated (a pole at 1 ± 1e-9) accumulates the least error of the feedforward into a drift."""
    lags = range(d, d + nb + 1)
    diff = (lambda x: np.r_[0.0, np.diff(x)]) if integral else (lambda x: x)
    y_all = diff(f)
    x = np.hstack([_lagged(qr - qm, lags), _lagged(diff(qr), lags), -_lagged(y_all, range(1, na + 1))])[rows]
    y = y_all[rows]
    scale = np.linalg.norm(x, axis=0)
    scale[scale == 0] = 1.0
    try:
        theta, *_ = np.linalg.lstsq(x / scale, y, rcond=None)
    except np.linalg.LinAlgError:
        return None
    theta = theta / scale
    if not np.all(np.isfinite(theta)):
        return None
    k = nb + 1
    pad = np.zeros(d)
    b_y, b_ff, a = theta[:k], theta[k:2 * k], np.r_[1.0, theta[2 * k:]]
    if integral:
        b_ff, a = np.convolve([1.0, -1.0], b_ff), np.convolve([1.0, -1.0], a)
        b_y = np.r_[b_y, 0.0]
    return np.r_[pad, b_ff + b_y], np.r_[pad, b_y], a


def fit_controller(rec_or_signals, *, holdout: float = 0.3, max_order: int = MAX_ORDER,
                   tolerance: float = CHECK_TOLERANCE) -> ControllerFit:
    """The controller of a log (a :class:`didim.Recording`, or a dict with ``dt``, ``qr``, ``qm``, ``force`` and
    optionally ``u_ext``), see the module's text. Raises :class:`DataError` when no linear law of order up to
    ``max_order`` (with a delay up to 2 samples) replays the held-out force within ``tolerance`` (``CHECK_TOLERANCE``
    by default; ``math.inf`` returns the best law whatever it misses)."""
    get = rec_or_signals.get if isinstance(rec_or_signals, dict) else (lambda k: getattr(rec_or_signals, k, None))
    dt = float(get("dt"))
    qr, qm, f = (np.asarray(get(k), dtype=float) for k in ("qr", "qm", "force"))
    u_ext = get("u_ext")
    if u_ext is not None:  # the known input is added to the command: the law explains the rest
        f = f - np.asarray(u_ext, dtype=float)
    n_all = len(f)
    name = get("name") or "record"
    if n_all < 50 * (max_order + 3):
        raise DataError(f"{name}: {n_all} samples are too few to fit a controller of order up to {max_order}")
    if not np.any(np.diff(qr)):
        raise DataError(f"{name}: the reference never moves: the controller's reference path cannot be fitted")
    sat = _plateau(f + (0.0 if u_ext is None else np.asarray(u_ext, dtype=float)))
    clipped = np.abs(f) >= (1 - 1e-9) * sat if math.isfinite(sat) else np.zeros(n_all, bool)
    n_train = int(round(n_all * (1 - holdout)))
    tried: List[Tuple[int, int, float]] = []
    best: Dict[Tuple[int, int, int], Tuple[float, TransferFunction]] = {}
    for n, nb in [(na, na + extra) for na in range(0, max_order + 1) for extra in (0, 1, 2) if na + extra >= 1]:
        # rows whose window (the force's n past samples) holds no clipped sample
        bad = np.convolve(clipped.astype(float), np.ones(n + 1), "full")[:n_all] > 0
        rows = np.flatnonzero(~bad[:n_train])
        rows = rows[rows >= nb + max(DELAYS)]
        if rows.size < 10 * (n + 2 * nb + 2):
            continue
        for d, integral in [(d, i) for d in DELAYS for i in (False, True)]:
            got = _fit(qr, qm, f, rows, n, nb, d, integral)
            if got is None:
                continue
            b_r, b_y, a = got
            if np.any(np.abs(np.roots(a)) > 1 + 1e-6):  # an unstable law is no drive's (an integrator: 1 to rounding)
                continue
            try:
                tf = TransferFunction(tuple(b_r), tuple(a), tuple(b_y), tuple(a), dt, saturation=sat, gain=1.0)
            except DataError:
                continue
            held = np.zeros(n_all, bool)
            held[n_train:] = ~clipped[n_train:]
            with np.errstate(all="ignore"):  # a law that blows up on replay is simply not kept
                err = mismatch(tf, f, tf.command(qr, qm), held)
            if not math.isfinite(err):
                continue
            tried.append((n + integral, d, err))
            best[(n + integral, nb + integral, d)] = min(best.get((n + integral, nb + integral, d), (math.inf, tf)), (err, tf),
                                                         key=lambda t: t[0])
    if not best:
        raise DataError(f"{name}: no stable linear controller of order up to {max_order} could be fitted to the log")
    lowest = min(e for e, _ in best.values())
    ok = sorted(k for k, (e, _) in best.items() if e <= max(ORDER_MARGIN * lowest, ROUNDING_FLOOR))
    n, nb, d = min(ok, key=lambda k: (k[0] + k[1], k[2]))  # the fewest coefficients, then the shortest delay
    err, tf = best[(n, nb, d)]
    if err > tolerance:
        raise DataError(f"{name}: no linear controller u = C_r(z)·qr − C_y(z)·qm of order up to {max_order} (delay up "
                        f"to {max(DELAYS)} samples) replays the logged force: the best misses the held-out samples by "
                        f"{100 * err:.3g} % (at most {100 * tolerance:g} % is accepted). A nonlinear feedforward, "
                        "a force that is a measured current rather than the command, or a controller that changed "
                        "during the log; give the controller (controller=..., CLI: --controller FILE)")
    # on the whole log, past the first samples, whose window reaches before the log (the law's rest state)
    keep = ~clipped
    keep[:len(tf.b_y)] = False
    whole = mismatch(tf, f, tf.command(qr, qm), keep)
    return ControllerFit(tf, n, d, err, whole, sat, tried)


__all__ = ["ControllerFit", "fit_controller"]
