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
from typing import Any, Dict, List, Optional, Tuple, Union

import numpy as np

from . import _core
from ._errors import DataError
from .controllers import TransferFunction


#: When no linear law can be fitted from the log to judge by (too short a record), a described controller is refused
#: when its law misses the logged force by more than this share of it (RMS, on the unsaturated samples). It is also the
#: most that a controller fitted from a log may miss (:func:`didim.fit_controller`). A right description replays the
#: log to rounding (0.0 % on the truthbench's drive records, at most 0.3 % on the EMPS, whose force is the logged
#: command); the usual mistakes miss it by 84–285 %.
CHECK_TOLERANCE = 0.05


def free_responses(tf: TransferFunction, n: int) -> np.ndarray:
    """The law's free responses (n × order): what its state at the first sample adds to the command. A log that
    begins with the loop already running starts the law in a state the log does not hold (an integrator's, a
    filter's); the replay from rest differs from the log by a combination of these columns, which the comparison
    takes out."""
    den = np.array(tf.a_r) if tf.a_r == tf.a_y else np.convolve(tf.a_r, tf.a_y)
    k = len(den) - 1
    out = np.zeros((n, k))
    if k:
        x = np.zeros(n)
        x[0] = 1.0
        h = _core.lfilter([1.0], list(den), x)  # the impulse response; column i is it i samples later
        for i in range(k):
            out[i:, i] = h[:n - i]
    return out


def mismatch(tf: TransferFunction, f: np.ndarray, c: np.ndarray, keep: np.ndarray) -> float:
    """‖F − F_law‖/‖F‖ on ``keep``, the law's unknown state at the first sample taken out (:func:`free_responses`)."""
    den = float(np.linalg.norm(f[keep]))
    if not den > 0:
        return math.inf
    e = (f - c)[keep]
    if not np.all(np.isfinite(e)):
        return math.inf
    with np.errstate(all="ignore"):
        x = free_responses(tf, len(f))[keep]
        if x.shape[1] and np.all(np.isfinite(x)):
            coef, *_ = np.linalg.lstsq(x, e, rcond=None)
            e = e - x @ coef
    return float(np.linalg.norm(e) / den)


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
    #: The usual cascade's settings that give this law (:func:`cascade_reading`): none, one, or two when the log cannot
    #: tell kp from 1/ti (no feedforward difference).
    cascade: Optional[List[Dict[str, float]]] = None

    def summary(self) -> str:
        parts = [f"controller fitted from the log: order {self.order}"
                 + (f", a pure delay of {self.delay} sample{'s' if self.delay > 1 else ''}" if self.delay else ""),
                 "integral action" if _has_integrator(self.controller) else "no integral action",
                 ("the reference and the position enter differently (C_r ≠ C_y: a feedforward other than the full "
                  "velocity one, or a derivative on the position only)") if _has_feedforward(self.controller)
                 else ("C_r ≈ C_y (the law acts on the tracking error alone, to the fit's precision: in a cascade, "
                       "full velocity feedforward)"),
                 (f"saturation ±{self.saturation:.4g}" if math.isfinite(self.saturation) else "no saturation seen"),
                 f"its law gives the logged force within {100 * self.error:.3g} % ({100 * self.heldout_error:.3g} % "
                 "on the held-out samples)"]
        if self.cascade:
            said = [", ".join(f"{k} = {r[k]:.5g}{u}" for k, u in (("kp", " 1/s"), ("kv", ""), ("ti", " s"), ("kff", ""),
                                                                    ("f_lp", " Hz"))) for r in self.cascade]
            parts.append("as the usual cascade (P position loop, PI velocity loop, velocity feedforward, command "
                         "low-pass; kv in force per unit speed): " + " or ".join(said)
                         + (" (this log cannot tell kp from 1/ti: with C_r = C_y they play symmetric parts)"
                            if len(said) > 1 else ""))
        return "; ".join(parts)

    def to_dict(self) -> Dict[str, Any]:
        return {**self.controller.to_dict(), "note": self.summary()}


