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
exact-sensitivity solver (:func:`oe_gn`) has no such restriction.
"""

from __future__ import annotations

import math
import time
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np

from . import _checks, _core
from ._errors import DataError, DidimError, IdentifiabilityError, SimulationError
from .recording import Recording
from .result import IdentificationResult, Iteration
from .signal import Decimation, diffcent, lowpass
from .simulation import DEFAULT_COULOMB_EPS, DEFAULT_TOL, param_names, params_vector, problem

Progress = Optional[Callable[[str], None]]

#: Decimation cutoffs of the paper: 5 Hz for the rigid step, 60 Hz for the flexible steps.
RIGID_CUTOFF_HZ = 5.0
FLEXIBLE_CUTOFF_HZ = 60.0


def _say(progress: Progress, msg: str) -> None:
    if progress is not None:
        progress(msg)


def _solve(w: np.ndarray, y: np.ndarray, names: Sequence[str], sigma: str = "paper") -> dict:
    """QR least squares; raises IdentifiabilityError naming dependent columns."""
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
            "or fix some of them"
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


def _idim_system(rec: Recording, model: str, offset: bool, lowpass_hz: float, lowpass_order: int, padding: str,
                 border: int, dec: Decimation, coulomb_eps: float, zoh_align: bool):
    """The decimated IDIM-LS system (Y, W) of a record (both rows of eq. (4) for the flexible model)."""
    if model == "flexible" and rec.ql is None:
        raise DataError("IDIM-LS of the flexible model needs the load position ql (a second encoder); use method='didim'")
    if not (0 <= border < rec.n // 2):
        raise DataError(f"border must be between 0 and half the record ({rec.n // 2}), got {border}")
    positions = [rec.qm] + ([rec.ql] if model == "flexible" else [])
    q = np.array([lowpass(x, lowpass_hz, rec.fs, order=lowpass_order, padding=padding) for x in positions])
    qd = diffcent(q, rec.dt)
    qdd = diffcent(qd, rec.dt)
    w = _core.regressor(model, q, qd, qdd, coulomb_eps=coulomb_eps, offset=offset)
    force = rec.force
    if zoh_align:
        force = np.concatenate([force[:1], 0.5 * (force[1:] + force[:-1])])
    rows = [(force[border:], w[0, border:, :])]
    if model == "flexible":
        rows.append((np.zeros(rec.n - border), w[1, border:, :]))
    return _stack_rows(rows, dec)


def idim_cross_test(rec: Recording, result: IdentificationResult) -> float:
    """Relative error ‖Y − Wχ̂‖/‖Y‖ of an IDIM-LS result on another record, built with the same recipe."""
    o = result.options
    dec = result.options.get("_decimation") or Decimation.matlab(10)
    y, w = _idim_system(rec, result.model, "OF" in result.params, o["lowpass_hz"], o["lowpass_order"], o["padding"],
                        o["border"], dec, o["coulomb_eps"], o["zoh_align"])
    chi = np.array([result.params[n] for n in param_names(result.model, "OF" in result.params)])
    return float(np.linalg.norm(y - w @ chi) / np.linalg.norm(y))


def idim_ls(
    rec: Recording,
    model: str = "rigid",
    *,
    offset: bool = False,
    lowpass_hz: float = 100.0,
    lowpass_order: int = 4,
    padding: str = "matlab",
    border: int = 49,
    decimation: Optional[Decimation] = None,
    sigma: str = "paper",
    coulomb_eps: float = 0.0,
    zoh_align: bool = False,
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
    """
    t0 = time.perf_counter()
    _checks.options(lowpass_hz=lowpass_hz, lowpass_order=lowpass_order, border=border, coulomb_eps=coulomb_eps,
                    zoh_align=zoh_align)
    _checks.one_of("sigma", sigma, ("paper", "sample_std"))
    names = param_names(model, offset)
    dec = decimation or Decimation.matlab(10)
    _checks.decimation_matches(dec, rec.fs)
    _checks.record_long_enough(dec, rec.n - min(border, rec.n - 1), rec.dt, len(names), 2 if model == "flexible" else 1,
                               "IDIM-LS")
    y, wd = _idim_system(rec, model, offset, lowpass_hz, lowpass_order, padding, border, dec, coulomb_eps, zoh_align)
    sol = _solve(wd, y, names, sigma)
    p = dict(zip(names, map(float, sol["params"])))
    return IdentificationResult(
        model=model,
        method="idim-ls",
        params=p,
        std=dict(zip(names, map(float, sol["std"]))),
        rel_std_pct=dict(zip(names, map(float, sol["rel_std_pct"]))),
        relative_error=float(sol["relative_error"]),
        iterations=1,
        simulations=0,
        elapsed_s=time.perf_counter() - t0,
        options=dict(lowpass_hz=lowpass_hz, lowpass_order=lowpass_order, padding=padding, border=border,
                     decimation=dec.describe(), _decimation=dec, sigma=sigma, coulomb_eps=coulomb_eps, zoh_align=zoh_align,
                     condition_number=float(sol["condition_number"])),
        covariance=sol["covariance"],
    )


