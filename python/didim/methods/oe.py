"""Closed-loop output-error methods: the Nelder-Mead baselines of section VI.F and an exact-sensitivity
Levenberg-Marquardt solver whose Jacobian comes from the forward sensitivity equations integrated in Rust."""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Dict, List, Optional, Sequence, Union

import numpy as np

from .._parallel import serial_blas
from .. import _checks, _core
from .._errors import DataError, DidimError, SimulationError
from .identification import (FLEXIBLE_CUTOFF_HZ, OE_LM_SUPPORTS, SIMULATING_SUPPORTS, Progress, _say, nelder_mead_simplex, prefetch,
                             start_notes, start_row_of, supports)
from ..model import Model
from ..recording import Recording
from ..result import IdentificationResult, Iteration
from ..signal import Decimation
from ..simulation import DEFAULT_TOL, Term, coulomb_eps_of, entry_model, params_vector, problem

CRITERIA = ("force", "position")


def pseudo_regular_initial(rigid: Dict[str, float], f_n_nat: float = 30.0) -> Dict[str, float]:
    """Eq. (33): half the rigid totals on each side, K12 = π² f_n_nat² M_tot (M_eq = M_tot/4); the rigid model's
    other parameters (an offset OF) as they are."""
    m, fv, fc = rigid["M"], rigid["Fv"], rigid["Fc"]
    d = {"M1": m / 2, "Fv1": fv / 2, "Fc1": fc / 2, "M2": m / 2, "Fv2": fv / 2, "Fc2": fc / 2,
         "K12": math.pi**2 * f_n_nat**2 * m}
    return {**d, **{k: v for k, v in rigid.items() if k not in ("M", "Fv", "Fc")}}


def _check_criterion(criterion: str) -> None:
    if criterion not in CRITERIA:
        raise DataError(f"criterion must be one of {', '.join(CRITERIA)}, got {criterion!r}")


def _measured(rec: Recording, criterion: str) -> np.ndarray:
    return rec.force if criterion == "force" else rec.qm