class RobotControllerFit(Dict[str, ControllerFit]):
    """:func:`fit_controller` of a robot's record: each joint's :class:`ControllerFit` by joint name, in the URDF's
    order; ``summary()`` one line per joint, ``to_dict()`` the joints file (``{"type": "joints", "joints": [...]}``,
    SI units) that ``load_record(..., controller=...)`` and ``--controller`` read back."""

    def summary(self) -> str:
        return "\n".join(f"{j}: {f.summary()}" for j, f in self.items())

    def to_dict(self) -> Dict[str, Any]:
        return {"type": "joints", "joints": [f.to_dict() for f in self.values()]}


#: A fitted law's coefficient below this share of its largest is zero when it is read as a cascade (the least
#: squares leave some 1e-5 of it where the cascade has none).
READING_RTOL = 1e-4


def cascade_reading(tf: TransferFunction) -> Optional[List[Dict[str, float]]]:
    """The usual cascade's settings (:meth:`TransferFunction.cascade` with a PI velocity loop, velocity feedforward
    and a first-order command low-pass; force gain 1) of a fitted law that has its structure, read off its
    coefficients; None when it has another (no integrator, more poles, a delay).

    Over the denominator ``(1 − z⁻¹)(1 − p·z⁻¹)`` the cascade's feedback numerator is ``kv(1 − p)·[α, −1] ∗
    [β, −1/T]`` with ``α = 1 + T/ti`` (the PI's zero) and ``β = kp + 1/T`` (the position loop's), and its
    feedforward numerator ``C_r − C_y`` is ``kv(1 − p)(kff − 1)/T·[α, −1] ∗ [1, −1]``. The feedforward's zero gives α
    and kff; without a feedforward difference (kff = 1, or C_r = C_y) the two zeros play symmetric parts and the log
    cannot tell kp from 1/ti: both readings are returned."""
    T = tf.dt
    a, b_y, b_r = np.array(tf.a_y), np.array(tf.b_y), np.array(tf.b_r)
    if tf.a_r != tf.a_y or len(a) != 3 or not _has_integrator(tf):
        return None
    p = float(-(a[1] + 1.0))  # a = [1, −(1 + p), p]
    if not (0.0 < p < 1.0) or abs(a[2] - p) > 1e-6 * max(abs(p), 1e-12) + 1e-9:
        return None
    def three(b):  # the numerator's taps without trailing zeros, to three
        b = np.trim_zeros(np.where(np.abs(b) <= READING_RTOL * np.abs(b).max(), 0.0, b), "b")
        return np.pad(b, (0, 3 - len(b))) if len(b) <= 3 else None

    b_y, b_r = three(b_y), three(b_r)
    if b_y is None or b_r is None or not b_y[2] > 0:
        return None
    g = b_y[2] * T  # kv(1 − p)
    kv = g / (1.0 - p)
    # b_y = g·[αβ, −(α/T + β), 1/T]: α·β = b_y0/g, α/T + β = −b_y1/g
    prod, S = b_y[0] / g, -b_y[1] / g
    disc = S * S - 4.0 * prod / T
    if disc < 0:
        return None
    roots = [(S + sg * math.sqrt(disc)) * T / 2.0 for sg in (1.0, -1.0)]  # α candidates
    f_lp = -math.log(p) / (2.0 * math.pi * T)
    d = b_r - b_y
    readings = []
    for alpha in roots:
        beta = prod / alpha
        ti, kp = T / (alpha - 1.0) if alpha > 1.0 else -1.0, beta - 1.0 / T
        if not (ti > 0 and kp > 0):
            continue
        kff = 1.0 + float(d[2]) * T / g  # the feedforward numerator's last coefficient is kv(1 − p)(kff − 1)/T
        readings.append({"kp": float(kp), "kv": float(kv), "ti": float(ti), "kff": float(kff), "f_lp": float(f_lp)})
    if np.linalg.norm(d) > READING_RTOL * np.linalg.norm(b_y) and len(readings) > 1:
        # the feedforward's zero [α, −1] tells the PI's zero: keep the reading that has it
        alpha_ff = float(d[0] / d[2]) if d[2] else math.nan
        readings = [min(readings, key=lambda r: abs(1.0 + T / r["ti"] - alpha_ff))]
    # a reading must reproduce the fitted law
    ok = []
    for r in readings:
        c = TransferFunction.cascade(dt=T, **r)
        tol = dict(rtol=10 * READING_RTOL, atol=READING_RTOL * np.abs(b_y).max())
        if np.allclose(c.b_y, b_y[:len(c.b_y)], **tol) and np.allclose(c.b_r, b_r[:len(c.b_r)], **tol):
            ok.append(r)
    return ok or None


