"""The model-mismatch doctor: locate where simulation and recording differ, name the physics that was left out,
model it, refit with DIDIM in closed loop, and keep it only when the fit improves on data the fit did not see.

The loop (``doctor``):
1. fit the base model (rigid or flexible) with DIDIM on the training part;
2. locate: the residual Y − Y_s (decimated measured minus simulated force) along time, frequency, velocity and
   position (each direction apart) and around events, with confidence bands;
3. name: each candidate effect's regressor is built from the simulated, noise-free states (with the core's basis
   functions where the effect is a model term), orthogonalized against the current model's regressor, and scored
   by a Wald test on the AR-prewhitened residual with a HAC (Newey-West) covariance; hyper-parameters (Stribeck
   speed, ripple period, backlash gap) by grid search with a Bonferroni factor for the grid; Holm's correction
   across candidates;
4. model: the best significant candidate is added to the model (simulator and regressor alike) and refitted in
   closed loop;
5. show: it is accepted only if the output error on held-out data (a validation recording, or the last part of
   the record) falls, by a one-sided Diebold-Mariano test at level ``alpha`` (HAC variance of the loss difference);
   repeat until nothing significant is left. Remaining structure that no candidate explains is reported as
   ``unnamed`` with where it lives.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from . import _checks, _core
from ._errors import DataError, DidimError, SimulationError
from ._io import jsonable as _clean
from .identification import didim_iterate
from .identification import fit_flexible_mode, flexible_from_mode, a_priori_mass
from .recording import Recording
from .result import IdentificationResult
from .signal import Decimation, diffcent
from .simulation import DEFAULT_COULOMB_EPS, SimResult, Term, coulomb_sign, param_names, simulate
from .stats import diebold_mariano, holm, orthogonalize, wald_added

#: Practical significance: an accepted effect must lower the held-out closed-loop force error by at least this share
#: of it (besides being statistically significant). Real friction differs from any smooth law, and at low noise a test
#: finds such differences; an engineer cares about an effect that changes the fit, not about one that is detectable.
MIN_HELDOUT_GAIN = 0.05
#: Practical significance of the ``unnamed`` check: structure left in the residual is reported only when its mean in
#: the worst bin of a view reaches this share of the force RMS (1 %: e.g. 0.4 N on a 44 N axis). Below that it is
#: the size of the differences between any smooth friction law and real friction, which a low-noise record makes
#: detectable but no engineer would model.
MIN_UNNAMED_SHARE = 0.01
EFFECTS = ("offset", "asymmetric_friction", "stribeck", "position_ripple", "position_dependent_coulomb", "flexibility",
           "load_friction", "coupling_damping", "delay", "backlash", "unnamed")

PHYSICS = {
    "offset": "A constant force acts on the axis whatever it does: an amplifier or current-sensor offset, a cable "
              "chain or a gravity component along the axis.",
    "asymmetric_friction": "Friction depends on the direction of motion: preload, seal or wiper drag, or a lubricant "
                           "film that differs going forward and backward.",
    "stribeck": "Friction is higher at low speed and decays as the speed grows (Stribeck effect): boundary "
                "lubrication before a fluid film forms.",
    # the same low-speed law with the other sign (a fitted Fs opposite to the Coulomb friction)
    "stribeck_deficit": "Friction is lower at low speed than the Coulomb-plus-viscous law says and recovers as the "
                        "speed grows: a low-speed friction deficit (lubricant, preload or seal behaviour that no "
                        "smooth Coulomb law captures); modelled by the Stribeck shape with the opposite sign.",
    # a Stribeck speed within a few smoothing speeds of zero (see FRICTION_SHAPE_SPEED)
    "friction_shape": "Friction reaches its Coulomb level at lower speed than the model's smoothed sign "
                      "v/sqrt(v² + ε²) (ε = 0.1 mm/s by default): the shape of the friction law through zero speed "
                      "(a sharper transition, or sticking), not necessarily a Stribeck effect; modelled by a Stribeck "
                      "term at that low speed, or by a smaller coulomb_eps.",
    "position_ripple": "A force periodic in position: motor cogging, ball-screw lead error or position-dependent "
                       "friction, with the period found in the spatial spectrum of the residual.",
    "position_dependent_coulomb": "The Coulomb friction level varies along the stroke, always against the motion "
                                  "(a preload or lubrication that changes along the screw, a worn or tight zone of a "
                                  "guide): the force flips sign with the direction, unlike a position ripple.",
    "flexibility": "The drive is not rigid: a flexible coupling (a two-mass model) shows as a resonance that the rigid "
                   "model cannot follow.",
    "load_friction": "Part of the friction acts on the load side of the coupling, so it reaches the motor through the "
                     "spring, delayed and filtered by the flexible mode.",
    "coupling_damping": "The coupling dissipates energy as it deflects (a damper in parallel with the spring: "
                        "elastomer, belt or joint friction that depends on the deflection rate): the flexible mode is "
                        "more damped than load friction alone would make it.",
    "delay": "The force is applied later than commanded: current-loop lag, communication or computation delay.",
    "backlash": "The coupling has a dead zone: the load is free over a small gap each time the force reverses.",
    "unnamed": "Structure remains in the residual that none of the candidate effects explains.",
}

#: Experiments that separate effects the record cannot tell apart.
SEPARATE = {
    frozenset({"offset", "asymmetric_friction"}): "record rests (stops) and moves in both directions: an offset acts at "
    "rest, direction-dependent friction only while moving",
    frozenset({"stribeck", "asymmetric_friction"}): "move at several low constant speeds in both directions",
    frozenset({"delay", "flexibility"}): "excite with a chirp through the expected mode and measure the load position",
    frozenset({"load_friction", "flexibility"}): "add a load encoder or move at several constant speeds",
    frozenset({"position_ripple", "position_dependent_coulomb"}): "move over the same positions in both directions: "
    "a ripple keeps its sign, position-dependent friction flips it with the direction",
    frozenset({"load_friction", "coupling_damping"}): "move at several constant speeds (load friction acts at every "
    "speed, coupling damping only while the coupling deflects) or add a load encoder",
}


@dataclass
class Finding:
    """One effect the doctor found: its name (see ``EFFECTS``), estimated parameters with σ, the evidence (test
    statistic, p-values, share of the residual it explains), the fit before and after on training and validation
    data (relative force errors), and a sentence of physics."""

    effect: str
    params: Dict[str, float]
    std: Dict[str, float]
    statistic: Dict[str, float]
    evidence: str
    physics: str
    fit: Dict[str, float] = field(default_factory=dict)
    where: Dict[str, Any] = field(default_factory=dict)
    accepted: bool = True

    def to_dict(self) -> Dict[str, Any]:
        return _clean({
            "effect": self.effect, "params": self.params, "std": self.std, "statistic": self.statistic,
            "evidence": self.evidence, "physics": self.physics, "fit": self.fit, "where": self.where,
        })


@dataclass
class State:
    """The model as the doctor grows it."""

    model: str
    params: Dict[str, float]
    frozen: Dict[str, float]
    offset: bool = False
    terms: Tuple[Term, ...] = ()
    backlash_gap: Optional[float] = None
    delay: int = 0

    def sim_kwargs(self) -> Dict[str, Any]:
        return dict(offset=self.offset, terms=self.terms, backlash_gap=self.backlash_gap, delay=self.delay)

    def all_params(self) -> Dict[str, float]:
        return {**self.frozen, **self.params}


@dataclass
class Diagnosis:
    """What the doctor found. ``findings`` lists the accepted effects (empty: nothing is missing), ``rejected`` the
    candidates that were significant on the training data but did not improve the held-out fit, ``fit`` the relative
    force errors before and after on training and validation data."""

    recording: str
    model: str
    findings: List[Finding]
    rejected: List[Finding]
    fit: Dict[str, float]
    base: IdentificationResult
    final_params: Dict[str, float]
    final_state: State
    ambiguities: List[Dict[str, Any]]
    rounds: List[Dict[str, Any]]
    locate: Dict[str, Any]
    options: Dict[str, Any]
    elapsed_s: float
    _figures: Dict[str, Any] = field(default_factory=dict, repr=False)
    _context: Dict[str, Any] = field(default_factory=dict, repr=False)

    def to_dict(self) -> Dict[str, Any]:
        return _clean({
            "recording": self.recording,
            "model": self.model,
            "findings": [f.to_dict() for f in self.findings],
            "rejected": [f.to_dict() for f in self.rejected],
            "fit": self.fit,
            "base_params": self.base.params,
            "final_params": self.final_params,
            "ambiguities": self.ambiguities,
            "rounds": self.rounds,
            "locate": {k: v for k, v in self.locate.items() if not k.startswith("_")},
            "options": self.options,
            "elapsed_s": self.elapsed_s,
        })

    def to_json(self) -> str:
        import json

        return json.dumps(self.to_dict(), indent=2)

    def to_html(self) -> str:
        from .report import diagnosis_html

        return diagnosis_html(self)

    def summary(self) -> str:
        lines = [f"doctor: {self.recording}, base model {self.model}"]
        f = self.fit
        lines.append(f"relative force error: training {100 * f['train_before']:.2f} % -> {100 * f['train_after']:.2f} %, "
                     f"validation {100 * f['valid_before']:.2f} % -> {100 * f['valid_after']:.2f} %")
        if not self.findings:
            lines.append("nothing significant is missing from the model")
        for x in self.findings:
            ps = ", ".join(f"{k} = {v:.4g}" for k, v in x.params.items())
            label = {PHYSICS["friction_shape"]: " (the friction law's shape through zero speed)",
                     PHYSICS["stribeck_deficit"]: " (a low-speed friction deficit)"}.get(x.physics, "")
            lines.append(f"- {x.effect}{label}: {ps + '; ' if ps else ''}{x.evidence}")
        for x in self.rejected:
            lines.append(f"  (not confirmed on held-out data: {x.effect}: {x.evidence})")
        for a in self.ambiguities:
            lines.append(f"  cannot tell apart {' / '.join(a['effects'])}: {a['experiment']}")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()


# ----------------------------------------------------------------------------------------------------------------


class _Data:
    """Training and validation views of the data, in the decimated domain of the doctor."""

    def __init__(self, rec: Recording, validate: Optional[Recording], dec: Decimation, holdout: float):
        self.rec, self.validate, self.dec = rec, validate, dec
        self.y = dec(rec.force)
        if validate is None:
            self.n_train = int(round(rec.n * (1 - holdout)))
            self.m_train = -(-self.n_train // dec.factor)
            self.yv = self.y[self.m_train:]
        else:
            self.n_train = rec.n
            self.m_train = len(self.y)
            self.yv = dec(validate.force)

    def errors(self, state: State) -> Tuple[np.ndarray, np.ndarray, SimResult]:
        """Decimated residuals on training and validation rows, and the training simulation."""
        sim = simulate(self.rec, state.all_params(), state.model, **state.sim_kwargs())
        ys = self.dec(sim.force)
        rt = self.y[: self.m_train] - ys[: self.m_train]
        if self.validate is None:
            rv = self.yv - ys[self.m_train:]
        else:
            simv = simulate(self.validate, state.all_params(), state.model, **state.sim_kwargs())
            rv = self.yv - self.dec(simv.force)
        return rt, rv, sim

    def rel(self, r: np.ndarray, train: bool) -> float:
        y = self.y[: self.m_train] if train else self.yv
        return float(np.linalg.norm(r) / np.linalg.norm(y))


def _refit(data: _Data, state: State, init: Dict[str, float], progress) -> Tuple[State, IdentificationResult]:
    """DIDIM refit of ``state`` (with its new terms) from ``init``, on the training samples."""
    free_init = {k: v for k, v in {**state.params, **init}.items() if k not in state.frozen}
    # every sample: the effects the doctor looks for (Stribeck, backlash, ...) live around reversals and stops
    r = didim_iterate(data.rec, state.model, free_init, frozen=state.frozen, decimation=data.dec, tol=1e-4, max_iter=30,
                  fit_samples=data.n_train, reversals="keep", **state.sim_kwargs())
    return replace(state, params=dict(r.params)), r


def _motor_columns(state: State, sim: SimResult, extra: Sequence[Term]) -> np.ndarray:
    """Columns (n × k) of the motor-row regressor of ``extra`` terms on the simulated states, from the core."""
    w = _core.regressor(state.model, sim.q, sim.qd, sim.qdd, offset=state.offset,
                        terms=[t.spec() for t in (*state.terms, *extra)], backlash_gap=state.backlash_gap)
    return w[0][:, -len(extra):]


def _base_columns(state: State, sim: SimResult) -> np.ndarray:
    w = _core.regressor(state.model, sim.q, sim.qd, sim.qdd, offset=state.offset,
                        terms=[t.spec() for t in state.terms] or None, backlash_gap=state.backlash_gap)
    from .simulation import param_names

    names = param_names(state.model, state.offset, state.terms)
    keep = [i for i, n in enumerate(names) if n not in state.frozen]
    return w[0][:, keep]


@dataclass
class _Candidate:
    effect: str
    columns: np.ndarray  # n × k, full rate
    hyper: Dict[str, float]
    grid: int  # size of the grid searched (Bonferroni factor)
    test: Any = None
    p_adj: float = 1.0
    rebuild: Optional[Callable[[float], np.ndarray]] = None  # columns for another hyper-parameter value
    step: float = 1.0  # ratio between neighbouring grid values


def _period_grid(v: np.ndarray, q: np.ndarray, rec: Recording, data: "_Data", share: float) -> Optional[np.ndarray]:
    """80 periods (m), geometric, from what the decimated record resolves at the typical speed to 1/``share`` of the
    stroke; None when the record cannot show a period."""
    stroke = float(np.ptp(q))
    moving = np.abs(v) > 0.05 * np.max(np.abs(v))
    vtyp = float(np.median(np.abs(v[moving]))) if moving.any() else 0.0
    pmin = max(4 * vtyp * rec.dt * data.dec.factor, 2e-4)
    pmax = stroke / share if stroke > 0 else 0.0
    return np.geomspace(pmin, pmax, 80) if pmax > pmin else None


def _candidates(state: State, sim: SimResult, data: _Data, done: Sequence[str]) -> List[List[_Candidate]]:
    """Every candidate effect, each as the list of its hyper-parameter variants."""
    rec = data.rec
    v, q = sim.qd[0], sim.q[0]
    out: List[List[_Candidate]] = []
    if "offset" not in done and not state.offset:
        out.append([_Candidate("offset", np.ones((rec.n, 1)), {}, 1)])
    if "asymmetric_friction" not in done:
        cols = _motor_columns(state, sim, [Term("dFv", "abs_viscous"), Term("dFc", "abs_coulomb")])
        out.append([_Candidate("asymmetric_friction", cols, {}, 1)])
    if "stribeck" not in done:
        vmax = float(np.max(np.abs(v)))
        grid = np.geomspace(max(2e-4, vmax / 500), max(vmax / 3, 3e-4), 10)
        make = lambda vs: _motor_columns(state, sim, [Term("Fs", "stribeck", vs)])  # noqa: E731
        out.append([_Candidate("stribeck", make(vs), {"vs": float(vs)}, len(grid), rebuild=make,
                               step=float(grid[1] / grid[0])) for vs in grid])
    # forces periodic in position: a ripple (same sign both ways) and Coulomb friction varying along the stroke
    # (against the motion), each searched over the same period grid, up to a third or a half of the stroke
    periodic = (("position_ripple", ("Ar_sin", "Ar_cos"), ("ripple_sin", "ripple_cos"), 3.0),
                ("position_dependent_coulomb", ("Aq_sin", "Aq_cos"), ("coulomb_ripple_sin", "coulomb_ripple_cos"), 2.0))
    for effect, names, kinds, share in periodic:
        grid = _period_grid(v, q, rec, data, share)
        if effect in done or grid is None:
            continue

        def make(P, names=names, kinds=kinds):
            return _motor_columns(state, sim, [Term(names[0], kinds[0], P), Term(names[1], kinds[1], P)])

        out.append([_Candidate(effect, make(P), {"period": float(P)}, len(grid), rebuild=make,
                               step=float(grid[1] / grid[0])) for P in grid])
    if "delay" not in done and state.delay == 0:
        out.append([_Candidate("delay", diffcent(sim.force, rec.dt)[:, None] * rec.dt, {}, 1)])
    if state.model == "rigid" and "flexibility" not in done:
        q4 = diffcent(diffcent(sim.qdd[0], rec.dt), rec.dt)
        out.append([_Candidate("flexibility", q4[:, None], {}, 1)])
    if state.model == "flexible":
        if "load_friction" not in done and state.frozen.get("Fv2", None) == 0.0:
            v12 = sim.qd[1]
            cols = np.column_stack([v12, coulomb_sign(v12)])
            out.append([_Candidate("load_friction", cols, {}, 1)])
        if "coupling_damping" not in done and not any(t.kind == "damper" for t in state.terms):
            out.append([_Candidate("coupling_damping", (sim.qd[0] - sim.qd[1])[:, None], {}, 1)])
        if "backlash" not in done and state.backlash_gap is None:
            q2 = sim.q[1] - sim.q[0]
            amp = float(np.percentile(np.abs(q2), 90))
            grid = np.geomspace(max(amp / 100, 1e-8), max(amp, 2e-8), 8)
            k12 = state.all_params()["K12"]
            out.append([_Candidate("backlash", (k12 * (np.sign(q2) * np.maximum(np.abs(q2) - g / 2, 0) - q2))[:, None],
                                   {"gap": float(g)}, len(grid)) for g in grid])
    return out


def _score(groups: List[List[_Candidate]], r: np.ndarray, wb: np.ndarray, data: _Data, a: np.ndarray) -> List[_Candidate]:
    """Best variant of each candidate, scored; Holm-adjusted p-values set in place."""
    best: List[_Candidate] = []
    for variants in groups:
        top = None
        for c in variants:
            x = data.dec.apply(np.zeros(data.rec.n), c.columns)[1][: data.m_train]
            x = orthogonalize(x, wb)
            c.test = wald_added(r, x, a)
            if top is None or c.test.p_value < top.test.p_value or (
                c.test.p_value == top.test.p_value and c.test.explained > top.test.explained
            ):
                top = c
        if top is not None and top.rebuild is not None:
            # refine the hyper-parameter between the grid neighbours of the best value
            (key, h0), = top.hyper.items()
            fine = h0 * np.geomspace(1 / top.step, top.step, 21)
            for h in fine:
                c = _Candidate(top.effect, top.rebuild(float(h)), {key: float(h)}, top.grid, rebuild=top.rebuild, step=top.step)
                x = orthogonalize(data.dec.apply(np.zeros(data.rec.n), c.columns)[1][: data.m_train], wb)
                c.test = wald_added(r, x, a)
                if c.test.explained > top.test.explained:
                    top = c
            top.grid = len(variants) + len(fine)
        if top is not None:
            best.append(top)
    raw = [min(1.0, c.test.p_value * c.grid) for c in best]
    for c, p in zip(best, holm(raw) if raw else []):
        c.p_adj = float(p)
    return sorted(best, key=lambda c: (c.p_adj, -c.test.explained))


def _coulomb(state: State) -> float:
    """The Coulomb friction on the motor side (Fc or Fc1) of a state."""
    return state.params.get("Fc", state.params.get("Fc1", 1.0))


def _model_candidate(c: _Candidate, state: State, base_result: IdentificationResult, data: _Data, progress):
    """Adds the candidate to the model and refits; returns (new state, result, reported params, std)."""
    beta = c.test.beta
    if c.effect == "offset":
        st = replace(state, offset=True)
        st, r = _refit(data, st, {"OF": float(beta[0])}, progress)
        return st, r, {"OF": st.params["OF"]}, {"OF": r.std.get("OF", math.nan)}
    if c.effect == "asymmetric_friction":
        st = replace(state, terms=state.terms + (Term("dFv", "abs_viscous"), Term("dFc", "abs_coulomb")))
        st, r = _refit(data, st, {"dFv": float(beta[0]), "dFc": float(beta[1])}, progress)
        return st, r, {k: st.params[k] for k in ("dFv", "dFc")}, {k: r.std.get(k, math.nan) for k in ("dFv", "dFc")}
    if c.effect == "stribeck":
        vs = c.hyper["vs"]
        best = None
        for f in (0.7, 1.0, 1.4):  # refine the Stribeck speed around the grid optimum
            st = replace(state, terms=state.terms + (Term("Fs", "stribeck", vs * f),))
            try:
                st, r = _refit(data, st, {"Fs": float(beta[0])}, progress)
            except DidimError:
                continue
            if best is None or r.output_error < best[1].output_error:
                best = (st, r, vs * f)
        if best is None:
            raise SimulationError("the Stribeck refit failed")
        st, r, vs = best
        # free sign: Fs opposite to the Coulomb friction is a low-speed deficit, named as such (see PHYSICS)
        return st, r, {"Fs": st.params["Fs"], "vs": vs}, {"Fs": r.std.get("Fs", math.nan)}
    if c.effect == "position_ripple":
        P = c.hyper["period"]
        st = replace(state, terms=state.terms + (Term("Ar_sin", "ripple_sin", P), Term("Ar_cos", "ripple_cos", P)))
        st, r = _refit(data, st, {"Ar_sin": float(beta[0]), "Ar_cos": float(beta[1])}, progress)
        amp = math.hypot(st.params["Ar_sin"], st.params["Ar_cos"])
        return st, r, {"amplitude": amp, "period": P, "Ar_sin": st.params["Ar_sin"], "Ar_cos": st.params["Ar_cos"]}, {
            "Ar_sin": r.std.get("Ar_sin", math.nan), "Ar_cos": r.std.get("Ar_cos", math.nan)}
    if c.effect == "position_dependent_coulomb":
        P = c.hyper["period"]
        st = replace(state, terms=state.terms + (Term("Aq_sin", "coulomb_ripple_sin", P),
                                                 Term("Aq_cos", "coulomb_ripple_cos", P)))
        st, r = _refit(data, st, {"Aq_sin": float(beta[0]), "Aq_cos": float(beta[1])}, progress)
        amp = math.hypot(st.params["Aq_sin"], st.params["Aq_cos"])
        fc = _coulomb(st)
        return st, r, {"amplitude": amp, "period": P, "relative_amplitude": amp / abs(fc) if fc else math.nan,
                       "Aq_sin": st.params["Aq_sin"], "Aq_cos": st.params["Aq_cos"]}, {
            "Aq_sin": r.std.get("Aq_sin", math.nan), "Aq_cos": r.std.get("Aq_cos", math.nan)}
    if c.effect == "delay":
        best = None
        for d in range(1, 9):  # search the delay in whole samples, upward until the fit gets clearly worse
            st = replace(state, delay=d)
            try:
                st, r = _refit(data, st, {}, progress)
            except DidimError:
                break  # a longer delay destabilises the simulated loop even more
            if best is None or r.output_error < best[1].output_error:
                best = (st, r)
            elif not r.converged or r.output_error > 1.1 * best[1].output_error:
                break  # past the minimum: longer delays only make the simulated loop less stable
        if best is None:
            raise SimulationError("the delay refit failed")
        st, r = best
        return st, r, {"delay_samples": float(st.delay), "delay_s": st.delay * data.rec.dt}, {}
    if c.effect == "flexibility":
        rigid_like = IdentificationResult(model="rigid", method="didim", params={k: state.params[k] for k in ("M", "Fv", "Fc")
                                          if k in state.params} | ({"OF": state.params["OF"]} if state.offset else {}),
                                          std={}, rel_std_pct={}, relative_error=math.nan, iterations=0, simulations=0,
                                          elapsed_s=0.0)
        # start the mode search at the residual's spectral peak (the rigid model cannot follow the resonance)
        from scipy.signal import welch

        rt, _, _ = data.errors(state)
        fs_d = data.rec.fs / data.dec.factor
        fr, pxx = welch(rt, fs=fs_d, nperseg=min(512, len(rt)))
        band = (fr >= 5.0) & (fr <= 0.45 * fs_d)
        f0 = float(fr[band][np.argmax(pxx[band])]) if band.any() else 40.0
        r2 = fit_flexible_mode(data.rec, rigid_like, f0=max(f0, 10.0), cutoff_hz=60.0)
        lam, f = r2.params["lambda"], r2.params["f_n_flex"]
        init = flexible_from_mode(state.params["M"], lam, f)
        init.update({"Fv1": state.params["Fv"], "Fc1": state.params["Fc"]})
        if state.offset:
            init["OF"] = state.params["OF"]
        extra = {t.name: state.params[t.name] for t in state.terms}
        st = State("flexible", {**init, **extra}, {"Fv2": 0.0, "Fc2": 0.0}, state.offset, state.terms, None, state.delay)
        st, r = _refit(data, st, {}, progress)
        p = st.params
        return st, r, {"f_n_flex": math.sqrt(p["K12"] / p["M2"]) / (2 * math.pi), "lambda": p["M1"] / (p["M1"] + p["M2"]),
                       "M1": p["M1"], "M2": p["M2"], "K12": p["K12"]}, {k: r.std.get(k, math.nan) for k in ("M1", "M2", "K12")}
    if c.effect == "load_friction":
        from .output_error import oe_gn

        st = replace(state, frozen={k: v for k, v in state.frozen.items() if k not in ("Fv2", "Fc2")})
        init = {**st.params, "Fv2": max(float(beta[0]), 1.0), "Fc2": max(float(beta[1]), 0.1)}
        init["Fv1"] = max(init["Fv1"] - init["Fv2"], 1.0)
        init["Fc1"] = max(init["Fc1"] - init["Fc2"], 0.1)
        r = oe_gn(data.rec, st.model, init, frozen=st.frozen, cutoff_hz=data.dec.cutoff_hz or 60.0, terms=st.terms,
                  backlash_gap=st.backlash_gap, delay=st.delay)
        st = replace(st, params=dict(r.params))
        return st, r, {"Fv2": st.params["Fv2"], "Fc2": st.params["Fc2"]}, {k: r.std.get(k, math.nan) for k in ("Fv2", "Fc2")}
    if c.effect == "coupling_damping":
        st = replace(state, terms=state.terms + (Term("C12", "damper"),))
        st, r = _refit(data, st, {"C12": max(float(beta[0]), 1.0)}, progress)
        if st.params["C12"] <= 0:
            raise SimulationError(f"the coupling damping came out non-positive (C12 = {st.params['C12']:.3g} N/(m/s)): "
                                  "not a damper")
        return st, r, {"C12": st.params["C12"]}, {"C12": r.std.get("C12", math.nan)}
    if c.effect == "backlash":
        g = c.hyper["gap"]
        st = replace(state, backlash_gap=g)
        st, r = _refit(data, st, {}, progress)
        return st, r, {"gap": g}, {}
    raise DataError(f"unknown effect {c.effect}")


_TERM_NAMES = {"asymmetric_friction": ("dFv", "dFc"), "stribeck": ("Fs",), "position_ripple": ("Ar_sin", "Ar_cos"),
               "coupling_damping": ("C12",), "position_dependent_coulomb": ("Aq_sin", "Aq_cos")}


def _without(state: State, effect: str) -> Optional[State]:
    """The state with an accepted effect taken out again (None where it cannot be, e.g. flexibility)."""
    if effect == "offset":
        return replace(state, offset=False, params={k: v for k, v in state.params.items() if k != "OF"})
    if effect in _TERM_NAMES:
        names = _TERM_NAMES[effect]
        return replace(state, terms=tuple(t for t in state.terms if t.name not in names),
                       params={k: v for k, v in state.params.items() if k not in names})
    if effect == "delay":
        return replace(state, delay=0)
    if effect == "backlash":
        return replace(state, backlash_gap=None)
    return None


def _locate(data: _Data, r: np.ndarray, sim: SimResult) -> Dict[str, Any]:
    """Residual along time, frequency, velocity and position (each direction apart), with 95 % bands; and a
    test of remaining structure per view (the ``unnamed`` check)."""
    dec, m = data.dec, data.m_train
    v = dec(sim.qd[0])[:m]
    q = dec(sim.q[0])[:m]
    fs = data.rec.fs / dec.factor
    rho = float(np.corrcoef(r[:-1], r[1:])[0, 1]) if len(r) > 3 else 0.0
    n_eff_factor = max((1 - rho) / (1 + rho), 1e-3)
    out: Dict[str, Any] = {"residual_rms": float(np.sqrt(np.mean(r**2))), "lag1_correlation": rho, "fs_hz": fs}

    def binned(x, mask, edges):
        idx = np.digitize(x[mask], edges) - 1
        rows = []
        for b in range(len(edges) - 1):
            sel = r[mask][idx == b]
            if len(sel) >= 5:
                se = float(np.std(sel, ddof=1) / math.sqrt(max(len(sel) * n_eff_factor, 1.0)))
                rows.append((float(0.5 * (edges[b] + edges[b + 1])), float(np.mean(sel)), 1.96 * se, int(len(sel))))
        return rows

    vmax = float(np.max(np.abs(v))) or 1.0
    moving = np.abs(v) > 0.02 * vmax
    out["velocity"] = {
        "forward": binned(v, moving & (v > 0), np.linspace(0.02 * vmax, vmax, 11)),
        "backward": binned(-v, moving & (v < 0), np.linspace(0.02 * vmax, vmax, 11)),
    }
    qe = np.linspace(float(q.min()), float(q.max()) + 1e-12, 13)
    out["position"] = {"forward": binned(q, moving & (v > 0), qe), "backward": binned(q, moving & (v < 0), qe)}
    t = np.arange(len(r)) / fs
    out["time"] = binned(t, np.ones(len(r), bool), np.linspace(0, t[-1] + 1e-9, 21))
    from scipy.signal import welch

    f, pxx = welch(r, fs=fs, nperseg=min(1024, len(r)))
    out["spectrum"] = {"f": f.tolist(), "psd": pxx.tolist()}
    return out


def _unnamed(data: _Data, r: np.ndarray, sim: SimResult, wb: np.ndarray, alpha: float) -> Optional[Finding]:
    """Tests the residual for structure along time, velocity and position bins; a significant view that no
    candidate explains becomes an ``unnamed`` finding saying where it lives."""
    dec, m = data.dec, data.m_train
    v = dec(sim.qd[0])[:m]
    q = dec(sim.q[0])[:m]
    n = len(r)
    views = {}
    t_idx = np.minimum((np.arange(n) * 10) // n, 9)
    views["time"] = (t_idx, [f"{k * n / 10 / (data.rec.fs / dec.factor):.2f}-{(k + 1) * n / 10 / (data.rec.fs / dec.factor):.2f} s" for k in range(10)])
    vmax = float(np.max(np.abs(v))) or 1.0
    ve = np.linspace(-vmax, vmax, 11)
    views["velocity"] = (np.clip(np.digitize(v, ve) - 1, 0, 9), [f"{ve[k]:.3g}..{ve[k + 1]:.3g} m/s" for k in range(10)])
    qe = np.linspace(q.min(), q.max() + 1e-12, 11)
    views["position"] = (np.clip(np.digitize(q, qe) - 1, 0, 9), [f"{qe[k]:.4g}..{qe[k + 1]:.4g} m" for k in range(10)])
    tests = {}
    from .stats import ar_fit

    a = ar_fit(r)
    for name, (idx, labels) in views.items():
        x = np.zeros((n, 10))
        x[np.arange(n), idx] = 1.0
        x = orthogonalize(x, wb)
        tests[name] = (wald_added(r, x, a), idx, labels)
    names = list(tests)
    padj = holm([tests[k][0].p_value for k in names])
    sig = [(names[i], padj[i]) for i in range(len(names)) if padj[i] < alpha]
    if not sig:
        return None
    name, p = min(sig, key=lambda s: s[1])
    test, idx, labels = tests[name]
    means = np.array([np.mean(r[idx == k]) if np.any(idx == k) else 0.0 for k in range(10)])
    worst = int(np.argmax(np.abs(means)))
    force_rms = float(np.sqrt(np.mean(data.y[:m] ** 2)))
    if abs(means[worst]) < MIN_UNNAMED_SHARE * force_rms:
        return None  # detectable, but too small to matter (see MIN_UNNAMED_SHARE)
    return Finding(
        effect="unnamed", params={}, std={},
        statistic={"wald": test.statistic, "dof": test.dof, "p_value": test.p_value, "p_adjusted": float(p),
                   "explained_pct": 100 * test.explained},
        evidence=f"the residual depends on {name} (Wald {test.statistic:.1f} on {test.dof} dof, adjusted p = {p:.2g}); "
                 f"largest mean residual {means[worst]:+.3g} N at {labels[worst]}",
        physics=PHYSICS["unnamed"],
        where={"view": name, "range": labels[worst], "mean_residual_N": float(means[worst])},
    )


#: A Stribeck speed below this (m/s; 10 × the Coulomb sign's default smoothing speed) describes the shape of the
#: Coulomb law's transition through zero speed, which no smooth law matches, rather than a physical Stribeck effect:
#: the finding then says so (PHYSICS["friction_shape"]).
FRICTION_SHAPE_SPEED = 10 * DEFAULT_COULOMB_EPS

#: Decimated training samples the doctor needs: its base fit, a candidate's few parameters and the AR-prewhitened
#: residual tests (up to AR(8)) have no power on fewer.
MIN_ROWS = 40


def doctor(
    recording: Recording,
    model: str = "rigid",
    validate: Optional[Recording] = None,
    *,
    apM: Optional[float] = None,
    alpha: float = 0.01,
    max_findings: int = 4,
    cutoff_hz: float = 40.0,
    holdout: float = 0.3,
    progress: Optional[Callable[[str], None]] = None,
) -> Diagnosis:
    """Diagnoses what the ``model`` ("rigid" or "flexible") misses on ``recording``; ``validate`` is a recording the
    fit does not see (otherwise the last ``holdout`` share of the record is held out). ``alpha`` is the family-wise
    level of the candidate tests and of the held-out confirmation. ``cutoff_hz`` is the decimation cutoff of the fits
    and of the residual analysis."""
    if model not in ("rigid", "flexible"):
        raise DataError(f"unknown model {model!r}: use rigid or flexible")
    from .recording import Recording

    for what, rec in (("recording", recording), ("validate", validate)):
        if (rec is not None or what == "recording") and not isinstance(rec, Recording):
            raise DataError(f"{what} must be a didim.Recording (read a file with didim.load_record), got "
                            f"{type(rec).__name__}")
    alpha = _checks.real("alpha", alpha, lo=0.0, hi=0.5, hint=" (family-wise test level)")
    if validate is None and not (0.1 <= _checks.real("holdout", holdout) <= 0.5):
        raise DataError(f"holdout must be between 0.1 and 0.5 of the record, got {holdout}")
    max_findings = _checks.whole("max_findings", max_findings, lo=0, hi=20)
    _checks.options(cutoff_hz=cutoff_hz)
    if apM is not None:
        apM = _checks.real("the a priori mass apM", apM, "kg", lo=0.0)
    if progress is not None and not callable(progress):
        raise DataError(f"progress must be a function taking a message (or None), got {type(progress).__name__}")
    _checks.excitation(recording.qr, recording.u_ext, param_names(model, False))
    t0 = time.perf_counter()
    say = progress or (lambda s: None)
    dec = Decimation.lowpass(cutoff_hz, recording.fs)
    n_fit = recording.n if validate is not None else int(recording.n * (1 - holdout))
    _checks.record_long_enough(dec, n_fit, recording.dt, MIN_ROWS, 1, "the doctor",
                               of="(the minimum of its fits and tests; the validation share is held out)")
    data = _Data(recording, validate, dec, holdout)

    # 1. base fit
    m0 = apM if apM is not None else a_priori_mass(recording)
    say(f"base fit: DIDIM {model}")
    if model == "rigid":
        state = State("rigid", {"M": m0, "Fv": 0.0, "Fc": 0.0}, {})
        state, base = _refit(data, state, {}, progress)
    else:
        from .identification import didim_flexible

        # the paper's base model (all friction on the motor): load friction is one of the effects to name
        fl = didim_flexible(recording, m0, variant="paper", reversals="keep")
        state = State("flexible", dict(fl.params), dict(fl.frozen))
        state, base = _refit(data, state, {}, progress)

    rt, rv, sim = data.errors(state)
    fit0 = {"train_before": data.rel(rt, True), "valid_before": data.rel(rv, False)}
    locate_before = _locate(data, rt, sim)
    findings: List[Finding] = []
    rejected: List[Finding] = []
    ambiguities: List[Dict[str, Any]] = []
    rounds: List[Dict[str, Any]] = []
    done: List[str] = []
    history = [(state, rt, rv, sim)]

    from .stats import ar_fit

    for rnd in range(max_findings):
        wb = orthogonalize(data.dec.apply(np.zeros(recording.n), _base_columns(state, sim))[1][: data.m_train], np.zeros((data.m_train, 0)))
        a = ar_fit(rt)
        ranked = _score(_candidates(state, sim, data, done), rt, wb, data, a)
        rounds.append({"round": rnd + 1, "candidates": [
            {"effect": c.effect, "hyper": c.hyper, "wald": c.test.statistic, "dof": c.test.dof, "p_value": c.test.p_value,
             "p_adjusted": c.p_adj, "explained_pct": 100 * c.test.explained} for c in ranked]})
        significant = [c for c in ranked if c.p_adj < alpha]
        say(f"round {rnd + 1}: " + ", ".join(f"{c.effect} p={c.p_adj:.2g} ({100 * c.test.explained:.1f} %)" for c in ranked[:4]))
        if not significant:
            break
        accepted = False
        tries = significant[:2]
        # a mode near the top of the analysed band looks like a delay (a phase lag): when either is a leading candidate
        # of a rigid model, its partner in ambiguity is tried too, even when not significant on its own (a whole-sample
        # delay's residual is mostly taken by the flexibility candidate's test, and the other way round)
        for lead, partner in (("delay", "flexibility"), ("flexibility", "delay")):
            if state.model == "rigid" and any(c.effect == lead for c in tries) and partner not in done \
                    and not any(c.effect == partner for c in tries):
                tries += [c for c in ranked if c.effect == partner]
        for c in tries:
            try:
                st_new, res, params, std = _model_candidate(c, state, base, data, progress)
                rt_n, rv_n, sim_n = data.errors(st_new)
            except DidimError as e:
                rejected.append(Finding(c.effect, {}, {}, {"p_adjusted": c.p_adj}, f"refit failed: {e}", PHYSICS[c.effect],
                                        accepted=False))
                done.append(c.effect)
                continue
            dm, p_dm, gain = diebold_mariano(rv, rv_n)
            stat = {"wald": c.test.statistic, "dof": c.test.dof, "p_value": c.test.p_value, "p_adjusted": c.p_adj,
                    "explained_pct": 100 * c.test.explained, "dm_statistic": dm, "dm_p_value": p_dm,
                    "valid_mse_reduction_pct": 100 * gain}
            fit = {"train_before": data.rel(rt, True), "train_after": data.rel(rt_n, True),
                   "valid_before": data.rel(rv, False), "valid_after": data.rel(rv_n, False)}
            evidence = (f"explains {100 * c.test.explained:.1f} % of the prewhitened training residual (Wald {c.test.statistic:.1f} "
                        f"on {c.test.dof} dof, adjusted p = {c.p_adj:.2g}); held-out error {100 * fit['valid_before']:.2f} % -> "
                        f"{100 * fit['valid_after']:.2f} % (Diebold-Mariano p = {p_dm:.2g})")
            practical = fit["valid_after"] < (1 - MIN_HELDOUT_GAIN) * fit["valid_before"]
            if p_dm < alpha and not practical:
                evidence += (f"; below the practical threshold: an effect must lower the held-out force error by at "
                             f"least {100 * MIN_HELDOUT_GAIN:.0f} % of itself")
            physics = PHYSICS[c.effect]
            if c.effect == "stribeck" and params["Fs"] * _coulomb(st_new) < 0:
                physics = PHYSICS["stribeck_deficit"]
            elif c.effect == "stribeck" and params["vs"] < FRICTION_SHAPE_SPEED:
                physics = PHYSICS["friction_shape"]
            f = Finding(c.effect, params, std, stat, evidence, physics, fit,
                        where={"hyper": c.hyper}, accepted=p_dm < alpha and practical)
            done.append(c.effect)
            if f.accepted:
                # effects the record cannot tell from this one
                for other in significant:
                    if other is c:
                        continue
                    xo = data.dec.apply(np.zeros(recording.n), other.columns)[1][: data.m_train]
                    xc = data.dec.apply(np.zeros(recording.n), c.columns)[1][: data.m_train]
                    xo, xc = orthogonalize(xo, wb), orthogonalize(xc, wb)
                    res_o = orthogonalize(xo, xc)
                    share = 1 - float(np.sum(res_o**2) / max(np.sum(xo**2), 1e-300))
                    if share > 0.9:
                        key = frozenset({c.effect, other.effect})
                        ambiguities.append({"effects": [c.effect, other.effect], "shared_pct": 100 * share,
                                            "experiment": SEPARATE.get(key, "excite the axis differently (other speeds, rests, both directions)")})
                findings.append(f)
                state, rt, rv, sim = st_new, rt_n, rv_n, sim_n
                # the model changed: candidates rejected on the old one get another chance on the new one
                done = [x.effect for x in findings]
                history.append((state, rt, rv, sim))
                accepted = True
                say(f"accepted {c.effect}: {evidence}")
                # backward pass: an earlier finding the new one makes redundant is taken out again
                for old in [x for x in findings[:-1] if x.effect != "unnamed"]:
                    st_drop = _without(state, old.effect)
                    if st_drop is None:
                        continue
                    try:
                        st_drop, _ = _refit(data, st_drop, {}, progress)
                        rt_d, rv_d, sim_d = data.errors(st_drop)
                    except DidimError:
                        continue
                    _, p_keep, _ = diebold_mariano(rv_d, rv)
                    if p_keep >= alpha:
                        old.accepted = False
                        old.evidence += f"; taken out again once {c.effect} was modelled (held-out error without it " \
                                        f"{100 * data.rel(rv_d, False):.2f} %, Diebold-Mariano p = {p_keep:.2g})"
                        findings.remove(old)
                        rejected.append(old)
                        state, rt, rv, sim = st_drop, rt_d, rv_d, sim_d
                        say(f"removed {old.effect}: no longer improves the held-out fit")
                break
            rejected.append(f)
            say(f"rejected {c.effect}: {evidence}")
        if not accepted and len(done) >= len(EFFECTS) - 1:
            break

    wb = data.dec.apply(np.zeros(recording.n), _base_columns(state, sim))[1][: data.m_train]
    un = _unnamed(data, rt, sim, wb, alpha)
    if un is not None:
        findings.append(un)
    fit = {**fit0, "train_after": data.rel(rt, True), "valid_after": data.rel(rv, False)}
    diag = Diagnosis(
        recording=recording.name or "recording", model=model, findings=findings, rejected=rejected, fit=fit, base=base,
        final_params=state.all_params(), final_state=state, ambiguities=ambiguities, rounds=rounds,
        locate={"before": locate_before, "after": _locate(data, rt, sim)},
        options=dict(alpha=alpha, max_findings=max_findings, cutoff_hz=cutoff_hz, holdout=None if validate else holdout,
                     validation=(validate.name or "validation recording") if validate else f"last {int(100 * holdout)} % of the record"),
        elapsed_s=time.perf_counter() - t0,
    )
    diag._context = {"data": data, "history": history}
    return diag


__all__ = ["doctor", "Diagnosis", "Finding", "EFFECTS", "PHYSICS"]