@serial_blas
def oe_nm(
    rec: Recording,
    model: Union[str, Model],
    initial: Dict[str, float],
    *,
    criterion: str = "force",
    cutoff_hz: float = FLEXIBLE_CUTOFF_HZ,
    xatol: float = 1e-4,
    fatol: float = 1e-6,
    max_iter: int = 2000,
    substeps: int = 10,
    coulomb_eps: Optional[float] = None,
    coulomb_law: str = "algebraic",
    progress: Progress = None,
    integrator: str = "exponential",
    sim_tol: float = DEFAULT_TOL,
    terms: Sequence[Term] = (),
    backlash_gap: Optional[float] = None,
    delay: int = 0,
    force_lag: float = 0.0,
    offset: Optional[bool] = None,
    start: str = "auto",
) -> IdentificationResult:
    """Nelder-Mead (scipy's) on all parameters with J_τ = ‖τ_ddm − τ‖² or J_q = ‖q1_ddm − q1‖² (eq. (32)) on
    decimated signals. Variables are scaled by their initial values (all nonzero with eq. (33)), so ``xatol`` is
    relative; ``fatol`` is relative to the initial criterion. ``terms``, ``backlash_gap``, ``delay`` and ``force_lag``
    extend the model as for :func:`didim.simulate` (a derivative-free method needs nothing more). ``start``: as for
    DIDIM (:func:`didim.methods.identification.didim_iterate`), the decimated rows of a record's start that the simulation
    has not joined yet are left out of the criterion ("auto") or kept ("keep")."""
    from scipy.optimize import minimize

    _check_criterion(criterion)
    _checks.options(cutoff_hz=cutoff_hz, xatol=xatol, fatol=fatol, max_iter=max_iter, substeps=substeps,
                    coulomb_eps=coulomb_eps)
    initial = _checks.physical(initial, "initial")
    model = entry_model(model, initial, offset=offset, terms=tuple(terms), backlash_gap=backlash_gap, delay=delay,
                        force_lag=force_lag, coulomb_eps=coulomb_eps, coulomb_law=coulomb_law)
    supports(model, SIMULATING_SUPPORTS, "oe-nm")
    model = replace(model, coulomb_eps=coulomb_eps_of(rec, model.coulomb_eps))
    t0 = time.perf_counter()
    names, x0 = params_vector(model, initial)
    scale = np.where(x0 != 0, np.abs(x0), 1.0)
    dec = Decimation.lowpass(cutoff_hz, rec.fs)
    _checks.record_long_enough(dec, rec.n, rec.dt, len(names), 1, "oe-nm")
    yd = dec(_measured(rec, criterion))
    count = {"sim": 0}
    history: List[Iteration] = []

    pb = problem(rec, model, substeps=substeps, integrator=integrator, tol=sim_tol)
    skip = start_row_of(rec, pb, x0, dec, start)
    ny = float(np.linalg.norm(yd[skip:]))
    _checks.measured_signal("force" if criterion == "force" else "motor position", ny, "oe-nm")
    output = "force" if criterion == "force" else "position"
    penalty = 1e3 * ny**2

    def cost(z):
        count["sim"] += 1
        try:
            return pb.squared_error(np.asarray(z, dtype=float) * scale, yd, dec.core, output=output, skip=skip)
        except (SimulationError, DataError):
            return penalty

    def cost_batch(zs):
        count["sim"] += len(zs)
        vals, _ = pb.squared_error_batch(np.ascontiguousarray(zs * scale), yd, dec.core, output=output, skip=skip)
        return np.where(np.isfinite(vals), vals, penalty)

    def callback(zk):
        history.append(Iteration(k=len(history) + 1, params=dict(zip(names, map(float, zk * scale))), rel_std_pct={},
                                 relative_error=float("nan"), output_error=float("nan")))
        if len(history) % 25 == 0:
            _say(progress, f"oe-nm iteration {len(history)}, {count['sim']} simulations")

    # the initial simplex (scipy's construction) is simulated in one parallel batch
    simplex = nelder_mead_simplex(np.ones_like(x0))
    vals = cost_batch(simplex)
    j0 = float(vals[0])
    res = minimize(prefetch(cost, lambda zs: vals, simplex), np.ones_like(x0), method="Nelder-Mead", callback=callback,
                   options=dict(xatol=xatol, fatol=fatol * j0, maxiter=max_iter, maxfev=4 * max_iter,
                                initial_simplex=simplex))
    chi = res.x * scale
    out = math.sqrt(float(res.fun)) / ny
    nan = {n: float("nan") for n in names}
    return IdentificationResult(
        model=model.kind, structure=model, method=f"oe-nm ({'J_tau' if criterion == 'force' else 'J_q'})",
        params=dict(zip(names, map(float, chi))), std=dict(nan), rel_std_pct=dict(nan),
        relative_error=out, output_error=out, iterations=int(res.nit), simulations=count["sim"],
        elapsed_s=time.perf_counter() - t0, converged=bool(res.success), message="" if res.success else str(res.message),
        initial=dict(initial), history=history,
        options=dict(criterion=criterion, decimation=dec.describe(), band_hz=dec.cutoff_hz, xatol=xatol, fatol=fatol, integrator=integrator,
                     coulomb_eps=model.coulomb_eps, coulomb_law=model.coulomb_law, substeps=substeps, sim_tol=sim_tol,
                     offset=model.offset, terms=[t.to_dict() for t in model.terms], backlash_gap=model.backlash_gap,
                     delay=model.delay, force_lag=model.force_lag, start_rows_left_out=skip),
        notes=start_notes(skip, dec, rec, "the criterion"),
    )


