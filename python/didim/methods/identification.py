"""IDIM-LS (section III), DIDIM (sections IV and V, the three-step procedure for flexible joints) and the
closed-loop output-error methods (section VI.F and an exact-sensitivity Gauss-Newton solver).

Conventions: SI units on the load side, the paper's parameter names, and
- ``relative_error``: ‖Y − Wχ̂‖/‖Y‖ of the final regression (or of the output for output-error methods),
- ``output_error``: ‖Y − Y_s(χ̂)‖/‖Y‖, Y and Y_s the decimated measured and simulated motor forces.

How the unactuated row of eq. (4) enters DIDIM (the paper leaves it implicit): each sample contributes two rows,
the motor row ``τ = M1 q̈1 + Fv1 q̇1 + Fc1 sign(q̇1) − K12 q2`` against the measured force and the load row
``0 = M2 q̈12 + Fv2 q̇12 + Fc2 sign(q̇12) + K12 q2`` against zero, both built from the simulated states and decimated
alike, with equal weight. The simulated states satisfy the load row exactly for the current load-side parameters, so
the load row only fixes their scale: the regression moves M2, Fv2, Fc2 and K12 together and keeps K12/M2 (the mode
f_n_flex of step 2) and the load friction at their current values. With eq. (30) (Fv2 = Fc2 = 0) the load friction
therefore stays at zero, and the motor friction absorbs the totals Fv1 + Fv2, Fc1 + Fc2: from the motor force alone,
DIDIM estimates M1, Fv_tot, Fc_tot, M2 and K12 (with f_n_flex from step 2), as in Tables 3 and 4 of the paper. The
exact-sensitivity solver (:func:`oe_lm`) has no such restriction.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import replace
from typing import Callable, Dict, List, Optional, Sequence, Union

import numpy as np

from .._parallel import serial_blas
from .. import _checks, _core
from .._errors import DataError, DidimError, DidimWarning, IdentifiabilityError, SimulationError
from ..recording import Recording
from ..result import IdentificationResult, Iteration
from ..model import STRUCTURE_FIELDS, Model, as_model, knot_weights
from ..signal import Decimation, decimation_matches, diffcent, lowpass
from ..simulation import DEFAULT_TOL, coulomb_eps_of, params_vector, problem, settling_samples, simulate
from .didim_loop import DIVERGENCE_FACTOR, DidimLoop, didim_loop, residual_settled

Progress = Optional[Callable[[str], None]]

#: The structure fields of :class:`didim.Model` each method supports beyond the kind and the offset (the methods that
#: simulate the closed loop take them all; IDIM-LS regresses measured states and has no simulator).
IDIM_LS_SUPPORTS = frozenset({"terms", "coulomb_eps", "coulomb_law"})
SIMULATING_SUPPORTS = frozenset(STRUCTURE_FIELDS) - {"offset"}
#: The three-step DIDIM builds its flexible model from the rigid one's: the friction law only.
THREE_STEP_SUPPORTS = frozenset({"coulomb_eps", "coulomb_law"})
#: oe-lm's exact sensitivities cover every field the simulator does (a force lag since the sixteenth session).
OE_LM_SUPPORTS = SIMULATING_SUPPORTS


def method_supports(method: str, kind: str) -> frozenset:
    """The structure fields ``method`` (a name of ``didim.METHODS``) supports for a model of ``kind``."""
    if method == "didim" and kind == "flexible":
        return THREE_STEP_SUPPORTS
    return {"idim-ls": IDIM_LS_SUPPORTS, "oe-lm": OE_LM_SUPPORTS}.get(method, SIMULATING_SUPPORTS)




def supports(model: Model, fields, method: str) -> None:
    """Refuses a model whose structure uses a field ``method`` does not support, naming it."""
    default = Model(model.kind)
    used = [f for f in STRUCTURE_FIELDS
            if f != "offset" and getattr(model, f) != getattr(default, f) and f not in fields]
    if used:
        raise DataError(f"{method} cannot identify {model.describe()}: it does not support {', '.join(used)}; give a "
                        "didim.Model without those fields, or use method 'didim'")

#: Decimation cutoffs of the paper: 5 Hz for the rigid step, 60 Hz for the flexible steps.
RIGID_CUTOFF_HZ = 5.0
FLEXIBLE_CUTOFF_HZ = 60.0


def _say(progress: Progress, msg: str) -> None:
    if progress is not None:
        progress(msg)


#: What a rank deficiency involving friction-profile terms usually means.
SPLINE_HINT = ("; friction-profile splines of one direction sum to that direction's part of the Coulomb sign wherever "
               "they cover the stroke, which the Coulomb friction already is: leave one knot of each direction out")


def _spline_hint(terms) -> str:
    return SPLINE_HINT if any(t.kind == "coulomb_spline" for t in terms or ()) else ""


def _check_spline_cover(rec: Recording, terms, free: Sequence[str]) -> None:
    """Refuses friction-profile splines that sum to 1 over the whole recorded stroke in one direction beside a free
    Coulomb friction: that direction's splines then equal its side of the Coulomb sign, the regressor is singular or
    nearly (positions just outside the knots' span leave a sliver), and the fit returns huge opposite values."""
    coulomb = [n for n in ("Fc", "Fc1") if n in free]
    if not coulomb:
        return
    for side, code in (("forward", 1), ("backward", -1), ("both-direction", 0)):
        spl = [t for t in terms or () if t.kind == "coulomb_spline" and t.hypers["side"] == code]
        if not spl:
            continue
        total = knot_weights(spl, rec.qm).sum(axis=1)
        if np.min(total) > 0.999:
            raise IdentifiabilityError(
                f"the {side} friction splines ({', '.join(t.name for t in spl)}) "
                f"cover the whole recorded stroke and sum to 1 there, so they equal that direction's part of the "
                f"Coulomb sign, which {coulomb[0]} already is" + SPLINE_HINT)


def _solve(w: np.ndarray, y: np.ndarray, names: Sequence[str], sigma: str = "paper", hint: str = "") -> dict:
    """QR least squares; raises IdentifiabilityError naming dependent columns (``hint``: what else to say)."""
    sol = _core.lstsq(np.ascontiguousarray(w), np.ascontiguousarray(y), sigma=sigma)
    if sol["rank"] < len(names):
        deps, which = [], []
        for col, comb in sol["dependencies"]:
            which.append(names[col])
            if comb:
                rhs = " + ".join(f"{c:.6g}·{names[i]}" for i, c in comb)
                deps.append(f"column {names[col]} = {rhs}")
            else:
                deps.append(f"column {names[col]} is zero ({names[col]} has no effect on this record)")
        raise IdentifiabilityError(
            f"the regressor has rank {sol['rank']} < {len(names)}: {'; '.join(deps)}. {', '.join(which)} cannot be "
            "identified separately on this record: excite the axis more (other speeds, both directions, accelerations) "
            "or fix some of them" + hint
        )
    return sol


def _stack_rows(rows: List[tuple], dec: Decimation):
    """Decimates each (y, W) row block in parallel and stacks them."""
    ys, ws = [], []
    for y, w in rows:
        yd, wd = dec.apply(y, w)
        ys.append(yd)
        ws.append(wd)
    return np.concatenate(ys), np.vstack(ws)


# --------------------------------------------------------------------------------------------------------------------
# IDIM-LS
# --------------------------------------------------------------------------------------------------------------------


def _idim_system(rec: Recording, model: Model, lowpass_hz: float, lowpass_order: int, padding: str,
                 border: int, dec: Decimation, zoh_align: bool):
    """The decimated IDIM-LS system (Y, W) of a record (both rows of eq. (4) for the flexible model); ``model``
    carries its Coulomb smoothing (0: the hard sign on the filtered velocities)."""
    if model.kind == "flexible" and rec.ql is None:
        raise DataError("IDIM-LS of the flexible model needs the load position ql (a second encoder); use method='didim'")
    if not (0 <= border < rec.n // 2):
        raise DataError(f"border must be between 0 and half the record ({rec.n // 2}), got {border}")
    positions = [rec.qm] + ([rec.ql] if model.kind == "flexible" else [])
    q = np.array([lowpass(x, lowpass_hz, rec.fs, order=lowpass_order, padding=padding) for x in positions])
    qd = diffcent(q, rec.dt)
    qdd = diffcent(qd, rec.dt)
    w = model.core().regressor(q, qd, qdd)
    force = rec.force
    if zoh_align:
        force = np.concatenate([force[:1], 0.5 * (force[1:] + force[:-1])])
    rows = [(force[border:], w[0, border:, :])]
    if model.kind == "flexible":
        rows.append((np.zeros(rec.n - border), w[1, border:, :]))
    return _stack_rows(rows, dec)


def idim_cross_test(rec: Recording, result: IdentificationResult) -> float:
    """Relative error ‖Y − Wχ̂‖/‖Y‖ of an IDIM-LS result on another record, built with the same recipe."""
    o = result.options
    dec = result.options.get("_decimation") or Decimation.matlab(10)
    model = result.structure
    y, w = _idim_system(rec, model, o["lowpass_hz"], o["lowpass_order"], o["padding"], o["border"], dec,
                        o["zoh_align"])
    chi = np.array([result.params[n] for n in model.param_names()])
    return float(np.linalg.norm(y - w @ chi) / np.linalg.norm(y))


@serial_blas
def idim_ls(
    rec: Recording,
    model: Union[str, Model] = "rigid",
    *,
    offset: Optional[bool] = None,
    lowpass_hz: float = 100.0,
    lowpass_order: int = 4,
    padding: str = "matlab",
    border: int = 49,
    decimation: Optional[Decimation] = None,
    sigma: str = "paper",
    coulomb_eps: float = 0.0,
    zoh_align: bool = False,
    terms: Sequence = (),
) -> IdentificationResult:
    """IDIM-LS: the inverse dynamic model on measured positions, eqs. (10)-(15).

    Positions are low-passed with a zero-phase Butterworth (``lowpass_order`` at ``lowpass_hz``), differentiated twice
    by central differences; the first ``border`` samples are dropped (edge effects); Y and every column of W are
    decimated alike (default: MATLAB's ``decimate`` by 10); ordinary least squares by QR. The flexible model needs
    the load position ``rec.ql`` and uses both rows of eq. (4), the load row against zero.

    ``sigma="sample_std"`` computes σ as the EMPS benchmark does (sample standard deviation of the error) instead of
    eq. (13). ``coulomb_eps=0`` uses the hard sign on the filtered velocities.

    ``zoh_align=True`` compares the central-difference acceleration at sample k with the mean of the commands held
    over [k−1, k) and [k, k+1), (τ[k−1] + τ[k])/2, instead of τ[k]: a drive's command is held over the following
    period, so τ[k] leads the central-difference states by half a sample, which biases viscous friction and the
    flexible parameters once the excitation reaches tens of Hz. Off by default (the benchmark's recipe).

    ``terms`` (:class:`didim.Term`) add columns to W, built by the core's basis functions on the filtered states.
    ``model`` may be a :class:`didim.Model` (its offset and terms; IDIM-LS supports no actuation delay, force lag or
    backlash, see ``IDIM_LS_SUPPORTS``).
    """
    t0 = time.perf_counter()
    _checks.options(lowpass_hz=lowpass_hz, lowpass_order=lowpass_order, border=border, coulomb_eps=coulomb_eps,
                    zoh_align=zoh_align)
    _checks.one_of("sigma", sigma, ("paper", "sample_std"))
    model = as_model(model, offset=offset, terms=tuple(terms))
    supports(model, IDIM_LS_SUPPORTS, "idim-ls")
    if model.coulomb_eps is not None and coulomb_eps not in (0.0, model.coulomb_eps):
        raise DataError(f"the model's coulomb_eps is {model.coulomb_eps:g}: leave the option coulomb_eps out")
    coulomb_eps = float(coulomb_eps if model.coulomb_eps is None else model.coulomb_eps)
    model = replace(model, coulomb_eps=coulomb_eps)
    terms = model.terms
    names = model.param_names()
    _check_spline_cover(rec, terms, names)
    dec = decimation or Decimation.matlab(10)
    decimation_matches(dec, rec.fs)
    _checks.record_long_enough(dec, rec.n - min(border, rec.n - 1), rec.dt, len(names),
                               2 if model.kind == "flexible" else 1, "IDIM-LS")
    y, wd = _idim_system(rec, model, lowpass_hz, lowpass_order, padding, border, dec, zoh_align)
    sol = _solve(wd, y, names, sigma, hint=_spline_hint(terms))
    p = dict(zip(names, map(float, sol["params"])))
    return IdentificationResult(
        model=model.kind,
        structure=model,
        method="idim-ls",
        params=p,
        std=dict(zip(names, map(float, sol["std"]))),
        rel_std_pct=dict(zip(names, map(float, sol["rel_std_pct"]))),
        relative_error=float(sol["relative_error"]),
        iterations=1,
        simulations=0,
        elapsed_s=time.perf_counter() - t0,
        options=dict(lowpass_hz=lowpass_hz, lowpass_order=lowpass_order, padding=padding, border=border,
                     decimation=dec.describe(), band_hz=dec.cutoff_hz, _decimation=dec, sigma=sigma, coulomb_eps=coulomb_eps, zoh_align=zoh_align,
                     terms=[t.to_dict() for t in terms], condition_number=float(sol["condition_number"])),
        covariance=sol["covariance"],
    )


# --------------------------------------------------------------------------------------------------------------------
# DIDIM
# --------------------------------------------------------------------------------------------------------------------


def nelder_mead_simplex(x0) -> np.ndarray:
    """scipy's default initial simplex for ``minimize(method="Nelder-Mead")``: x0 and, per coordinate, x0 with that
    coordinate times 1.05 (0.00025 where it is 0)."""
    x0 = np.atleast_1d(np.asarray(x0, dtype=float)).ravel()
    sim = np.tile(x0, (x0.size + 1, 1))
    for k in range(x0.size):
        sim[k + 1, k] = 1.05 * x0[k] if x0[k] != 0 else 0.00025
    return sim


def prefetch(cost, cost_batch, points) -> Callable:
    """``cost`` with the values at ``points`` computed beforehand in one parallel batch (``cost_batch``): the first
    call at each of those points returns the stored value. Used to evaluate a Nelder-Mead initial simplex on all
    cores; the minimizer sees exactly the values it would have computed itself."""
    cache = {}
    for x, v in zip(points, cost_batch(np.asarray(points, dtype=float))):
        cache.setdefault(tuple(map(float, x)), float(v))

    def f(x):
        v = cache.pop(tuple(map(float, np.ravel(x))), None)
        return cost(x) if v is None else v

    return f


#: Masses and stiffness must stay positive for the closed loop to be simulated.
_POSITIVE = ("M", "M1", "M2", "K12")
# DIDIM's divergence test and pull-backs are the shared loop's (didim.methods.didim_loop)
#: Largest factor by which one DIDIM step may change a mass or the stiffness. The regression is only valid while the
#: simulated loop's bandwidth stays near the real one (eqs. (17)-(18)); from a far a priori mass (1000 kg for a 100 kg
#: axis) the first LS step can overshoot by orders of magnitude (to 1 kg, where the simulated loop chatters and the
#: iteration is trapped). Steps within this factor, as every step near convergence is, are taken whole.
MAX_STEP_RATIO = 4.0


#: A regression error ‖Y − Wχ‖/‖Y‖ below this is rounding: the model reproduces the data exactly (noise-free data
#: made by the same model), and criterion (21), a relative change of that rounding, would never settle.
EXACT_FIT = 1e-10


def _physical(names: Sequence[str], chi: np.ndarray, ref: Optional[np.ndarray] = None) -> bool:
    """Masses and stiffness positive (and within MAX_STEP_RATIO of ``ref``), every value finite."""
    if not np.all(np.isfinite(chi)):
        return False
    for i, n in enumerate(names):
        if n in _POSITIVE:
            if chi[i] <= 0:
                return False
            if ref is not None and ref[i] > 0 and not (1 / MAX_STEP_RATIO <= chi[i] / ref[i] <= MAX_STEP_RATIO):
                return False
    return True


class _AxisPlant:
    """One axis as DIDIM's loop (:func:`didim.methods.didim_loop.didim_loop`) sees it: the core's problem simulates χ and
    builds the decimated regressor of the simulated states in one call; the least squares leave out the samples
    around reversals (the rows follow each iterate's velocity; an alternation between two sets freezes both out) and
    the start the simulation takes to join the record; a mass or the stiffness must stay positive and change by at
    most MAX_STEP_RATIO per step; criterion (21) says when it has converged."""

    symbol = "χ"
    short_step_reason = ("a mass or the stiffness would have changed by more than "
                         f"{MAX_STEP_RATIO:g}× or become non-positive")

    def __init__(self, *, rec, pb, names, free, fi, y_motor, yd_motor, ny, dec, m_fit, start_row, exclude, hint, tol,
                 method, kind, progress, first=None):
        self.rec, self.pb, self.names, self.free_names, self.free = rec, pb, names, free, fi
        self.y_motor, self.yd_motor, self.ny, self.dec, self.m_fit = y_motor, yd_motor, ny, dec, m_fit
        self.start_row, self.exclude, self.hint, self.tol = start_row, exclude, hint, tol
        self.method, self.kind, self.progress = method, kind, progress
        self.iterations: List[Iteration] = []
        self.notes: List[str] = []
        self.masks: List[np.ndarray] = []  # the rows kept by the reversal exclusion in the last two iterations
        self.frozen_rows: Optional[np.ndarray] = None  # set when the iterates alternated between two masks
        self.first = first  # (χ⁰, its system) when the caller simulated χ⁰ already: the first call uses it

    def simulate(self, chi: np.ndarray):
        # one call: simulate with χᵏ, build W of the simulated states, decimate Y, W and the simulated force
        if self.first is not None and np.array_equal(chi, self.first[0]):
            y_all, w_all, force_dec = self.first[1][:3]
        else:
            y_all, w_all, force_dec = self.pb.didim_system(chi, self.y_motor, self.free, self.dec.core)
        self.first = None
        if self.m_fit is not None:  # keep the training rows of each dof's block
            m = len(force_dec)
            keep = np.concatenate([np.arange(d * m, d * m + self.m_fit) for d in range(len(y_all) // m)])
            y_all, w_all, force_dec = y_all[keep], w_all[keep], force_dec[:self.m_fit]
        self._chi = chi
        return y_all, w_all, force_dec

    def output_error(self, sim) -> float:
        err = float(np.linalg.norm((self.yd_motor - sim[2])[self.start_row:])) / self.ny
        it = self.iterations
        if it and np.array_equal(self._chi, _vector(it[-1].params, self.names)):
            it[-1].output_error = err  # the output error of the iterate the last step produced
        return err

    def solve(self, chi: np.ndarray, sim) -> dict:
        y_all, w_all, force_dec = sim
        it = self.iterations
        rows = _moving_rows(w_all, self.free_names) if self.exclude else None
        if rows is not None:
            if self.frozen_rows is not None:
                rows = rows & self.frozen_rows
            elif (len(self.masks) == 2 and len(it) >= 3 and self.masks[1].shape == rows.shape
                  and np.array_equal(self.masks[0], rows) and not np.array_equal(self.masks[1], rows)
                  and np.allclose(chi, _vector(it[-3].params, self.names), rtol=1e-9, atol=0)):
                # the rows left out follow each iterate's simulated velocity; a row whose decimated Coulomb
                # regressor sits at the threshold can make DIDIM alternate between two points, each leaving out
                # the row the other keeps (rigid with offset on DATA_EMPS_PULSES): both are left out from here on
                self.frozen_rows = rows & self.masks[1]
                rows = self.frozen_rows
                self.notes.append(f"iteration {len(it) + 1}: the iterates alternated between two points, each "
                                  "leaving out samples around reversals that the other kept; both sets are left out "
                                  "from here on")
            self.masks = (self.masks + [rows])[-2:]
        if self.start_row:
            m_rows = len(force_dec)
            settled = np.tile(np.arange(m_rows) >= self.start_row, len(y_all) // m_rows)
            rows = settled if rows is None else rows & settled
        sol = (_solve(w_all, y_all, self.free_names, hint=self.hint) if rows is None
               else _solve(w_all[rows], y_all[rows], self.free_names, hint=self.hint))
        sol["rows_kept"] = None if rows is None else (int(np.count_nonzero(rows)), len(rows))
        return sol

    def physical(self, new: np.ndarray, old: Optional[np.ndarray]) -> bool:
        return _physical(self.names, new, old)

    def describe(self, loop: DidimLoop) -> str:
        sol = loop.history[-1]
        self.iterations.append(Iteration(
            k=len(self.iterations) + 1,
            params=dict(zip(self.names, map(float, loop.theta))),
            rel_std_pct=dict(zip(self.free_names, map(float, sol["rel_std_pct"]))),
            relative_error=float(sol["relative_error"]),
            output_error=float("nan"),
        ))
        msg = (f"{self.method} {self.kind} iteration {len(self.iterations)}: ‖Y−Wχ‖/‖Y‖ = "
               f"{100 * sol['relative_error']:.3f} %, output error of χ{len(self.iterations) - 1} = "
               f"{100 * loop.error:.3f} %")
        _say(self.progress, msg)
        return msg

    def converged(self, loop: DidimLoop) -> bool:
        """Criterion (21) on a whole step: the regression's residual changed by at most ``tol`` of itself (or the
        model reproduces the data exactly)."""
        h = loop.history
        return residual_settled(loop, self.tol) or (loop.alpha == 1 and len(h) >= 2
                                                    and h[-1]["relative_error"] <= EXACT_FIT)

    def settled(self, loop: DidimLoop) -> str:
        return "accept"


def didim_iterate(
    rec: Recording,
    model: Union[str, Model],
    initial: Dict[str, float],
    *,
    frozen: Optional[Dict[str, float]] = None,
    cutoff_hz: Optional[float] = None,
    decimation: Optional[Decimation] = None,
    tol: float = 1e-3,
    max_iter: int = 30,
    substeps: int = 10,
    divergence_factor: float = DIVERGENCE_FACTOR,
    progress: Progress = None,
    method: str = "didim",
    fit_samples: Optional[int] = None,
    integrator: str = "exponential",
    sim_tol: float = DEFAULT_TOL,
    reversals: str = "auto",
    start: str = "auto",
    give_up_above: Optional[float] = None,
    **structure,
) -> IdentificationResult:
    """DIDIM iterations, eqs. (16)-(21): simulate the closed loop with χᵏ, build the IDM regressor of the simulated
    (noise-free) states, decimate Y and W in parallel, solve by QR for χᵏ⁺¹; stop when
    |‖ρₖ₊₁‖ − ‖ρₖ‖|/‖ρₖ‖ ≤ tol (eq. (21)).

    ``initial`` gives χ⁰ for the estimated parameters, ``frozen`` the parameters held at fixed values.

    Safeguards (not in the paper; they never act on an iteration that goes well): an LS step that makes a mass or the
    stiffness non-positive, or changes one by more than ``MAX_STEP_RATIO`` (4×), is shortened
    (χ + α(χ_LS − χ), α = 1/2, 1/4, ...) until it is not; an iterate whose
    simulation fails, or whose simulated output error exceeds ``divergence_factor`` times the best so far (a real
    rise, not the slow wandering of DIDIM's fixed point, which is not the output-error minimum), is pulled back
    halfway to the best iterate, at most ``MAX_BACKTRACKS`` times in a row; after that the iteration is declared
    divergent and the result holds the best iterate with ``converged=False`` and a message.

    ``fit_samples`` restricts the regression and the output errors to the first samples (the rest of the record is
    then held out for validation). ``integrator``, ``sim_tol`` and ``substeps`` choose the simulator's scheme (see
    :func:`didim.simulate`). ``model`` is a :class:`didim.Model`, or a kind with its structure fields as keywords
    (``offset``, ``terms``, ``backlash_gap``, ``delay``, ``force_lag``, ``coulomb_eps``, ``coulomb_law``).

    ``reversals`` (not in the paper): ``"exclude"`` leaves out of the regression the decimated samples around velocity
    reversals and stops, where the decimated Coulomb regressor of the simulated velocity is not saturated
    (``|dec sign(q̇)| < COULOMB_SATURATED``): there the fit depends on the shape of the friction law near zero speed,
    which no smooth law gets right (real friction sticks; another simulator smooths otherwise), and those few samples
    bias Fv and Fc by several percent. The closed loop is still simulated through them. ``"auto"`` (default) excludes
    them for the rigid model (the only model it applies to) when at least ``MIN_MOVING_SHARE`` of the samples remain,
    and keeps them for a model with friction-profile terms (``coulomb_spline_*``, which live where the axis reverses);
    ``"keep"`` is the paper's regression on every sample.

    ``start`` (not in the paper): the simulation starts at rest on the reference (or on the record's lead-in,
    :attr:`didim.Recording.lead_in`, for a log cut in the acceleration from rest); a log that began while the axis
    moved otherwise, or away from the reference, starts elsewhere, and the simulation takes some samples to join it
    (:func:`didim.simulation.settling_samples`, on the simulation with χ⁰). Over those samples the simulated states
    answer a start the axis never had, and the regression on them biases the fit (a log cut at 83 mm/s: M 80 kg
    instead of 95). ``"auto"`` (default) leaves the decimated rows they reach (1 % of their weight or more) out of
    the regression and from the output errors the iterations compare; ``"keep"`` keeps every row. A record that
    starts where the simulation does is fitted alike.

    ``give_up_above`` (not in the paper): a relative output error; when the best iterate's is still above it after a
    third of ``max_iter`` iterations, the iterations stop there and the result is the best iterate, not converged (for
    a caller that compares the fit with a model whose error it knows: an iteration that has come nowhere near it by
    then, as a flexible refit wandering on closed-loop-unstable iterates, would only wander on).
    """
    t0 = time.perf_counter()
    if reversals not in ("auto", "exclude", "keep"):
        raise DataError(f"reversals must be 'auto', 'exclude' or 'keep', got {reversals!r}")
    model = as_model(model, **structure)
    _checks.options(tol=tol, max_iter=max_iter, substeps=substeps, divergence_factor=divergence_factor,
                    cutoff_hz=cutoff_hz)
    # the number the result's structure carries
    model = replace(model, coulomb_eps=coulomb_eps_of(rec, model.coulomb_eps))
    kind, terms = model.kind, model.terms
    initial = _checks.physical(initial, "initial")
    frozen = _checks.physical(dict(frozen or {}), "frozen")
    names = model.param_names()
    unknown = [k for k in list(initial) + list(frozen) if k not in names]
    if unknown:
        raise DataError(f"unknown parameter(s) {', '.join(unknown)} for the {model.describe()} ({', '.join(names)})")
    free = [n for n in names if n not in frozen]
    _check_spline_cover(rec, terms, free)
    hint = _spline_hint(terms)  # what a rank deficiency also says
    missing = [n for n in free if n not in initial]
    if missing:
        raise DataError(f"initial values missing for {', '.join(missing)}")
    if decimation is None:
        cutoff = cutoff_hz if cutoff_hz is not None else (RIGID_CUTOFF_HZ if kind == "rigid" else FLEXIBLE_CUTOFF_HZ)
        decimation = Decimation.lowpass(cutoff, rec.fs)
    dec = decimation
    decimation_matches(dec, rec.fs)
    _checks.record_long_enough(dec, rec.n, rec.dt, len(free), 2 if kind == "flexible" else 1, f"{method} ({kind})")
    fi = [names.index(n) for n in free]
    if reversals == "exclude" and kind != "rigid":
        raise DataError("reversals='exclude' is for the rigid model (the flexible regression has a load row per "
                        "sample whose friction reverses on its own); use 'keep' or 'auto'")
    # a friction profile along the stroke lives where the axis reverses (its knots near the ends of the stroke): "auto"
    # keeps the reversals then, else those splines lose most of their samples, and the samples left out change with
    # each iterate's simulated velocity (DIDIM alternated between two points on the EMPS)
    profile = any(t.kind == "coulomb_spline" for t in terms)
    exclude = (reversals == "exclude" or (reversals == "auto" and not profile)) and kind == "rigid" and (
        _coulomb_column(free) is not None)
    chi = np.array([initial.get(n, frozen.get(n, 0.0)) for n in names], dtype=float)
    pb = problem(rec, model, substeps=substeps, integrator=integrator, tol=sim_tol)
    m_fit = None if fit_samples is None else -(-int(fit_samples) // dec.factor)
    # the states answer the force applied: the command `delay` samples earlier, through the force lag
    y_motor = pb.applied_force(rec.force)
    # the first decimated row regressed, from the first iterate's own simulation (its system is the loop's first)
    first = None
    if start == "auto":
        try:
            first = (chi.copy(), pb.didim_system(chi, y_motor, fi, dec.core, with_q=True))
            start_row = settled_row(rec, first[1][3], dec)
        except DidimError:  # as start_row_of: 0 when the simulation fails (the iterations report it)
            first = None
            start_row = start_row_of(rec, pb, chi, dec, start)
    else:
        start_row = start_row_of(rec, pb, chi, dec, start)
    yd_motor = dec(rec.force)[:m_fit]
    ny = float(np.linalg.norm(yd_motor[start_row:]))  # the output errors leave the start out too
    _checks.measured_signal("force", ny, f"{method} ({kind})")

    plant = _AxisPlant(rec=rec, pb=pb, names=names, free=free, fi=fi, y_motor=y_motor, yd_motor=yd_motor, ny=ny,
                       dec=dec, m_fit=m_fit, start_row=start_row, exclude=exclude, hint=hint, tol=tol, method=method,
                       kind=kind, progress=progress, first=first)

    def give_up(loop: DidimLoop) -> Optional[str]:
        k = len(loop.history)
        if give_up_above is None or k < max(1, max_iter // 3) or not loop.best[0] > give_up_above:
            return None
        return (f"stopped after {k} iterations: the best simulated output error ({100 * loop.best[0]:.2f} %) is still "
                f"above {100 * give_up_above:.2f} %")

    loop = didim_loop(plant, chi, max_iter=max_iter, divergence_factor=divergence_factor, notes=plant.notes,
                      give_up=give_up)
    history, notes = plant.iterations, plant.notes
    chi, converged, message, n_sim, stop = loop.theta, loop.converged, loop.message, loop.simulations, loop.stop
    best = (loop.best[0], loop.best[1], loop.best[2]) if loop.best[2] is not None else (math.inf, chi, None)
    sol = loop.history[-1] if loop.history else None
    if not converged and message.startswith("no convergence"):
        message = f"no convergence in {max_iter} iterations (criterion (21) with tol = {tol})"
    if "non-physical estimate even when shortened" in message:
        message = (f"iteration {len(history) + 1}: the least-squares step makes a mass or the stiffness "
                   "non-positive even when shortened 64×; stopped")

    final_out = float("nan")
    if converged:
        try:
            if m_fit is None:
                final_out = math.sqrt(pb.squared_error(chi, yd_motor, dec.core, skip=start_row)) / ny
            else:
                final_out = float(np.linalg.norm((yd_motor - dec(pb.simulate(chi)["force"])[:m_fit])[start_row:])) / ny
            n_sim += 1
            history[-1].output_error = final_out
            if final_out > divergence_factor * best[0]:
                converged = False
                message = (
                    f"diverged: the regression converged but the simulated output error of the result "
                    f"({100 * final_out:.2f} %) exceeds {divergence_factor:g} × the best iterate's "
                    f"({100 * best[0]:.2f} %); returning the best iterate"
                )
        except (SimulationError, DataError) as e:
            converged, message = False, f"the simulation of the final estimate failed ({e})"
    if not converged and best[2] is not None:
        final_out, chi, sol = best[0], best[1], best[2]
        # the best iterate's regression estimated the next iterate: its σ stand for the returned χ, its %σ must too
        with np.errstate(divide="ignore", invalid="ignore"):
            sol = {**sol, "rel_std_pct": 100 * np.asarray(sol["std"], dtype=float) / np.abs(chi[fi])}
    elif not converged and sol is None:
        raise (type(stop) if stop is not None else SimulationError)(f"DIDIM could not start: {message}")
    notes += start_notes(start_row, dec, rec, "the regression")
    if exclude and sol is not None and sol.get("rows_kept") is not None:
        kept, total = sol["rows_kept"]
        notes.append(f"regression on {kept} of {total} decimated samples: the {total - kept} around velocity reversals "
                     "and stops are left out (their fit depends on the friction law's shape near zero speed); "
                     "reversals='keep' uses them, as the paper does")

    return IdentificationResult(
        model=kind,
        structure=model,
        method=method,
        params={n: float(chi[i]) for i, n in enumerate(names) if n in free},
        std=dict(zip(free, map(float, sol["std"]))),
        rel_std_pct=dict(zip(free, map(float, sol["rel_std_pct"]))),
        relative_error=float(sol["relative_error"]),
        output_error=final_out,
        iterations=len(history),
        simulations=n_sim,
        elapsed_s=time.perf_counter() - t0,
        converged=converged,
        message=message,
        initial={n: float(initial[n]) for n in free},
        frozen=frozen,
        history=history,
        options=dict(decimation=dec.describe(), band_hz=dec.cutoff_hz, tol=tol, substeps=substeps,
                     coulomb_eps=model.coulomb_eps, coulomb_law=model.coulomb_law, offset=model.offset,
                     terms=[t.to_dict() for t in terms], backlash_gap=model.backlash_gap, delay=model.delay,
                     force_lag=model.force_lag, integrator=integrator,
                     sim_tol=sim_tol, reversals="exclude" if exclude else "keep", start_rows_left_out=start_row),
        covariance=sol["covariance"],
        notes=notes,
    )


#: A decimated sample counts as moving when the decimated Coulomb regressor |dec sign(q̇)| reaches this (of 1).
COULOMB_SATURATED = 0.99
#: Samples around reversals are left out only while at least this share of the decimated samples remains.
MIN_MOVING_SHARE = 0.3


def _coulomb_column(free: Sequence[str]) -> Optional[int]:
    for name in ("Fc", "Fc1"):
        if name in free:
            return list(free).index(name)
    return None


def _moving_rows(w: np.ndarray, free: Sequence[str]) -> Optional[np.ndarray]:
    """The rows of the motor block where the decimated Coulomb regressor is saturated, or None (keep every row) when
    fewer than MIN_MOVING_SHARE of them are."""
    j = _coulomb_column(free)
    if j is None:
        return None
    keep = np.abs(w[:, j]) >= COULOMB_SATURATED
    if np.count_nonzero(keep) < MIN_MOVING_SHARE * len(keep) or np.count_nonzero(keep) < 4 * w.shape[1]:
        return None
    return keep


#: ``start="auto"``: a decimated row is left out of the regression when the samples before the simulation has
#: joined the record weigh this much of it (the decimated indicator of those samples).
START_LEAK = 0.01


def settled_row(rec: Recording, q_sim: np.ndarray, dec: Decimation) -> int:
    """The first decimated row past the start of a record that began away from the simulated initial state (0 when it
    began where the simulation does): the samples before the simulation (motor position ``q_sim``) has joined the
    record (:func:`didim.simulation.settling_samples`) weigh less than ``START_LEAK`` in it and every later row. On a
    robot's record (``q_sim`` (samples, joints)), the last joint to join sets it."""
    if rec.has_joint_columns:
        k = max(settling_samples(rec.qm[:, j], q_sim[:, j], rec.dt, rec.encoder_step[j] or None)
                for j in range(rec.ndof))
    else:
        k = settling_samples(rec.qm, q_sim, rec.dt, rec.position_resolution)
    return 0 if k == 0 else dec.leak_end(rec.n, k, START_LEAK)


def start_notes(skip: int, dec: Decimation, rec: Recording, left_out_of: str, option: bool = True) -> List[str]:
    """The note of a fit that left a record's start out (``skip`` decimated rows) of ``left_out_of``; none without.
    ``option``: the method has ``start='keep'``."""
    if not skip:
        return []
    where = (f"at rest {1e3 * len(rec.qr_lead) * rec.dt:.0f} ms before the record, through its lead-in"
             if len(rec.qr_lead) else "at rest on the reference")
    return [f"the record begins away from the simulation's start ({where}): the first {skip} decimated samples "
            f"({1e3 * skip * dec.factor * rec.dt:.0f} ms: the samples before the simulation joins the record, and the "
            f"decimation filter's reach) are left out of {left_out_of}"
            + ("; start='keep' uses them, as the paper does" if option else "")]


def start_row_of(rec: Recording, pb, chi: np.ndarray, dec: Decimation, start: str) -> int:
    """The first decimated row a fit uses: for ``start="auto"`` :func:`settled_row` on the simulation with χ (0 when
    it fails: the iterations report that), for ``"keep"`` 0."""
    if start not in ("auto", "keep"):
        raise DataError(f"start must be 'auto' or 'keep', got {start!r}")
    if start == "keep":
        return 0
    try:
        q = pb.simulate(chi)["q"][0]
    except DidimError:
        return 0
    return settled_row(rec, q, dec)


def _vector(params: Dict[str, float], names: Sequence[str]) -> np.ndarray:
    return np.array([params[n] for n in names], dtype=float)


#: Where rigid DIDIM is known to converge, as factors of the data's mass: the paper's 25-1000 kg on a 107 kg axis
#: (0.23-9.3), and didim's check of apM = 25-1000 kg on 56 records of 70-115 kg (0.22-14), all converged.
APM_ROBUST_RANGE = (0.2, 15.0)
#: Low-pass cutoff (Hz) of the rough rigid fit behind the default a priori mass: below the usual flexible modes.
APM_LOWPASS_HZ = 10.0


def a_priori_mass(rec: Recording) -> float:
    """The default a priori mass ``apM`` (kg), from the data alone: a rigid least-squares fit of the force on the
    measured motor position's acceleration, velocity, sign of velocity and a constant, with the position and the
    force low-passed alike (zero-phase Butterworth, order 4, at ``APM_LOWPASS_HZ``, below the flexible modes, where
    the axis moves as one mass) and differentiated by central differences. It estimates the total mass to some ten
    percent, well inside the range where rigid DIDIM converges (``APM_ROBUST_RANGE``, 0.2 to 15 times the truth). Falls back to a fit on the reference when the motor position does not give a positive mass."""
    fc = min(APM_LOWPASS_HZ, 0.2 * rec.fs)
    try:
        q = lowpass(rec.qm, fc, rec.fs, order=4)
        f = lowpass(rec.force, fc, rec.fs, order=4)
    except DataError:  # a record too short for the filter: the method's own checks will say so
        q = f = None
    if q is not None:
        qd = diffcent(q, rec.dt)
        qdd = diffcent(qd, rec.dt)
        edge = min(rec.n // 10, int(2 * rec.fs / fc))  # filter transients at both ends
        sl = slice(edge, rec.n - edge) if rec.n > 4 * edge + 8 else slice(None)
        w = np.column_stack([qdd, qd, np.sign(qd), np.ones(rec.n)])[sl]
        x, *_ = np.linalg.lstsq(w, f[sl], rcond=None)
        if np.isfinite(x[0]) and x[0] > 0:
            return float(x[0])
    qd = diffcent(rec.qr, rec.dt)
    qdd = diffcent(qd, rec.dt)
    w = np.column_stack([qdd, qd, np.sign(qd), np.ones(rec.n)])
    x, *_ = np.linalg.lstsq(w, rec.force, rcond=None)
    return float(x[0]) if x[0] > 0 else float(np.linalg.norm(rec.force) / max(np.linalg.norm(qdd), 1e-12))


def _check_apm(rec: Recording, apM: float) -> Optional[str]:
    """A warning text when a user's apM lies outside the robust range around the data's own estimate."""
    est = a_priori_mass(rec)
    lo, hi = APM_ROBUST_RANGE
    if not (lo * est <= apM <= hi * est):
        return (f"apM = {apM:.4g} kg lies outside {lo:g}-{hi:g} × the mass the data suggest ({est:.4g} kg), the range "
                "where rigid DIDIM is known to converge (the paper's 25-1000 kg on a 107 kg axis); it may not converge. Leave "
                "apM out to start from the data's estimate")
    return None


@serial_blas
def didim_rigid(rec: Recording, apM: Optional[float] = None, *, offset: Optional[bool] = None,
                cutoff_hz: float = RIGID_CUTOFF_HZ, model: Union[str, Model] = "rigid", **kw) -> IdentificationResult:
    """Step 1: rigid DIDIM from χ⁰ = (apM, 0, 0[, 0]), eq. (22), decimation cutoff 5 Hz by default; extra ``terms``
    (in ``kw``) start at 0 like the frictions. Without ``apM``, χ⁰ starts from :func:`a_priori_mass`; an ``apM``
    outside the robust range around it gives a :class:`~didim.DidimWarning`."""
    if apM is None:
        apM = a_priori_mass(rec)
    else:
        apM = _checks.real("the a priori mass apM", apM, "kg", lo=0.0)
        warning = _check_apm(rec, apM)
        if warning:
            warnings.warn(f"{rec.name or 'record'}: {warning}", DidimWarning, stacklevel=3)
    structure = {k: kw.pop(k) for k in list(kw) if k in STRUCTURE_FIELDS}
    model = as_model(model, offset=offset, **structure)
    if model.kind != "rigid":
        raise DataError(f"didim_rigid fits the rigid model, got {model.describe()}")
    init = {"M": float(apM), "Fv": 0.0, "Fc": 0.0}
    if model.offset:
        init["OF"] = 0.0
    init.update({t.name: 0.0 for t in model.terms})
    return didim_iterate(rec, model, init, cutoff_hz=cutoff_hz, **kw)


def flexible_from_mode(m_tot: float, lam: float, f_n: float) -> Dict[str, float]:
    """M1, M2 and K12 from the total mass, the mass ratio λ and the blocked-motor mode f_n_flex, eqs. (23), (24), (26)."""
    return {"M1": lam * m_tot, "M2": (1 - lam) * m_tot, "K12": 4 * math.pi**2 * (1 - lam) * f_n**2 * m_tot}


#: Eq. (28): step 2 starts cover λ in [0.1, 0.9] and f_n_flex in [10, 80] Hz; didim evaluates this grid in one
#: parallel batch and starts Nelder-Mead from its best point. The criterion's valley is narrow in f (the chirp's
#: resonance) and wide in λ, hence 8 geometric steps of 1.35 in f and 5 in λ.
MODE_GRID_LAMBDA = tuple(np.round(np.linspace(0.1, 0.9, 5), 3))
MODE_GRID_F_HZ = tuple(np.round(np.geomspace(10.0, 80.0, 8), 3))
#: The grid only ranks starting points for Nelder-Mead, which then runs at the simulator's tolerance: its simulations
#: use a position tolerance of 1e-6 of the stroke (against 1e-9 by default), which on the truthbench flexible records
#: changes the criterion by at most 6 % of itself, keeps the ranking of the best points and is 2.5-3 times faster.
GRID_SIM_TOL = 1e-6
#: Step 2's Nelder-Mead simulates at a position tolerance of 1e-7 of the stroke (force within 1e-3 of a fine
#: integration): on the truthbench flexible records its optimum f_n_flex moves by less than 0.1 % against 1e-9 (the
#: default of steps 1 and 3, which refine from it), and it runs 2-3 times faster on records played at rest, where the
#: Coulomb friction's steep slope through zero speed makes the simulator refine.
MODE_SIM_TOL = 1e-7
#: Load shares of the friction totals on the grid of the friction-split variant.
MODE_GRID_SHARE = (0.0, 0.5)
#: The friction split's grid plane (s = 0.5) is evaluated at this many best points of the paper's plane (s = 0).
GRID_SPLIT_TOP = 8
#: A step-2 optimum within this margin of the rigid model's output error explains nothing the rigid model does not.
RIGID_LIMIT_MARGIN = 0.97
#: A step-2 optimum lies above the analysed band when the decimation's zero-phase filter passes less than this share of
#: a force at its frequency (Butterworth 4 at 60 Hz: above 79 Hz; at the cutoff itself it passes half): there the
#: criterion no longer sees the mode's resonance, only a compliance any frequency above it gives.
MODE_BAND_GAIN = 0.1
#: The friction split is used when it lowers step 2's output error by more than this fraction.
SPLIT_GAIN = 0.05
#: Step 3 ending with an output error above this factor times step 2's has drifted (its model cannot hold the mode);
#: below it, a higher error than step 2's is normal (DIDIM's fixed point is not the output-error minimum).
STEP3_DRIFT_FACTOR = 1.25


class _ModeCriterion:
    """Step 2's criterion (25), ‖Y − Y_s‖/‖Y‖ on the decimated force, as a function of (λ, f_n_flex[, s]) with
    M_tot, Fv_tot, Fc_tot (and OF) from step 1: eqs. (26)-(27) put all friction on the motor (s = 0); the friction
    split (beyond the paper) puts the share s of both totals on the load side."""

    def __init__(self, rec: Recording, rigid: IdentificationResult, dec: Decimation, model: Model, numerics: dict):
        self.rec = rec
        self.rigid = rigid.params
        self.model = model  # the flexible model, with step 1's offset and friction law
        self.offset = model.offset
        self.integrator = numerics.get("integrator", "exponential")
        self._rigid_limit: Optional[float] = None
        self.dec = dec
        self.yd = dec(rec.force)
        tol = numerics.get("tol", DEFAULT_TOL)
        # a log that began away from the simulation's start: its first rows are left out, as in step 1 (start="auto";
        # the step-1 model's simulation says where the start ends)
        self.skip = 0
        if rigid.options.get("start_rows_left_out"):
            self.skip = settled_row(rec, simulate(rec, rigid).q[0], dec)
        self.ny = float(np.linalg.norm(self.yd[self.skip:]))
        _checks.measured_signal("force", self.ny, "step 2")
        self.pb = problem(rec, model, **dict(numerics, tol=max(MODE_SIM_TOL, tol)))
        self.pb_grid = problem(rec, model, **dict(numerics, tol=max(GRID_SIM_TOL, tol)))
        self.bad = 1e3  # returned for points outside the domain or that fail to simulate (relative error 100000 %)

    def params(self, lam: float, f: float, s: float = 0.0) -> Dict[str, float]:
        m, fv, fc = self.rigid["M"], self.rigid["Fv"], self.rigid["Fc"]
        p = flexible_from_mode(m, lam, f)
        d = {"M1": p["M1"], "Fv1": (1 - s) * fv, "Fc1": (1 - s) * fc, "M2": p["M2"], "Fv2": s * fv, "Fc2": s * fc,
             "K12": p["K12"]}
        if self.offset:
            d["OF"] = self.rigid["OF"]
        return d

    @staticmethod
    def valid(x) -> bool:
        return 0.0 < x[0] < 1.0 and x[1] > 0.0 and (len(x) < 3 or 0.0 <= x[2] <= 1.0)

    def batch(self, xs, tally: Optional[list] = None, coarse: bool = False) -> np.ndarray:
        """The criterion at each row of ``xs``; the number of simulations run is added to ``tally[0]``.
        ``coarse``: simulated at ``GRID_SIM_TOL``, to rank the grid's points (see there)."""
        xs = np.atleast_2d(np.asarray(xs, dtype=float))
        ok = np.array([self.valid(x) for x in xs], dtype=bool)
        out = np.full(len(xs), self.bad)
        if ok.any():
            pts = np.array([params_vector(self.model, self.params(*x))[1] for x in xs[ok]])
            if tally is not None:
                tally[0] += len(pts)
            vals, _ = (self.pb_grid if coarse else self.pb).squared_error_batch(pts, self.yd, self.dec.core,
                                                                               skip=self.skip)
            out[ok] = np.where(np.isfinite(vals), np.sqrt(np.abs(vals)) / self.ny, self.bad)
        return out

    def __call__(self, x, tally: Optional[list] = None) -> float:
        return float(self.batch([x], tally)[0])

    def rigid_limit(self, tally: Optional[list] = None) -> float:
        """The criterion of the flexible model moving as one mass (λ → 1, f_n_flex at the Nyquist frequency): what
        the rigid model explains at this decimation."""
        if self._rigid_limit is None:
            self._rigid_limit = self(np.array([0.999, 0.5 * self.rec.fs]), tally)
        return self._rigid_limit


#: Step 2's Nelder-Mead stops when the simplex spans less than MODE_XTOL relatively in f_n_flex (0.05 %, i.e. 0.1 % in
#: K12: step 3 keeps f_n_flex, so its precision is the final one) and MODE_XTOL_SHARE in λ and s (step 3 identifies
#: M1, M2 and the friction split again), and the criterion varies less than ``tol`` relatively across it.
MODE_XTOL = 5e-4
MODE_XTOL_SHARE = 5e-3
#: ... and the criterion varies across the simplex by less than this share of itself: simulated at MODE_SIM_TOL, the
#: force is within about 1e-3 of a fine integration, and the step sequence moves the criterion by that much from
#: point to point, so a tighter test is below its precision and Nelder-Mead shrinks on noise (the demo's friction
#: split took 89 iterations at 1e-4 against 27 at 1e-3, for the same f_n_flex within 0.02 %).
MODE_FTOL = 1e-3
#: The "auto" variant first runs the paper's Nelder-Mead to tolerances this many times looser: enough to compare the
#: paper's model with the friction split (the criterion is then within about a percent of its minimum), and the
#: search resumes from its simplex, at no extra cost, only when the paper's variant is the one kept.
MODE_LOOSE = 10.0


class _ModeSearch:
    """scipy's Nelder-Mead (as MATLAB's fminsearch) on step 2's criterion from x0, resumable: :meth:`run` stops at a
    tolerance and a later call continues from the simplex where it stopped (Nelder-Mead's state is its simplex), so
    a loose search followed by a tight one takes the tight search's path. f_n_flex is scaled by its start and λ, s by
    MODE_XTOL_SHARE / MODE_XTOL, so one tolerance serves all variables (the moves are invariant to this scaling: only
    the stopping test sees it). The initial simplex is evaluated in one batch."""

    def __init__(self, crit: _ModeCriterion, x0, max_iter: int, progress: Progress, label: str, tally: list):
        self.crit, self.max_iter, self.progress, self.label, self.tally = crit, max_iter, progress, label, tally
        self.x0 = np.asarray(x0, dtype=float)
        self.scale = np.full(len(x0), MODE_XTOL_SHARE / MODE_XTOL)  # scipy's xatol is one number for all coordinates
        self.scale[1] = float(x0[1])
        self.simplex = nelder_mead_simplex(self.x0 / self.scale)
        self.values = crit.batch(self.simplex * self.scale, tally)
        self.f_ref = float(self.values[0])
        self.trace: List[tuple] = []
        self.nit = 0
        self.success = False
        self.message = ""

    @property
    def x(self) -> np.ndarray:
        return self.simplex[0] * self.scale

    @property
    def fun(self) -> float:
        return float(self.values[0])

    def run(self, tol: float, loose: float = 1.0) -> "_ModeSearch":
        """Continues until the simplex spans less than ``loose`` × MODE_XTOL (scaled) and its values vary less than
        ``loose`` × ``tol`` of the criterion at the start."""
        from scipy.optimize import minimize

        def callback(uk):
            xk = uk * self.scale
            self.trace.append(tuple(map(float, xk)))
            _say(self.progress, f"step 2 ({self.label}) iteration {len(self.trace)}: " + ", ".join(
                f"{n} = {v:.4g}" for n, v in zip(("λ", "f_n_flex", "s"), xk)))

        cost = prefetch(lambda u: self.crit(u * self.scale, self.tally), lambda us: self.values, self.simplex)
        res = minimize(cost, self.simplex[0], method="Nelder-Mead", callback=callback,
                       options=dict(xatol=loose * MODE_XTOL, fatol=loose * tol * self.f_ref,
                                    maxiter=max(self.max_iter - self.nit, 1), initial_simplex=self.simplex))
        self.simplex, self.values = res.final_simplex
        self.nit += int(res.nit)
        self.success, self.message = bool(res.success), str(res.message)
        return self


def _degenerate(x, j: float, rigid_limit: float, dec: Decimation, fs_hz: float) -> str:
    """Why a step-2 optimum is not a flexible mode this record can support ('' when it is one)."""
    lam, f = float(x[0]), float(x[1])
    passed = dec.gain(f, fs_hz)
    if passed < MODE_BAND_GAIN:
        return (f"the best mode, f_n_flex = {f:.1f} Hz, lies above the analysed band (decimation cutoff "
                f"{dec.cutoff_hz:g} Hz, whose filter passes {100 * passed:.1f} % of a force at that frequency): the "
                "record does not show the flexible mode")
    if lam >= 0.97 or lam <= 0.03:
        return (f"the best mass ratio λ = {lam:.3f} puts almost all the mass on one side: the flexible model "
                "degenerates into the rigid one")
    if j >= RIGID_LIMIT_MARGIN * rigid_limit:
        return (f"the best flexible model explains the force no better than the rigid one (output error "
                f"{100 * j:.2f} % against {100 * rigid_limit:.2f} %): the record does not excite the flexible mode")
    return ""


def _mode_grid(crit: _ModeCriterion, lambda0: float, f0: float, friction_split: bool, grid_start: bool,
               tally: Optional[list] = None):
    """Step 2's starting points and their criterion (coarse, see GRID_SIM_TOL): (λ⁰, f⁰) and eq. (28)'s grid with all
    friction on the motor, then, for the friction split, the share MODE_GRID_SHARE[1] on the load at (λ⁰, f⁰) and at the
    GRID_SPLIT_TOP best points of the first plane (the mode's frequency is set by the record's resonance whatever the
    split, so the split's best start lies near the paper's)."""
    pts = [(lambda0, f0, 0.0)]
    if grid_start:
        pts += [(a, b, 0.0) for a in MODE_GRID_LAMBDA for b in MODE_GRID_F_HZ]
    pts_arr = np.array(pts)
    vals = crit.batch(pts_arr, tally, coarse=True)
    if friction_split:
        s = MODE_GRID_SHARE[1]
        top = np.argsort(vals)[:GRID_SPLIT_TOP] if grid_start else np.array([], dtype=int)
        more = np.array([(lambda0, f0, s)] + [(pts_arr[i, 0], pts_arr[i, 1], s) for i in top if i > 0])
        pts_arr = np.vstack([pts_arr, more])
        vals = np.concatenate([vals, crit.batch(more, tally, coarse=True)])
    return pts_arr, vals


def fit_flexible_mode(
    rec: Recording,
    rigid: IdentificationResult,
    *,
    lambda0: float = 0.5,
    f0: float = 40.0,
    friction_split: bool = False,
    cutoff_hz: float = FLEXIBLE_CUTOFF_HZ,
    tol: float = MODE_FTOL,
    max_iter: int = 300,
    substeps: int = 10,
    coulomb_eps: Optional[float] = None,
    coulomb_law: str = "algebraic",
    progress: Progress = None,
    integrator: str = "exponential",
    sim_tol: float = DEFAULT_TOL,
    grid_start: bool = True,
) -> IdentificationResult:
    """Step 2: Nelder-Mead on (λ, f_n_flex) with M_tot, Fv_tot, Fc_tot frozen from step 1, eqs. (23)-(28):
    M1 = λ M_tot, M2 = (1 − λ) M_tot, K12 = 4π²(1 − λ) f² M_tot, Fv1 = Fv_tot, Fc1 = Fc_tot, Fv2 = Fc2 = 0.

    Starts: eq. (28) asks for initial values covering f_n_flex in [10, 80] Hz and λ in [0.1, 0.9]. With
    ``grid_start`` (default) the criterion is evaluated on that grid (5 × 8 points, f geometric) and at (λ⁰, f⁰) in
    one parallel batch (see :func:`_mode_grid`), and Nelder-Mead starts from the best point; ``grid_start=False`` starts from (λ⁰, f⁰) alone.

    ``friction_split=True`` (beyond the paper) also fits the load share s of the friction totals, Fv2 = s Fv_tot,
    Fc2 = s Fc_tot, Fv1 = (1 − s) Fv_tot, Fc1 = (1 − s) Fc_tot: the paper's model cannot reproduce the mode when the
    load's Coulomb friction governs it (a chirp played at rest).

    The result's ``converged`` is False with a message when Nelder-Mead stops early or when the optimum is
    degenerate (λ at 0 or 1, f_n_flex above the analysed band, or no better than the rigid model, whose output
    error at this decimation is in ``options["rigid_output_error"]``): the record then does not show the mode."""
    t0 = time.perf_counter()
    _checks.options(lambda0=lambda0, f0=f0, cutoff_hz=cutoff_hz, tol=tol, max_iter=max_iter, substeps=substeps,
                    coulomb_eps=coulomb_eps)
    coulomb_eps = coulomb_eps_of(rec, coulomb_eps)
    dec = Decimation.lowpass(cutoff_hz, rec.fs)
    flexible = Model("flexible", offset=rigid.structure.offset,
                     coulomb_eps=coulomb_eps, coulomb_law=coulomb_law)
    crit = _ModeCriterion(rec, rigid, dec, flexible, dict(substeps=substeps, integrator=integrator, tol=sim_tol))
    tally = [0]
    grid = _mode_grid(crit, lambda0, f0, friction_split, grid_start, tally)
    search = _mode_search(crit, grid, friction_split, grid_start, max_iter, progress, tally)
    return _mode_result(search.run(tol), crit, grid, tally, t0, tol=tol, grid_start=grid_start)


def _mode_search(crit: _ModeCriterion, grid: tuple, friction_split: bool, grid_start: bool, max_iter: int,
                 progress: Progress, tally: list) -> _ModeSearch:
    """Step 2's Nelder-Mead, not run yet, from the best point of the grid (of its plane: s = 0 for the paper's)."""
    pts_arr, vals = grid
    dims = 3 if friction_split else 2
    use = np.full(len(pts_arr), True) if friction_split else pts_arr[:, 2] == 0.0  # the paper's: all friction on the motor
    i = int(np.flatnonzero(use)[np.argmin(vals[use])])
    x0 = pts_arr[i, :dims]
    if grid_start:
        _say(progress, f"step 2 start: {int(use.sum())} points of eq. (28)'s grid, best λ = {x0[0]:.2f}, "
             f"f_n_flex = {x0[1]:.1f} Hz" + (f", s = {x0[2]:.2f}" if dims == 3 else ""))
    if dims == 3 and x0[2] == 0.0:
        x0 = np.array([x0[0], x0[1], 0.05])  # Nelder-Mead's simplex scales by x0: start s off its bound
    return _ModeSearch(crit, x0, max_iter, progress, "friction split" if dims == 3 else "paper", tally)


def _mode_result(search: _ModeSearch, crit: _ModeCriterion, grid: tuple, tally: list, t0: float, *, tol: float,
                 grid_start: bool) -> IdentificationResult:
    """Step 2's result from its search: converged unless Nelder-Mead stopped early or the optimum is degenerate."""
    dims = len(search.x0)
    x, j = search.x, search.fun
    rigid_limit = crit.rigid_limit(tally)
    why = _degenerate(x, j, rigid_limit, crit.dec, crit.rec.fs)
    names = ["lambda", "f_n_flex", "load_share"][:dims]
    history = [Iteration(k=i + 1, params=dict(zip(names, p)), rel_std_pct={}, relative_error=float("nan"),
                         output_error=float("nan")) for i, p in enumerate(search.trace)]
    return IdentificationResult(
        model="flexible",
        method="nelder-mead (" + ", ".join(names) + ")",
        params=dict(zip(names, map(float, x))),
        std={n: float("nan") for n in names},
        rel_std_pct={n: float("nan") for n in names},
        relative_error=j,
        output_error=j,
        iterations=search.nit,
        simulations=tally[0],
        elapsed_s=time.perf_counter() - t0,
        converged=search.success and not why,
        message=why or ("" if search.success else search.message),
        initial=dict(zip(names, map(float, grid[0][0, :dims]))),
        frozen=crit.params(*x),
        history=history,
        options=dict(decimation=crit.dec.describe(), tol=tol, integrator=crit.integrator, grid_start=grid_start,
                     frozen_structure=crit.model.to_dict(),
                     nelder_mead_start=dict(zip(names, map(float, search.x0))), rigid_output_error=rigid_limit,
                     degenerate=why, friction_split=dims == 3),
    )


#: Variants of the three-step procedure: "paper" (eqs. (22)-(30) as written), "friction-split" (step 2 also fits the
#: load share of the friction, step 3 frees Fv2 and Fc2: beyond the paper), "auto" (the split when it explains the
#: record clearly better, see SPLIT_GAIN).
VARIANTS = ("auto", "paper", "friction-split")


#: The load share of the friction tried at the paper's step-2 optimum to see whether the split can do better.
SPLIT_PROBE = 0.05


def _split_needed(crit: _ModeCriterion, paper: IdentificationResult, grid: tuple, tally: Optional[list] = None) -> str:
    """Why the friction split may explain the record better than the paper's step 2 ('' when it cannot locally).

    At the paper's optimum (λ*, f*) the criterion is stationary in λ and f; if moving the share SPLIT_PROBE of the
    friction to the load raises it, the point (λ*, f*, s = 0) satisfies the optimality conditions of the split problem
    (s ≥ 0) as well, so a split Nelder-Mead from there would stay. The grid's points with friction on the load stand
    for the rest of the domain: when one of them beats every point with s = 0, another minimum may be there."""
    x = paper.params
    j0 = paper.output_error
    j_probe = crit(np.array([x["lambda"], x["f_n_flex"], SPLIT_PROBE]), tally)
    if j_probe < j0:
        return (f"a load share s = {SPLIT_PROBE:g} lowers the paper's step-2 output error from {100 * j0:.2f} % to "
                f"{100 * j_probe:.2f} %")
    pts, vals = grid
    on_load = pts[:, 2] > 0
    if on_load.any() and vals[on_load].min() < vals[~on_load].min():
        return (f"on the grid of eq. (28), friction on the load explains the record better ({100 * vals[on_load].min():.2f} "
                f"% against {100 * vals[~on_load].min():.2f} %)")
    return ""


def _step2(rec: Recording, r1: IdentificationResult, variant: str, *, lambda0: float, f0: float, cutoff_hz: float,
           grid_start: bool, progress: Progress, model: Model, numerics: dict, tol: float = MODE_FTOL,
           max_iter: int = 300):
    """Step 2 of :func:`didim_flexible` for ``variant``; returns its result (of the variant kept) and the notes that
    say which variant was kept and why.

    "auto": the grid of both planes in one batch (see :func:`_mode_grid`); the paper's Nelder-Mead to MODE_LOOSE
    times its tolerances; the split's when it may do better (:func:`_split_needed`), started also from the paper's
    optimum; the split is kept when it lowers the output error by more than SPLIT_GAIN, and otherwise the paper's
    search resumes to its full tolerance. A split that wins by less than MODE_LOOSE × tol above the margin resumes
    the paper's search before deciding, so the loose stop never decides a close call."""
    t0 = time.perf_counter()
    dec = Decimation.lowpass(cutoff_hz, rec.fs)
    crit = _ModeCriterion(rec, r1, dec, model, numerics)
    tally = [0]
    grid = _mode_grid(crit, lambda0, f0, variant != "paper", grid_start, tally)
    search = dict(grid_start=grid_start, max_iter=max_iter, progress=progress, tally=tally)
    result = dict(tol=tol, grid_start=grid_start)
    if variant == "friction-split":
        _say(progress, "step 2 (friction split, beyond the paper): Nelder-Mead on (λ, f_n_flex, s)")
        split = _mode_search(crit, grid, True, **search).run(tol)
        return _mode_result(split, crit, grid, tally, t0, **result), []

    _say(progress, "step 2: Nelder-Mead on (λ, f_n_flex)")
    paper = _mode_search(crit, grid, False, **search)
    if variant == "paper":
        return _mode_result(paper.run(tol), crit, grid, tally, t0, **result), []

    paper.run(tol, loose=MODE_LOOSE)
    loose = _mode_result(paper, crit, grid, tally, t0, **result)
    split_why = _split_needed(crit, loose, grid, tally)
    jp = loose.output_error
    if not split_why:
        r = _mode_result(paper.run(tol), crit, grid, tally, t0, **result)
        return r, [f"variant paper: all friction on the motor is a minimum of the friction-split criterion too (a load "
                   f"share s = {SPLIT_PROBE:g} raises step 2's output error from {100 * jp:.2f} %, and no point of the "
                   f"grid with friction on the load does better), so the split was not run"]

    _say(progress, "step 2 (friction split, beyond the paper): Nelder-Mead on (λ, f_n_flex, s)")
    if not loose.options["degenerate"]:
        # the paper's optimum has found the record's resonance: the split starts there too if it does better than
        # the grid's points (its f_n_flex is close already, only s and λ have to move)
        x = loose.params
        more = np.array([(x["lambda"], x["f_n_flex"], s) for s in MODE_GRID_SHARE[1:]])
        grid = (np.vstack([grid[0], more]), np.concatenate([grid[1], crit.batch(more, tally)]))
    split = _mode_result(_mode_search(crit, grid, True, **search).run(tol), crit, grid, tally, t0, **result)
    js = split.output_error
    if js >= (1 - SPLIT_GAIN) * (1 - MODE_LOOSE * tol) * jp:  # not a clear win over the loose paper optimum
        paper_r = _mode_result(paper.run(tol), crit, grid, tally, t0, **result)
        jp = paper_r.output_error
    if js < (1 - SPLIT_GAIN) * jp and not split.options["degenerate"]:
        split.simulations = tally[0]
        return split, [f"variant friction-split (beyond the paper): putting the share s = "
                       f"{split.params['load_share']:.2f} of the friction on the load lowers step 2's output error "
                       f"from {100 * jp:.2f} % (paper, all friction on the motor) to {100 * js:.2f} %, so Fv2 and Fc2 "
                       f"are identified too (the split was tried because {split_why})"]
    paper_r = _mode_result(paper.run(tol), crit, grid, tally, t0, **result)  # resumes only if not done above
    return paper_r, [f"variant paper: the friction split does not explain the record better (step 2 output error "
                     f"{100 * js:.2f} % against {100 * paper_r.output_error:.2f} % with all friction on the motor)"]


def _mass_split_drift(r: IdentificationResult) -> str:
    """Says so when step 3's second half of iterations slid M2 and K12 together (by over 5 %, the same way): the load
    row keeps their ratio, the mode, and nothing on the record pins the split of the mass ('' otherwise)."""
    h = [it.params for it in r.history if "M2" in it.params and "K12" in it.params]
    if len(h) < 6:
        return ""
    a, b = h[len(h) // 2], h[-1]
    dm, dk = b["M2"] / a["M2"] - 1, b["K12"] / a["K12"] - 1
    if abs(dm) < 0.05 or dm * dk <= 0:
        return ""
    return (f"M2 and K12 were still sliding together ({a['M2']:.4g} → {b['M2']:.4g} kg, {a['K12']:.4g} → "
            f"{b['K12']:.4g} N/m over the last {len(h) - len(h) // 2 - 1} iterations: the mode holds, the mass split drifts); the "
            f"result is the iterate with the lowest output error (M2 = {r.params.get('M2', float('nan')):.4g} kg)")


def _cannot_support(why: str, rec: Recording) -> str:
    fix = ("superimpose a small chirp (e.g. 2-40 Hz, tens of µm) on a slow constant-speed move, so the load moves "
           "in one direction while the mode is excited, or add a load encoder (ql) and use method='idim-ls'")
    return f"this record cannot support a flexible identification: {why}. To fix the experiment: {fix}"


@serial_blas
def didim_flexible(
    rec: Recording,
    apM: Optional[float] = None,
    *,
    offset: Optional[bool] = None,
    model: Union[str, Model] = "flexible",
    variant: str = "auto",
    lambda0: float = 0.5,
    f0: float = 40.0,
    rigid_cutoff_hz: float = RIGID_CUTOFF_HZ,
    cutoff_hz: float = FLEXIBLE_CUTOFF_HZ,
    tol: float = 1e-3,
    max_iter: int = 30,
    substeps: int = 10,
    coulomb_eps: Optional[float] = None,
    coulomb_law: str = "algebraic",
    progress: Progress = None,
    integrator: str = "exponential",
    sim_tol: float = DEFAULT_TOL,
    grid_start: bool = True,
    reversals: str = "auto",
    start: str = "auto",
) -> IdentificationResult:
    """The three-step procedure of section V: rigid DIDIM (step 1), Nelder-Mead on (λ, f_n_flex) (step 2, started on
    eq. (28)'s grid), DIDIM on the flexible model initialised by eqs. (29)-(30) (step 3).

    ``variant="paper"`` runs the paper's procedure: Fv2 = Fc2 = 0 throughout, the motor friction carries the totals.
    ``variant="friction-split"`` (beyond the paper) also fits the load share s of the friction in step 2 and frees Fv2
    and Fc2 in step 3 (the load row of eq. (4) keeps their ratio to M2, so step 3 keeps s). ``"auto"`` (default) evaluates
    the grid of both step 2s in one batch, runs the paper's step 2, then the split's when it may do better (see
    :func:`_split_needed`), and takes the split when it lowers step 2's output error by more than ``SPLIT_GAIN``
    (5 %) (see :func:`_step2`); the result's ``options["variant"]`` and ``notes`` say which ran and why.

    Step 3 keeps step 2's f_n_flex (the load row moves M2 and K12 together; the paper's own Tables do the same). A
    step-3 output error above step 2's is normal (DIDIM's fixed point is not the output-error minimum) and is noted;
    above ``STEP3_DRIFT_FACTOR`` (1.25) times step 2's, step 3 has drifted and the result is flagged. When step 2's optimum is degenerate (no visible mode), step 3 is not run: the result holds step 2's
    parameters with ``converged=False`` and a message naming the reason and the experiment that would fix it."""
    t0 = time.perf_counter()
    _checks.options(lambda0=lambda0, f0=f0, rigid_cutoff_hz=rigid_cutoff_hz, cutoff_hz=cutoff_hz, tol=tol,
                    max_iter=max_iter, substeps=substeps, coulomb_eps=coulomb_eps)
    _checks.one_of("variant", variant, VARIANTS)
    model = as_model(model, offset=offset, coulomb_eps=coulomb_eps, coulomb_law=coulomb_law)
    supports(model, THREE_STEP_SUPPORTS, "the three-step DIDIM")
    if model.kind != "flexible":
        raise DataError(f"the three-step DIDIM fits the flexible model, got {model.describe()}")
    model = replace(model, coulomb_eps=coulomb_eps_of(rec, model.coulomb_eps))
    coulomb_eps, coulomb_law, offset = model.coulomb_eps, model.coulomb_law, model.offset
    common = dict(substeps=substeps, integrator=integrator, sim_tol=sim_tol)
    _say(progress, "step 1: rigid DIDIM")
    rigid = Model("rigid", offset=offset, coulomb_eps=coulomb_eps, coulomb_law=coulomb_law)
    r1 = didim_rigid(rec, apM, model=rigid, cutoff_hz=rigid_cutoff_hz, tol=tol, max_iter=max_iter, progress=progress,
                     reversals=reversals, start=start, **common)
    if not r1.converged:
        # nothing sensible to start steps 2 and 3 from: hand back step 1, flagged, with its history
        r1.message = (f"step 1 (rigid DIDIM) did not converge, so steps 2 and 3 were not run and this is step 1's rigid "
                      f"result: {r1.message}")
        r1.elapsed_s = time.perf_counter() - t0
        return r1

    r2, notes = _step2(rec, r1, variant, lambda0=lambda0, f0=f0, cutoff_hz=cutoff_hz, grid_start=grid_start,
                       progress=progress, model=model,
                       numerics=dict(substeps=substeps, integrator=integrator, tol=sim_tol))
    chosen = "friction-split" if r2.options["friction_split"] else "paper"
    n_sim = r1.simulations + r2.simulations
    if r2.options["degenerate"]:
        r = IdentificationResult(
            model="flexible", structure=model, method="didim", params=dict(r2.frozen), std={}, rel_std_pct={},
            relative_error=float("nan"), output_error=r2.output_error, iterations=0, simulations=n_sim,
            elapsed_s=time.perf_counter() - t0, converged=False, message=_cannot_support(r2.options["degenerate"], rec),
            options=dict(variant=chosen, coulomb_eps=coulomb_eps, coulomb_law=coulomb_law, integrator=integrator,
                         sim_tol=sim_tol,
                         substeps=substeps), steps={"rigid": r1, "mode": r2}, notes=notes)
        return r

    _say(progress, "step 3: flexible DIDIM")
    lam, f = r2.params["lambda"], r2.params["f_n_flex"]
    init = flexible_from_mode(r1.params["M"], lam, f)
    if chosen == "paper":
        init.update({"Fv1": 0.0, "Fc1": 0.0})  # eq. (30)
        frozen = {"Fv2": 0.0, "Fc2": 0.0}
    else:
        # the load row of eq. (4) only scales the load parameters together: they start where step 2 put them
        init.update({k: r2.frozen[k] for k in ("Fv1", "Fc1", "Fv2", "Fc2")})
        frozen = {}
    if offset:
        init["OF"] = 0.0
    r3 = didim_iterate(rec, model, init, frozen=frozen, cutoff_hz=cutoff_hz, tol=tol, max_iter=max_iter,
                       progress=progress, start=start, **common)
    r3.steps = {"rigid": r1, "mode": r2}
    r3.notes = notes + r3.notes
    if r3.converged and r3.output_error > STEP3_DRIFT_FACTOR * r2.output_error:
        r3.converged = False
        r3.message = (
            f"step 3 drifted: its simulated output error ({100 * r3.output_error:.2f} %) is {r3.output_error / r2.output_error:.2f} "
            f"× step 2's ({100 * r2.output_error:.2f} %), M2 and K12 moved together from {init['M2']:.4g} kg, "
            f"{init['K12']:.4g} N/m to {r3.params['M2']:.4g} kg, {r3.params['K12']:.4g} N/m")
    elif r3.converged and r3.output_error > r2.output_error:
        r3.notes.append(f"step 3's simulated output error ({100 * r3.output_error:.2f} %) is above step 2's "
                        f"({100 * r2.output_error:.2f} %): normal, DIDIM's fixed point is not the output-error minimum")
    if not r3.converged:
        if "step 2's" not in r3.message:
            r3.message += f" (step 2's output error was {100 * r2.output_error:.2f} %)"
        slide = _mass_split_drift(r3)
        if slide:
            r3.message += "; " + slide
        if chosen == "paper":
            r3.message += (". The paper's model puts all friction on the motor; when the load's Coulomb friction "
                           "governs the mode (a chirp played with the axis at rest) it cannot reproduce it: use "
                           "variant='friction-split' or method='oe-lm', or superimpose the chirp on a slow "
                           "constant-speed move")
        else:
            r3.message += "; consider method='oe-lm'"
    if not r2.converged and not r2.options["degenerate"]:
        r3.notes.append(f"step 2 stopped without converging ({r2.message})")
    r3.options["variant"] = chosen
    r3.simulations += n_sim
    r3.elapsed_s = time.perf_counter() - t0
    r3.method = "didim"
    return r3