def _has_integrator(tf: TransferFunction) -> bool:
    return bool(abs(sum(tf.a_y)) < 1e-6 * sum(abs(a) for a in tf.a_y))


def _has_feedforward(tf: TransferFunction) -> bool:
    br, by = np.array(tf.b_r), np.array(tf.b_y)
    return bool(np.linalg.norm(br - by) > READING_RTOL * np.linalg.norm(by))


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


#: The least damping ratio a fitted law's oscillating poles may have. A drive's filters ring little (a low-pass's
#: poles at ζ ≥ 0.5, a notch's at 0.1–1); a law with poles at ζ → 0 away from zero frequency is a resonator, which
#: replays a sine or a multisine the drive added to its command (a dither, an injected excitation the controller did
#: not make) from the positions' response to it: fitted on an EMPS-like log carrying a 30 Hz dither of 1 % of the
#: force, such a law replayed it to 0.00 % and the right controller, which does not make the dither, was refused.
MIN_POLE_DAMPING = 0.1


def _resonant(poles: np.ndarray, dt: float) -> bool:
    """Whether a pole oscillates (complex, or on the negative real axis) with a damping ratio below
    :data:`MIN_POLE_DAMPING`: s = ln(z)/dt, ζ = −Re(s)/|s|."""
    z = poles[(np.abs(poles.imag) > 1e-12) | (poles.real < 0)]
    z = z[np.abs(z) > 1e-12]
    if not z.size:
        return False
    s = np.log(z.astype(complex)) / dt
    return bool(np.any(-s.real < MIN_POLE_DAMPING * np.abs(s)))