@serial_blas
def oe_lm(
    rec: Recording,
    model: Union[str, Model],
    initial: Dict[str, float],
    *,
    criterion: str = "force",
    cutoff_hz: float = FLEXIBLE_CUTOFF_HZ,
    frozen: Optional[Dict[str, float]] = None,
    tol: float = 1e-8,
    max_iter: int = 50,
    substeps: int = 10,
    coulomb_eps: Optional[float] = None,
    coulomb_law: str = "algebraic",
    progress: Progress = None,
    integrator: str = "exponential",
    sim_tol: float = DEFAULT_TOL,
    terms: Sequence[Term] = (),
    backlash_gap: Optional[float] = None,
    delay: int = 0,
    offset: Optional[bool] = None,
    start: str = "auto",
) -> IdentificationResult:
    """Closed-loop output error by Levenberg-Marquardt with the exact Jacobian of the decimated simulated output
    (motor force, or motor position), from the forward sensitivity equations of the closed loop (controller
    included). Covariance: σ̂²(JᵀJ)⁻¹ at the solution, σ̂² = ‖r‖²/(m − p), from the same QR solver as DIDIM.
    ``terms``, ``backlash_gap`` and ``delay`` extend the model as for :func:`didim.simulate`; their sensitivities
    are exact too. ``start`` as for :func:`oe_nm`."""
    _check_criterion(criterion)
    _checks.options(cutoff_hz=cutoff_hz, tol=tol, max_iter=max_iter, substeps=substeps, coulomb_eps=coulomb_eps)
    initial = _checks.physical(initial, "initial")
    t0 = time.perf_counter()
    frozen = _checks.physical(dict(frozen or {}), "frozen")
    full = {**initial, **frozen}
    model = entry_model(model, full, offset=offset, terms=tuple(terms), backlash_gap=backlash_gap, delay=delay,
                        coulomb_eps=coulomb_eps, coulomb_law=coulomb_law)
    supports(model, OE_LM_SUPPORTS, "oe-lm (its sensitivities)")
    model = replace(model, coulomb_eps=coulomb_eps_of(rec, model.coulomb_eps))
    names, chi = params_vector(model, full)
    free = [i for i, n in enumerate(names) if n not in frozen]
    dec = Decimation.lowpass(cutoff_hz, rec.fs)
    _checks.record_long_enough(dec, rec.n, rec.dt, len(free), 1, "oe-lm")
    measured = _measured(rec, criterion)
    pb = problem(rec, model, substeps=substeps, integrator=integrator, tol=sim_tol)
    skip = start_row_of(rec, pb, chi, dec, start)
    ny = float(np.linalg.norm(dec(measured)[skip:]))
    _checks.measured_signal("force" if criterion == "force" else "motor position", ny, "oe-lm")
    output = "force" if criterion == "force" else "position"
    n_sim = 0

    def evaluate(x):
        # one call: simulation with forward sensitivities, residual measured − simulated and ∂(simulated)/∂χ,
        # decimated alike (past a record's start)
        nonlocal n_sim
        n_sim += 1
        r, jac = pb.linearize(x, measured, free, dec.core, output=output)
        return r[skip:], jac[skip:]

    try:
        r, jac = evaluate(chi)
    except (SimulationError, DataError) as e:
        raise SimulationError(f"oe-lm: the simulation with the initial parameters failed: {e}") from None
    cost = float(r @ r)
    mu = 1e-3
    history: List[Iteration] = []
    converged, message = False, ""
    for it in range(max_iter):
        with np.errstate(all="ignore"):
            d = np.sqrt(np.sum(jac**2, axis=0))
        d[d == 0] = 1.0
        # ‖J δ − r‖² = ‖R δ − Qᵀr‖² + const: the damped steps solve small (2p × p) problems on R
        step_ok, stuck = False, ""
        try:
            if not (np.all(np.isfinite(jac)) and np.all(np.isfinite(r))):
                raise np.linalg.LinAlgError("non-finite entries")
            qmat, rmat = np.linalg.qr(jac)
            qtr = qmat.T @ r
        except np.linalg.LinAlgError as e:
            stuck = (f"stopped at iteration {it + 1}: the Levenberg-Marquardt step cannot be computed ({e}): the "
                     "Jacobian overflows or is degenerate; check the parameter values and scales")
            qmat = rmat = qtr = None
        for _ in range(0 if stuck else 20):
            a = np.vstack([rmat, math.sqrt(mu) * np.diag(d)])
            b = np.concatenate([qtr, np.zeros(len(free))])
            try:
                if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
                    raise np.linalg.LinAlgError("non-finite entries")
                delta = np.linalg.lstsq(a, b, rcond=None)[0]
            except np.linalg.LinAlgError as e:
                stuck = (f"stopped at iteration {it + 1}: the Levenberg-Marquardt step cannot be computed ({e}): the "
                         "Jacobian overflows or is degenerate; check the parameter values and scales")
                break
            trial = chi.copy()
            trial[free] += delta
            try:
                r_t, j_t = evaluate(trial)
                # a trial whose sensitivities are not finite cannot carry the next step: reject it like a failure
                c_t = float(r_t @ r_t) if np.all(np.isfinite(j_t)) else math.inf
            except (SimulationError, DataError):
                c_t = math.inf
            if c_t < cost:
                step_ok = True
                break
            mu *= 4.0
        if stuck:
            message = stuck
            break
        if not step_ok:
            message = "converged: no step decreases the criterion any further"
            converged = True
            break
        rel_dec = (cost - c_t) / cost
        rel_step = float(np.max(np.abs(delta) / np.maximum(np.abs(chi[free]), 1e-12)))
        chi, r, jac, cost = trial, r_t, j_t, c_t
        mu = max(mu / 3.0, 1e-12)
        history.append(Iteration(k=it + 1, params=dict(zip(names, map(float, chi))), rel_std_pct={},
                                 relative_error=math.sqrt(cost) / ny, output_error=math.sqrt(cost) / ny))
        _say(progress, f"oe-lm iteration {it + 1}: output error {100 * math.sqrt(cost) / ny:.4f} %")
        if rel_dec < tol or rel_step < 1e-9:
            converged = True
            break
    else:
        message = f"no convergence in {max_iter} iterations"
    fnames = [names[i] for i in free]
    try:
        sol = _core.lstsq(np.ascontiguousarray(jac), np.ascontiguousarray(r))
    except DidimError as e:  # no covariance at this point (e.g. a zero Jacobian): the estimate still stands
        nan = np.full(len(fnames), np.nan)
        sol = dict(std=nan, covariance=None, condition_number=np.nan)
        message = (message + "; " if message else "") + f"no covariance: {e}"
    return IdentificationResult(
        model=model.kind, structure=model, method=f"oe-lm ({'J_tau' if criterion == 'force' else 'J_q'})",
        params={n: float(chi[i]) for i, n in enumerate(names) if i in free},
        std=dict(zip(fnames, map(float, sol["std"]))),
        rel_std_pct={n: float(100 * s / abs(chi[names.index(n)])) if chi[names.index(n)] else math.inf
                     for n, s in zip(fnames, sol["std"])},
        relative_error=math.sqrt(cost) / ny, output_error=math.sqrt(cost) / ny,
        iterations=len(history), simulations=n_sim, elapsed_s=time.perf_counter() - t0,
        converged=converged, message=message, initial=dict(initial), frozen=frozen, history=history,
        options=dict(criterion=criterion, decimation=dec.describe(), band_hz=dec.cutoff_hz, tol=tol, integrator=integrator,
                     coulomb_eps=model.coulomb_eps, coulomb_law=model.coulomb_law, substeps=substeps, sim_tol=sim_tol,
                     offset=model.offset, terms=[t.to_dict() for t in model.terms], backlash_gap=model.backlash_gap,
                     delay=model.delay, condition_number=float(sol["condition_number"]),
                     start_rows_left_out=skip),
        covariance=sol["covariance"], notes=start_notes(skip, dec, rec, "the criterion"),
    )