# --------------------------------------------------------------------------------------------------------------------
# DIDIM
# --------------------------------------------------------------------------------------------------------------------


def _output_error(yd: np.ndarray, sim_force: np.ndarray, dec: Decimation) -> float:
    return float(np.linalg.norm(yd - dec(sim_force)[: len(yd)]) / np.linalg.norm(yd))


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


def didim(
    rec: Recording,
    model: str,
    initial: Dict[str, float],
    *,
    frozen: Optional[Dict[str, float]] = None,
    offset: bool = False,
    cutoff_hz: Optional[float] = None,
    decimation: Optional[Decimation] = None,
    tol: float = 1e-3,
    max_iter: int = 30,
    substeps: int = 10,
    coulomb_eps: float = DEFAULT_COULOMB_EPS,
    divergence_factor: float = 1.02,
    progress: Progress = None,
    method: str = "didim",
    terms: Sequence = (),
    backlash_gap: Optional[float] = None,
    delay: int = 0,
    fit_samples: Optional[int] = None,
    integrator: str = "exponential",
    sim_tol: float = DEFAULT_TOL,
) -> IdentificationResult:
    """DIDIM iterations, eqs. (16)-(21): simulate the closed loop with χᵏ, build the IDM regressor of the simulated
    (noise-free) states, decimate Y and W in parallel, solve by QR for χᵏ⁺¹; stop when
    |‖ρₖ₊₁‖ − ‖ρₖ‖|/‖ρₖ‖ ≤ tol (eq. (21)).

    ``initial`` gives χ⁰ for the estimated parameters, ``frozen`` the parameters held at fixed values. Divergence
    (the simulated output error growing beyond ``divergence_factor`` times its best value twice in a row, or a
    simulation that fails) stops the iteration: the result then holds the iterate with the lowest output error and
    ``converged=False`` with a message saying what happened. ``fit_samples`` restricts the regression and the
    output errors to the first samples (the rest of the record is then held out for validation). ``integrator``,
    ``sim_tol`` and ``substeps`` choose the simulator's scheme (see :func:`didim.simulate`); ``terms``,
    ``backlash_gap`` and ``delay`` extend the model (see :func:`didim.simulate`).
    """
    t0 = time.perf_counter()
    _checks.options(tol=tol, max_iter=max_iter, substeps=substeps, coulomb_eps=coulomb_eps,
                    divergence_factor=divergence_factor, cutoff_hz=cutoff_hz)
    initial = _checks.physical(initial, "initial")
    frozen = _checks.physical(dict(frozen or {}), "frozen")
    names = param_names(model, offset, terms)
    unknown = [k for k in list(initial) + list(frozen) if k not in names]
    if unknown:
        raise DataError(f"unknown parameter(s) {', '.join(unknown)} for the {model} model ({', '.join(names)})")
    free = [n for n in names if n not in frozen]
    missing = [n for n in free if n not in initial]
    if missing:
        raise DataError(f"initial values missing for {', '.join(missing)}")
    if decimation is None:
        cutoff = cutoff_hz if cutoff_hz is not None else (RIGID_CUTOFF_HZ if model == "rigid" else FLEXIBLE_CUTOFF_HZ)
        decimation = Decimation.lowpass(cutoff, rec.fs)
    dec = decimation
    _checks.decimation_matches(dec, rec.fs)
    _checks.record_long_enough(dec, rec.n, rec.dt, len(free), 2 if model == "flexible" else 1, f"{method} ({model})")
    fi = [names.index(n) for n in free]
    chi = np.array([initial.get(n, frozen.get(n, 0.0)) for n in names], dtype=float)
    pb = problem(rec, model, offset=offset, substeps=substeps, coulomb_eps=coulomb_eps, integrator=integrator, tol=sim_tol,
                 terms=terms, backlash_gap=backlash_gap, delay=delay)
    m_fit = None if fit_samples is None else -(-int(fit_samples) // dec.factor)
    yd_motor = dec(rec.force)[:m_fit]
    ny = float(np.linalg.norm(yd_motor))
    _checks.measured_signal("force", ny, f"{method} ({model})")
    y_motor = rec.force
    if delay:  # the states answer the force applied, which is the command `delay` samples earlier
        y_motor = np.concatenate([np.zeros(delay), rec.force[:-delay]])

    history: List[Iteration] = []
    best = (math.inf, chi.copy(), None)  # (output error, χ, solution)
    n_sim, worse, converged, message = 0, 0, False, ""
    rho_prev = None
    sol = None
    stop: Optional[DidimError] = None  # the error that stopped the iterations, re-raised if there is no iterate
    for k in range(max_iter):
        # one call: simulate with χᵏ, build W of the simulated states, decimate Y, W and the simulated force
        try:
            y_all, w_all, force_dec = pb.didim_system(chi, y_motor, fi, dec.core)
            if m_fit is not None:  # keep the training rows of each dof's block
                m = len(force_dec)
                keep = np.concatenate([np.arange(d * m, d * m + m_fit) for d in range(len(y_all) // m)])
                y_all, w_all, force_dec = y_all[keep], w_all[keep], force_dec[:m_fit]
        except (SimulationError, DataError) as e:
            message = f"iteration {k}: the simulation with χ{k} failed ({e}); stopped"
            stop = e
            break
        n_sim += 1
        out_err = float(np.linalg.norm(yd_motor - force_dec)) / ny
        if history:
            history[-1].output_error = out_err
        if out_err < best[0]:
            best, worse = (out_err, chi.copy(), sol), 0
        elif out_err > divergence_factor * best[0]:
            worse += 1
            if worse >= 2:
                message = (
                    f"diverged: the simulated output error grew from {100 * best[0]:.2f} % to {100 * out_err:.2f} % "
                    f"(iteration {k}); returning the iterate with the lowest output error. The initial values are "
                    "probably too far from the truth, or the model misses a physical effect"
                )
                break
        try:
            sol = _solve(w_all, y_all, free)
        except IdentifiabilityError as e:
            message = f"iteration {k + 1}: {e}"
            stop = e
            break
        chi = chi.copy()
        chi[fi] = sol["params"]
        rho = float(sol["residual_norm"])
        history.append(
            Iteration(
                k=k + 1,
                params=dict(zip(names, map(float, chi))),
                rel_std_pct=dict(zip(free, map(float, sol["rel_std_pct"]))),
                relative_error=float(sol["relative_error"]),
                output_error=float("nan"),
            )
        )
        _say(progress, f"{method} {model} iteration {k + 1}: ‖Y−Wχ‖/‖Y‖ = {100 * sol['relative_error']:.3f} %, "
             f"output error of χ{k} = {100 * out_err:.3f} %")
        if rho_prev is not None and abs(rho - rho_prev) / rho_prev <= tol:
            converged = True
            break
        rho_prev = rho
    else:
        message = f"no convergence in {max_iter} iterations (criterion (21) with tol = {tol})"

    final_out = float("nan")
    if converged:
        try:
            if m_fit is None:
                final_out = math.sqrt(pb.output_error(chi, yd_motor, dec.core)) / ny
            else:
                final_out = float(np.linalg.norm(yd_motor - dec(pb.simulate(chi)["force"])[:m_fit])) / ny
            n_sim += 1
            history[-1].output_error = final_out
            if final_out > divergence_factor * best[0]:
                converged = False
                message = (
                    f"diverged: the regression converged but the simulated output error of the result "
                    f"({100 * final_out:.2f} %) exceeds the best iterate's ({100 * best[0]:.2f} %); returning the best iterate"
                )
        except (SimulationError, DataError) as e:
            converged, message = False, f"the simulation of the final estimate failed ({e})"
    if not converged and best[2] is not None:
        final_out, chi, sol = best[0], best[1], best[2]
    elif not converged and sol is None:
        raise (type(stop) if stop is not None else SimulationError)(f"DIDIM could not start: {message}")

    return IdentificationResult(
        model=model,
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
        options=dict(decimation=dec.describe(), tol=tol, substeps=substeps, coulomb_eps=coulomb_eps, offset=offset,
                     terms=[t.spec() for t in terms], backlash_gap=backlash_gap, delay=delay, integrator=integrator),
        covariance=sol["covariance"],
    )


def reference_mass(rec: Recording) -> float:
    """A rough a priori mass (kg) from the reference alone: least squares of the measured force on the reference's
    acceleration, velocity and sign of velocity. Used only when no a priori value ``apM`` is given."""
    qd = diffcent(rec.qr, rec.dt)
    qdd = diffcent(qd, rec.dt)
    w = np.column_stack([qdd, qd, np.sign(qd), np.ones(rec.n)])
    x, *_ = np.linalg.lstsq(w, rec.force, rcond=None)
    return float(x[0]) if x[0] > 0 else float(np.linalg.norm(rec.force) / max(np.linalg.norm(qdd), 1e-12))


def didim_rigid(rec: Recording, apM: Optional[float] = None, *, offset: bool = False, cutoff_hz: float = RIGID_CUTOFF_HZ,
                **kw) -> IdentificationResult:
    """Step 1: rigid DIDIM from χ⁰ = (apM, 0, 0[, 0]), eq. (22), decimation cutoff 5 Hz by default."""
    if apM is None:
        apM = reference_mass(rec)
    apM = _checks.real("the a priori mass apM", apM, "kg", lo=0.0)
    init = {"M": float(apM), "Fv": 0.0, "Fc": 0.0}
    if offset:
        init["OF"] = 0.0
    return didim(rec, "rigid", init, offset=offset, cutoff_hz=cutoff_hz, **kw)


def flexible_from_mode(m_tot: float, lam: float, f_n: float) -> Dict[str, float]:
    """M1, M2 and K12 from the total mass, the mass ratio λ and the blocked-motor mode f_n_flex, eqs. (23), (24), (26)."""
    return {"M1": lam * m_tot, "M2": (1 - lam) * m_tot, "K12": 4 * math.pi**2 * (1 - lam) * f_n**2 * m_tot}


def fit_flexible_mode(
    rec: Recording,
    rigid: IdentificationResult,
    *,
    lambda0: float = 0.5,
    f0: float = 40.0,
    cutoff_hz: float = FLEXIBLE_CUTOFF_HZ,
    tol: float = 1e-4,
    max_iter: int = 300,
    substeps: int = 10,
    coulomb_eps: float = DEFAULT_COULOMB_EPS,
    progress: Progress = None,
    integrator: str = "exponential",
    sim_tol: float = DEFAULT_TOL,
    grid_start: bool = False,
) -> IdentificationResult:
    """Step 2: Nelder-Mead on (λ, f_n_flex) with M_tot, Fv_tot, Fc_tot frozen from step 1, eqs. (23)-(28):
    M1 = λ M_tot, M2 = (1 − λ) M_tot, K12 = 4π²(1 − λ) f² M_tot, Fv1 = Fv_tot, Fc1 = Fc_tot, Fv2 = Fc2 = 0.

    ``grid_start=True`` (not in the paper) first evaluates the criterion on a coarse grid, λ in 0.1..0.9 (9 values)
    times f_n_flex in 3..2·cutoff_hz Hz (10 values, geometric), in one parallel batch with (λ⁰, f⁰), and starts the
    Nelder-Mead from the best of them: the result then no longer depends on (λ⁰, f⁰) (see docs/robustness.md)."""
    from scipy.optimize import minimize

    t0 = time.perf_counter()
    _checks.options(lambda0=lambda0, f0=f0, cutoff_hz=cutoff_hz, tol=tol, max_iter=max_iter, substeps=substeps,
                    coulomb_eps=coulomb_eps)
    offset = "OF" in rigid.params
    m, fv, fc = rigid.params["M"], rigid.params["Fv"], rigid.params["Fc"]
    dec = Decimation.lowpass(cutoff_hz, rec.fs)
    yd = dec(rec.force)
    ny = float(np.linalg.norm(yd))
    _checks.measured_signal("force", ny, "step 2")
    count = {"sim": 0}
    trace: List[tuple] = []

    def chi(lam, f):
        p = flexible_from_mode(m, lam, f)
        d = {"M1": p["M1"], "Fv1": fv, "Fc1": fc, "M2": p["M2"], "Fv2": 0.0, "Fc2": 0.0, "K12": p["K12"]}
        if offset:
            d["OF"] = rigid.params["OF"]
        return d

    pb = problem(rec, "flexible", offset=offset, substeps=substeps, coulomb_eps=coulomb_eps, integrator=integrator,
                 tol=sim_tol)
    penalty = 1e3 * ny**2

    def vector(lam, f):
        return params_vector("flexible", chi(lam, f), offset)[1]

    def cost(x):
        lam, f = float(x[0]), float(x[1])
        if not (0.0 < lam < 1.0 and f > 0.0):
            return penalty
        count["sim"] += 1
        try:
            return pb.output_error(vector(lam, f), yd, dec.core)
        except (SimulationError, DataError):
            return penalty

    def cost_batch(xs):
        ok = [(0.0 < x[0] < 1.0 and x[1] > 0.0) for x in xs]
        out = np.full(len(xs), penalty)
        if any(ok):
            pts = np.array([vector(float(x[0]), float(x[1])) for x, g in zip(xs, ok) if g])
            count["sim"] += len(pts)
            vals, _ = pb.output_error_batch(pts, yd, dec.core)
            out[np.flatnonzero(ok)] = np.where(np.isfinite(vals), vals, penalty)
        return out

    def callback(xk):
        trace.append((float(xk[0]), float(xk[1])))
        _say(progress, f"step 2 iteration {len(trace)}: λ = {xk[0]:.4f}, f_n_flex = {xk[1]:.3f} Hz")

    initial = (lambda0, f0)
    if grid_start:
        pts = np.array([(a, b) for a in np.linspace(0.1, 0.9, 9) for b in np.geomspace(3.0, 2 * cutoff_hz, 10)]
                       + [(lambda0, f0)])
        g = cost_batch(pts)
        lambda0, f0 = map(float, pts[int(np.argmin(g))])
        _say(progress, f"step 2 grid start: {len(pts)} points, best λ = {lambda0:.3f}, f_n_flex = {f0:.2f} Hz")
    simplex = nelder_mead_simplex([lambda0, f0])
    vals = cost_batch(simplex)
    j0 = float(vals[0])
    res = minimize(prefetch(cost, lambda xs: vals, simplex), [lambda0, f0], method="Nelder-Mead", callback=callback,
                   options=dict(xatol=1e-4, fatol=tol * j0, maxiter=max_iter, initial_simplex=simplex))
    lam, f = map(float, res.x)
    j = float(res.fun)
    history = [Iteration(k=i + 1, params={"lambda": a, "f_n_flex": b}, rel_std_pct={}, relative_error=float("nan"),
                         output_error=float("nan")) for i, (a, b) in enumerate(trace)]
    return IdentificationResult(
        model="flexible",
        method="nelder-mead (λ, f_n_flex)",
        params={"lambda": lam, "f_n_flex": f},
        std={"lambda": float("nan"), "f_n_flex": float("nan")},
        rel_std_pct={"lambda": float("nan"), "f_n_flex": float("nan")},
        relative_error=math.sqrt(j) / ny,
        output_error=math.sqrt(j) / ny,
        iterations=int(res.nit),
        simulations=count["sim"],
        elapsed_s=time.perf_counter() - t0,
        converged=bool(res.success),
        message="" if res.success else str(res.message),
        initial={"lambda": initial[0], "f_n_flex": initial[1]},
        frozen={k: v for k, v in chi(lam, f).items()},
        history=history,
        options=dict(decimation=dec.describe(), tol=tol, integrator=integrator, grid_start=grid_start,
                     nelder_mead_start={"lambda": lambda0, "f_n_flex": f0}),
    )


def didim_flexible(
    rec: Recording,
    apM: Optional[float] = None,
    *,
    offset: bool = False,
    lambda0: float = 0.5,
    f0: float = 40.0,
    rigid_cutoff_hz: float = RIGID_CUTOFF_HZ,
    cutoff_hz: float = FLEXIBLE_CUTOFF_HZ,
    tol: float = 1e-3,
    max_iter: int = 30,
    substeps: int = 10,
    coulomb_eps: float = DEFAULT_COULOMB_EPS,
    progress: Progress = None,
    integrator: str = "exponential",
    sim_tol: float = DEFAULT_TOL,
    grid_start: bool = False,
) -> IdentificationResult:
    """The three-step procedure of section V: rigid DIDIM (step 1), Nelder-Mead on (λ, f_n_flex) (step 2), DIDIM on
    the flexible model initialised by eqs. (29)-(30) (step 3). Fv2 and Fc2 are held at zero (the paper's choice) and
    the motor friction carries the totals; see the module docstring for why. When the axis has load-side friction,
    steps 2 and 3 are biased and step 3 can drift: the result is then flagged ``converged=False`` with the reason,
    and :func:`didim.output_error.oe_gn` (exact sensitivities) is the method to use."""
    t0 = time.perf_counter()
    _checks.options(lambda0=lambda0, f0=f0, rigid_cutoff_hz=rigid_cutoff_hz, cutoff_hz=cutoff_hz, tol=tol,
                    max_iter=max_iter, substeps=substeps, coulomb_eps=coulomb_eps)
    common = dict(substeps=substeps, coulomb_eps=coulomb_eps, integrator=integrator, sim_tol=sim_tol)
    _say(progress, "step 1: rigid DIDIM")
    r1 = didim_rigid(rec, apM, offset=offset, cutoff_hz=rigid_cutoff_hz, tol=tol, max_iter=max_iter, progress=progress, **common)
    if not r1.converged:
        # nothing sensible to start steps 2 and 3 from: hand back step 1, flagged, with its history
        r1.message = (f"step 1 (rigid DIDIM) did not converge, so steps 2 and 3 were not run and this is step 1's rigid "
                      f"result: {r1.message}")
        r1.elapsed_s = time.perf_counter() - t0
        return r1
    _say(progress, "step 2: Nelder-Mead on (λ, f_n_flex)")
    r2 = fit_flexible_mode(rec, r1, lambda0=lambda0, f0=f0, cutoff_hz=cutoff_hz, progress=progress,
                           grid_start=grid_start, **common)
    _say(progress, "step 3: flexible DIDIM")
    init = flexible_from_mode(r1.params["M"], r2.params["lambda"], r2.params["f_n_flex"])
    init.update({"Fv1": 0.0, "Fc1": 0.0})
    frozen = {"Fv2": 0.0, "Fc2": 0.0}
    if offset:
        init["OF"] = 0.0
    r3 = didim(rec, "flexible", init, frozen=frozen, offset=offset, cutoff_hz=cutoff_hz, tol=tol, max_iter=max_iter,
               progress=progress, **common)
    r3.steps = {"rigid": r1, "mode": r2}
    if r3.converged and r3.output_error > r2.output_error * 1.02:
        r3.converged = False
        r3.message = (
            f"step 3 ended with a simulated output error of {100 * r3.output_error:.2f} %, worse than step 2's "
            f"{100 * r2.output_error:.2f} %: the flexible DIDIM drifted (typical of load-side friction, which the "
            "three-step procedure freezes at zero); use method='oe-gn'"
        )
    elif not r3.converged:
        r3.message += f" (step 2's output error was {100 * r2.output_error:.2f} %); consider method='oe-gn'"
    if not r2.converged:
        r3.message = (r3.message + "; " if r3.message else "") + f"note: step 2 stopped without converging ({r2.message})"
    r3.simulations += r1.simulations + r2.simulations
    r3.elapsed_s = time.perf_counter() - t0
    r3.method = "didim"
    return r3