class _Design:
    """The equation-error least squares of every order for one delay ``d`` (and with or without ``integral``), from
    one QR factorization. The law is regressed on the tracking error ``qr − qm`` (through C_y) and the reference
    (through the feedforward C_r − C_y): the two positions themselves are nearly the same column (the axis tracks its
    reference), which leaves the least squares ill-conditioned. With ``integral`` the denominator holds the integrator
    ``1 − z⁻¹`` exactly and the feedforward has no gain at rest (a constant reference gives a constant command): the
    law is regressed on the differenced force and reference. Replayed from rest, an integrator only estimated (a pole
    at 1 ± 1e-9) accumulates the least error of the feedforward into a drift.

    Every order's columns are a subset of the largest order's (the same lags of the same signals), and its rows a
    superset of the rows every order can use (``common``). With ``[X y]`` on those rows factored once (R, whose last
    column holds Qᵀy), one order's least squares over its own rows is the small problem ``[R_S; X_S on its other
    rows] θ = [Qᵀy; y there]``: exactly the same solution as on the whole matrix, at a few hundredths of its cost
    (120 problems of 17,000 rows each on the EMPS)."""

    def __init__(self, qr, qm, f, d: int, integral: bool, nb_max: int, na_max: int, common: np.ndarray):
        diff = (lambda x: np.r_[0.0, np.diff(x)]) if integral else (lambda x: x)
        self.d, self.integral, self.nb_max, self.na_max = d, integral, nb_max, na_max
        self.y = diff(f)
        lags = range(d, d + nb_max + 1)
        self.x = np.hstack([_lagged(qr - qm, lags), _lagged(diff(qr), lags), -_lagged(self.y, range(1, na_max + 1))])
        self.common = common
        xy = np.column_stack([self.x[common], self.y[common]])
        # R of [X y] on the common rows (fewer rows than columns: R is as many rows high, and still exact)
        self.r = np.linalg.qr(xy, mode="r")[: xy.shape[1]] if len(common) else np.zeros((0, xy.shape[1]))

    def columns(self, na: int, nb: int) -> np.ndarray:
        k = self.nb_max + 1
        return np.r_[np.arange(nb + 1), k + np.arange(nb + 1), 2 * k + np.arange(na)]

    def fit(self, rows: np.ndarray, na: int, nb: int) -> Optional[Tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """(b_r, b_y, a) of the law of denominator order ``na`` and numerators of ``nb + 1`` taps on ``rows`` (a
        superset of the common rows), or None."""
        cols = self.columns(na, nb)
        extra = np.setdiff1d(rows, self.common, assume_unique=True)
        m = np.vstack([self.r[:, cols], self.x[np.ix_(extra, cols)]])
        rhs = np.r_[self.r[:, -1], self.y[extra]]
        scale = np.linalg.norm(m, axis=0)  # the columns' norms on the rows: Q keeps them
        scale[scale == 0] = 1.0
        try:  # the cutoff of the whole problem's least squares (eps times its larger dimension)
            theta, *_ = np.linalg.lstsq(m / scale, rhs, rcond=np.finfo(float).eps * max(len(rows), len(cols)))
        except np.linalg.LinAlgError:
            return None
        theta = theta / scale
        if not np.all(np.isfinite(theta)):
            return None
        k = nb + 1
        pad = np.zeros(self.d)
        b_y, b_ff, a = theta[:k], theta[k:2 * k], np.r_[1.0, theta[2 * k:]]
        if self.integral:
            b_ff, a = np.convolve([1.0, -1.0], b_ff), np.convolve([1.0, -1.0], a)
            b_y = np.r_[b_y, 0.0]
        return np.r_[pad, b_ff + b_y], np.r_[pad, b_y], a


def fit_controller(rec_or_signals, *, holdout: float = 0.3, max_order: int = MAX_ORDER,
                   tolerance: float = CHECK_TOLERANCE) -> Union[ControllerFit, RobotControllerFit]:
    """The controller of a log (a :class:`didim.Recording`, or a dict with ``dt``, ``qr``, ``qm``, ``force`` and
    optionally ``u_ext``), see the module's text. Raises :class:`DataError` when no linear law of order up to
    ``max_order`` (with a delay up to 2 samples) replays the held-out force within ``tolerance`` (``CHECK_TOLERANCE``
    by default; ``math.inf`` returns the best law whatever it misses). A robot's record: each joint's law from its
    own log, by joint name (a :class:`RobotControllerFit`; the error names the joint)."""
    if getattr(rec_or_signals, "has_joint_columns", False):
        out = RobotControllerFit()
        for j, name in enumerate(rec_or_signals.joint_names):
            try:
                out[name] = fit_controller(rec_or_signals.joint(j), holdout=holdout, max_order=max_order,
                                           tolerance=tolerance)
            except DataError as e:
                raise DataError(f"joint {name}: {e}") from None
        return out
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
    orders = [(na, na + extra) for na in range(0, max_order + 1) for extra in (0, 1, 2) if na + extra >= 1]

    def usable(n: int, nb: int) -> np.ndarray:
        # rows whose window (the force's n past samples) holds no clipped sample, past the longest lag
        bad = np.convolve(clipped.astype(float), np.ones(n + 1), "full")[:n_all] > 0
        rows = np.flatnonzero(~bad[:n_train])
        return rows[rows >= nb + max(DELAYS)]

    na_max, nb_max = max(n for n, _ in orders), max(nb for _, nb in orders)
    common = usable(na_max, nb_max)
    designs = {(d, i): _Design(qr, qm, f, d, i, nb_max, na_max, common) for d in DELAYS for i in (False, True)}
    for n, nb in orders:
        rows = usable(n, nb)
        if rows.size < 10 * (n + 2 * nb + 2):
            continue
        for d, integral in [(d, i) for d in DELAYS for i in (False, True)]:
            got = designs[(d, integral)].fit(rows, n, nb)
            if got is None:
                continue
            b_r, b_y, a = got
            poles = np.roots(a)
            if np.any(np.abs(poles) > 1 + 1e-6):  # an unstable law is no drive's (an integrator: 1 to rounding)
                continue
            if _resonant(poles, dt):  # a law that rings is no drive's either: it replays an excitation, not a law
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
    return ControllerFit(tf, n, d, err, whole, sat, tried, cascade_reading(tf) if d == 0 else None)


__all__ = ["ControllerFit", "RobotControllerFit", "fit_controller"]