def check_sensitivities(
    rec: Recording,
    params,
    model: str = "flexible",
    *,
    offset: Optional[bool] = None,
    output: str = "force",
    rel_step: float = 1e-6,
    terms: Sequence[Term] = (),
    backlash_gap: Optional[float] = None,
    **sim_kw,
) -> Dict[str, float]:
    """Checks the exact forward sensitivities against central differences of the simulated ``output`` ("force" or
    "position"): the 2p perturbed simulations run as one parallel batch. Returns, per parameter, the largest
    difference relative to the largest sensitivity. With the exponential integrator a perturbation that changes the
    integrator's step sequence shows up as a local spike; ``rel_step`` of 1e-6 rarely does.
    """
    from ..simulation import simulate_batch

    from ..simulation import NUMERICS

    numerics = {k: sim_kw.pop(k) for k in NUMERICS if k in sim_kw}
    model = entry_model(model, params, offset=offset, terms=tuple(terms), backlash_gap=backlash_gap, **sim_kw)
    names, chi = params_vector(model, params)
    if output not in ("force", "position"):
        raise DataError(f"output must be 'force' or 'position', got {output!r}")
    sens = problem(rec, model, **numerics).simulate_sensitivity(chi)
    exact = sens["dforce"] if output == "force" else sens["dq"][0]
    h = rel_step * np.maximum(np.abs(chi), 1e-3)
    sets = np.vstack([chi + np.diag(h), chi - np.diag(h)])
    b = simulate_batch(rec, sets, model, **numerics)
    if not all(e is None for e in b.errors):
        raise SimulationError(f"a perturbed simulation failed: {next(e for e in b.errors if e)}")
    sim = b.force if output == "force" else b.q[:, 0, :]
    p = len(names)
    fd = (sim[:p] - sim[p:]) / (2 * h[:, None])
    scale = np.maximum(np.max(np.abs(fd), axis=1), 1e-300)
    return {n: float(np.max(np.abs(fd[j] - exact[j])) / scale[j]) for j, n in enumerate(names)}

