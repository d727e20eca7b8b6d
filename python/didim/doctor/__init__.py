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
   the record) falls, by a one-sided Diebold-Mariano test on the absolute errors at level ``alpha`` (HAC variance
   of the loss difference), and by at least ``MIN_HELDOUT_GAIN`` of itself;
   repeat until nothing significant is left. Remaining structure that no candidate explains is reported as
   ``unnamed`` with where it lives.

Layout: :mod:`.effects` holds one :class:`~didim.doctor.effects.Effect` per effect it can name (the registry),
:mod:`.fit` the model as the doctor grows it and its refit; this module the rounds, the tests and the diagnosis.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from .. import _checks, units
from .._errors import DataError, DidimError
from .._parallel import serial_blas
from ..formats._io import jsonable as _clean
from ..methods.identification import a_priori_mass
from ..recording import Recording
from ..result import IdentificationResult
from ..signal import Decimation, welch
from ..model import Model
from ..simulation import SimResult, coulomb_eps_of, default_coulomb_eps, param_names
from ..stats import ar_fit, diebold_mariano, holm, orthogonalize, prewhiten, wald_added, wald_groups, wald_whitened
from .effects import (FRICTION_SHAPE, REGISTRY, STRIBECK_DEFICIT, UNNAMED, Candidate, Effect, final_values,
                      params_text, separating_experiment)
from .._parallel import cores
from .fit import Data, State, fit_friction_law, refit
from .finding import AMBIGUOUS_SHARE, HELDOUT_LOSS, MIN_HELDOUT_GAIN, Finding
from .ranking import best_variant, holm_ranked as _holm_ranked
from .words import lead_in_words, start_words

#: Practical significance of the ``unnamed`` check: structure left in the residual is reported only when its mean in
#: the worst bin of a view reaches this share of the force RMS (1 %: e.g. 0.4 N on a 44 N axis). Below that it is
#: the size of the differences between any smooth friction law and real friction, which a low-noise record makes
#: detectable but no engineer would model.
MIN_UNNAMED_SHARE = 0.01
#: An earlier finding's hyper-parameter chosen again on a changed model (``Effect.retune``) replaces it only when the
#: training output error falls by more than this share of it.
RETUNE_GAIN = 1e-3
#: The names of the effects the doctor can report (see :data:`didim.doctor.effects.REGISTRY`), and ``unnamed``.
EFFECTS = tuple(REGISTRY) + ("unnamed",)
#: The sentence of physics of each effect, and of the variants a fitted Stribeck term can turn out to be.
PHYSICS = {**{name: e.physics for name, e in REGISTRY.items()}, "stribeck_deficit": STRIBECK_DEFICIT,
           "friction_shape": FRICTION_SHAPE, "unnamed": UNNAMED}

#: Decimated training samples the doctor needs: its base fit, a candidate's few parameters and the AR-prewhitened
#: residual tests (up to AR(8)) have no power on fewer.
MIN_ROWS = 40


@dataclass
class Diagnosis:
    """What the doctor found. ``findings`` lists the accepted effects (empty: nothing is missing), ``rejected`` the
    candidates that were significant on the training data but did not improve the held-out fit, ``fit`` the relative
    force errors before and after on training and validation data: ``train_force_*``/``valid_force_*`` the closed-loop
    force error at the full rate (the measure of ``result.force_error``), ``train_*``/``valid_*`` on the decimated
    force the tests work on."""

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
            "options": {k: v for k, v in self.options.items() if not k.startswith("_")},
            "elapsed_s": self.elapsed_s,
        })

    def to_json(self) -> str:
        import json

        return json.dumps(self.to_dict(), indent=2)

    @property
    def final_result(self) -> IdentificationResult:
        """The final model as a result: ``didim.simulate(rec, d.final_result)`` simulates it, ``.save("m.json")``
        keeps it for ``didim simulate RECORD m.json``. Its ``force_error`` is the full-rate closed-loop force error
        on the training samples (``fit["train_force_after"]``)."""
        st = self.final_state
        return IdentificationResult(
            model=st.kind, method="doctor (DIDIM refit)", params=dict(st.params), std={}, rel_std_pct={},
            relative_error=float("nan"), iterations=len(self.rounds), simulations=0, elapsed_s=self.elapsed_s,
            frozen=dict(st.frozen), structure=st.model, force_error=self.fit["train_force_after"],
            notes=[f"the doctor's final model: {', '.join(f.effect for f in self.findings) or 'the base model'}"])

    def to_html(self) -> str:
        from ..report import diagnosis_html

        return diagnosis_html(self)

    def summary(self) -> str:
        """What the doctor found, in an engineer's words first (the final model's quantities with units, forward and
        backward apart, the held-out force error each finding brought), then the statistics in a details section
        (the parameters as each effect was accepted)."""
        lines = [f"doctor: {self.recording}, base model {self.model}"]
        f = self.fit
        starts = self.locate.get("start", [])
        after = {x["record"]: f" ({100 * x['force_error_after_start']:.2f} % after its start)" for x in starts}
        valid_name = self.options.get("_valid_record")
        steps = [x.fit.get("valid_force_after") for x in self.findings if x.effect != "unnamed"]
        last = steps[-1] if steps else None
        retuned = (last is not None and math.isfinite(last)
                   and f"{100 * last:.2f}" != f"{100 * f['valid_force_after']:.2f}")
        lines.append(f"closed-loop force error: training {100 * f['train_force_before']:.2f} % -> "
                     f"{100 * f['train_force_after']:.2f} %{after.get(self.recording, '')}, validation "
                     f"({self.options['validation']}) {100 * f['valid_force_before']:.2f} % -> "
                     f"{100 * f['valid_force_after']:.2f} %{after.get(valid_name, '') if valid_name else ''}"
                     + (f" (the final model; the last finding below ended at {100 * last:.2f} %, before an earlier "
                        "one's hyper-parameter or the friction law was chosen again)" if retuned else ""))
        if self.options.get("controller_origin"):
            lines.append(f"no controller was described: the {self.options['controller_origin']}")
        for name, c in (self.options.get("controller_check") or {}).items():
            if c is not None:
                lines.append(f"controller check ({name}): the law on the logged qr and qm gives the logged force "
                             f"within {100 * c['mismatch']:.3g} %" + ("" if c["passed"] else " (NOT within "
                                                                    f"{100 * c['tolerance']:g} %: {c['likely'] or 'no usual mistake explains it'})"))
        law = self.final_state.model if self.final_state is not None else self.base.structure
        if law is not None and law.coulomb_eps is not None:
            how = {"fitted": "fitted in closed loop", "given": "given",
                   "default": "didim's default for the record"}[self.options.get("friction_law", "default")]
            lines.append(f"friction law through zero speed ({how}): {law.coulomb_law}, smoothing speed "
                         f"{units.speed(law.coulomb_eps, self.base.axis)}")
        for ld in self.locate.get("lead_in", []):
            lines.append("lead-in: " + lead_in_words(ld))
        for st in self.locate.get("start", []):
            lines.append("start: " + start_words(st))
        if not self.findings:
            lines.append("nothing significant is missing from the model")
        for x in self.findings:
            label = {PHYSICS["friction_shape"]: " (the friction law's shape through zero speed)",
                     PHYSICS["stribeck_deficit"]: " (a low-speed friction deficit)"}.get(x.physics, "")
            text = x.words or x.evidence
            gain = x.held_out()
            twins = [e for a in self.ambiguities if a.get("equal") and x.effect in a["effects"]
                     for e in a["effects"] if e != x.effect]
            if twins:  # the record cannot tell them apart: no pick of one as the physics
                label += f" or {' or '.join(dict.fromkeys(twins))} (this record cannot tell them apart: see below)"
            lines.append(f"- {x.effect}{label}: {text}" + (f"; {gain}" if gain and x.words else ""))
        accepted = {x.effect for x in self.findings}
        if any(x.effect not in accepted for x in self.rejected):
            # an effect tried on several models appears once, with its last try, and not when a later try was
            # accepted (every try is in the details)
            last = {x.effect: x for x in self.rejected if x.effect not in accepted}
            lines.append("not confirmed on held-out data: " + "; ".join(
                f"{x.effect} ({x.held_out() or x.evidence}{'; ' + x.note if x.note else ''})" for x in last.values()))
        for a in self.ambiguities:
            lines.append(f"this record cannot tell apart {' / '.join(a['effects'])}; the experiment that would: "
                         f"{a['experiment']}")
        if not self.findings and not self.rejected:
            return "\n".join(lines)
        lines.append(f"details (each effect's values when it was accepted; the tests work on the force low-passed at "
                     f"{self.options['cutoff_hz']:g} Hz and decimated: training "
                     f"{100 * f['train_before']:.2f} % -> {100 * f['train_after']:.2f} %, validation "
                     f"{100 * f['valid_before']:.2f} % -> {100 * f['valid_after']:.2f} %):")
        for x in self.findings + self.rejected:
            ps = params_text(x.effect, x.params, self.base.axis)
            rnd = f" (round {x.where['round']})" if "round" in x.where else ""
            lines.append(f"  {x.effect}{rnd}: {ps + '; ' if ps else ''}{x.evidence}")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()


def _test_all(cands: List[Candidate], r: np.ndarray, wb: np.ndarray, data: Data, a: np.ndarray) -> None:
    """Sets each candidate's Wald test. The (decimated) columns of all of them are orthogonalized to the base
    columns ``wb`` and prewhitened in one pass (both act column by column), then tested together by their normal
    equations (:func:`didim.stats.wald_groups`): the ranking's tests at a fraction of the cost for the grids of
    hyper-parameters. Each candidate keeps the one-by-one SVD test (``exact``) on the same columns, which
    :func:`_best_of` sets on the variant it keeps: an adopted effect's refit starts from that test's coefficients, and
    DIDIM stops within its tolerance of wherever its start leads (from the normal equations' coefficients, 3e-11 apart,
    a Stribeck hump on truthbench/axes was adopted at 2.889 N instead of 2.893 N)."""
    if not cands:
        return
    # stacked column by column (Fortran order), as the core gives them: the product in orthogonalize then runs the
    # BLAS on the same layout as for the columns of any other call, and gives each column the same bits
    x = orthogonalize(np.concatenate([np.asarray(c.columns, dtype=float).T for c in cands], axis=0).T, wb)
    rw, xw = prewhiten(a, r, x)
    ends = np.cumsum([c.columns.shape[1] for c in cands])
    for c, t, e in zip(cands, wald_groups(rw, xw, [c.columns.shape[1] for c in cands]), ends):
        c.test = t
        c.exact = (lambda s=int(e - c.columns.shape[1]), e=int(e): wald_whitened(rw, xw[:, s:e]))


def _score(groups: List[List[Candidate]], r: np.ndarray, wb: np.ndarray, data: Data, a: np.ndarray) -> List[Candidate]:
    """Best variant of each candidate, scored; Holm-adjusted p-values set in place."""
    best = [c for c in (_best_of(variants, r, wb, data, a) for variants in groups) if c is not None]
    return _holm_ranked(best)


def _best_of(variants: List[Candidate], r: np.ndarray, wb: np.ndarray, data: Data, a: np.ndarray) -> Optional[Candidate]:
    """The best variant of one effect's candidates, its hyper-parameter refined between grid neighbours
    (:func:`best_variant`)."""
    def refine(top: Candidate) -> List[Candidate]:
        if top.rebuild is None:
            return []
        (key, h0), = top.hyper.items()
        fine = h0 * np.geomspace(1 / top.step, top.step, 21)
        return [Candidate(top.effect, x, {key: float(h)}, top.grid, rebuild=top.rebuild, step=top.step)
                for h, x in zip(fine, top.rebuild(fine))]

    return best_variant(variants, lambda cs: _test_all(cs, r, wb, data, a), refine)


def _locate(data: Data, r: np.ndarray, sim: SimResult) -> Dict[str, Any]:
    """Residual along time, frequency, velocity and position (each direction apart), with 95 % bands; and a
    test of remaining structure per view (the ``unnamed`` check)."""
    dec, rows = data.dec, data.train_rows
    v = dec(sim.qd[0])[rows]
    q = dec(sim.q[0])[rows]
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
    t = (data.t0 + np.arange(len(r))) / fs
    out["time"] = binned(t, np.ones(len(r), bool), np.linspace(t[0], t[-1] + 1e-9, 21))
    f, pxx = welch(r, fs=fs, nperseg=min(1024, len(r)))
    out["spectrum"] = {"f": f.tolist(), "psd": pxx.tolist()}
    return out


#: :func:`_start`: the start is reported when it holds at least this share of the record's residual energy.
START_SHARE = 0.1


def _start(rec: Recording, state: State) -> Optional[Dict[str, Any]]:
    """Where a record starts in motion or off the reference (the log began after the closed loop did), the first
    samples of the closed-loop simulation, which starts at rest on the reference (or before the record's lead-in),
    differ from it whatever the model:
    how long, how much of the residual energy that is, and the force error without those samples."""
    sim = state.simulate(rec)
    k, after = sim.settled(rec)
    if k == 0:
        return None
    r = rec.force - sim.force
    energy = float(r @ r)
    share = float(r[:k] @ r[:k]) / energy if energy > 0 else 0.0
    if share < START_SHARE:
        return None
    return {"record": rec.name or "recording", "initial_gap_m": float(abs(sim.q[0][0] - rec.qm[0])), "samples": int(k),
            "seconds": float(k * rec.dt), "residual_share": share,
            "force_error_after_start": after, "lead_in": bool(rec.qr_lead.size)}


def _lead_in(rec: Recording) -> Optional[Dict[str, Any]]:
    """A record's lead-in (:attr:`Recording.qr_lead`): the stretch before the log that the simulation runs through."""
    lead = rec.qr_lead
    if not lead.size:
        return None
    return {"record": rec.name or "recording", "samples": int(lead.size), "seconds": float(lead.size * rec.dt),
            "speed_m_s": float((rec.qr[1] - lead[-1]) / (2 * rec.dt)), "rest_m": float(lead[0]),
            "first_m": float(rec.qr[0]), "reconstructed": isinstance(rec.lead_in, str)}


def _unnamed(data: Data, r: np.ndarray, sim: SimResult, wb: np.ndarray, alpha: float) -> Optional[Finding]:
    """Tests the residual for structure along time, velocity and position (each direction of motion apart: friction
    that varies along the stroke flips its sign with the direction and cancels in a pooled view); a significant view
    that no candidate explains becomes an ``unnamed`` finding saying where it lives.

    The velocity and position views prewhiten with an AR model fitted on the residual *without* that view's bin
    means (the innovations under the alternative): an AR fitted on the residual itself takes smooth structure for
    noise and whitens most of it away (97 % of a 6 N position-dependent friction). The time view keeps the AR of the
    residual itself: slow drifts of coloured noise are structure in time, which that AR should take."""
    dec, rows = data.dec, data.train_rows
    v = dec(sim.qd[0])[rows]
    q = dec(sim.q[0])[rows]
    n = len(r)
    fs = data.rec.fs / dec.factor
    axis = data.rec.axis  # the labels in the record's kind of units (mm or rad)
    views = {}
    every = np.ones(n, bool)
    t_idx = np.minimum((np.arange(n) * 10) // n, 9)
    t0 = data.t0 / fs
    views["time"] = (t_idx, every, [f"{t0 + k * n / 10 / fs:.2f}-{t0 + (k + 1) * n / 10 / fs:.2f} s"
                                    for k in range(10)])
    vmax = float(np.max(np.abs(v))) or 1.0
    ve = np.linspace(-vmax, vmax, 11)
    views["velocity"] = (np.clip(np.digitize(v, ve) - 1, 0, 9), every,
                         [f"{units.speed(ve[k], axis)} to {units.speed(ve[k + 1], axis)}" for k in range(10)])
    qe = np.linspace(q.min(), q.max() + 1e-12, 11)
    q_idx = np.clip(np.digitize(q, qe) - 1, 0, 9)
    moving = np.abs(v) > 0.02 * vmax
    for way, mask in (("forward", moving & (v > 0)), ("backward", moving & (v < 0))):
        views[f"position, moving {way}"] = (q_idx, mask, [
            f"{units.length(qe[k], axis)} to {units.length(qe[k + 1], axis)}, moving {way}" for k in range(10)])
    tests = {}
    for name, (idx, mask, labels) in views.items():
        x = np.zeros((n, 10))
        x[np.flatnonzero(mask), idx[mask]] = 1.0
        x = orthogonalize(x[:, x.any(axis=0)], wb)
        if x.shape[1] == 0:
            continue
        if name == "time":  # slow drifts of coloured noise are time structure too: the AR may take them
            a = ar_fit(r)
        else:
            beta, *_ = np.linalg.lstsq(x, r, rcond=None)
            a = ar_fit(r - x @ beta)
        tests[name] = (wald_added(r, x, a), np.where(mask, idx, -1), labels)
    names = list(tests)
    padj = holm([tests[k][0].p_value for k in names])
    sig = [(names[i], padj[i]) for i in range(len(names)) if padj[i] < alpha]
    if not sig:
        return None
    name, p = min(sig, key=lambda s: s[1])
    test, idx, labels = tests[name]
    means = np.array([np.mean(r[idx == k]) if np.any(idx == k) else 0.0 for k in range(10)])
    worst = int(np.argmax(np.abs(means)))
    force_rms = float(np.sqrt(np.mean(data.y[rows] ** 2)))
    if abs(means[worst]) < MIN_UNNAMED_SHARE * force_rms:
        return None  # detectable, but too small to matter (see MIN_UNNAMED_SHARE)
    return Finding(
        effect="unnamed", params={}, std={},
        statistic={"wald": test.statistic, "dof": test.dof, "p_value": test.p_value, "p_adjusted": float(p),
                   "explained_pct": 100 * test.explained},
        evidence=f"the residual depends on {name} (Wald {test.statistic:.1f} on {test.dof} dof, adjusted p = {p:.2g}); "
                 f"largest mean residual {'+' if means[worst] > 0 else ''}{units.force(means[worst], axis)} at {labels[worst]}",
        physics=UNNAMED,
        where={"view": name, "range": labels[worst], "mean_residual_N": float(means[worst])},
    )


def _check_arguments(recording, model, validate, apM, alpha, max_findings, cutoff_hz, holdout, progress):
    if model not in ("rigid", "flexible"):
        raise DataError(f"unknown model {model!r}: use rigid or flexible")
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
    if validate is not None and validate.n == recording.n and np.array_equal(validate.force, recording.force) \
            and np.array_equal(validate.qr, recording.qr):
        raise DataError("the validation record is the training record (the same force and reference): its errors would "
                        "not be held out; give another run of the axis, or leave validate out to hold out the last "
                        f"{100 * holdout:.0f} % of the record")
    return apM, alpha, max_findings


def _base_fit(data: Data, model: str, apM: Optional[float], progress,
              coulomb_eps: Union[str, float, None] = "fit") -> Tuple[State, IdentificationResult]:
    """The base model fitted by DIDIM on the training part: rigid from the a priori mass (with didim's default
    friction law or the given one: the doctor fits the law after :meth:`_Search.before_law`), flexible by the paper's
    three steps (all friction on the motor: load friction is one of the effects to name)."""
    m0 = apM if apM is not None else a_priori_mass(data.rec)
    axis = data.rec.axis
    fit = isinstance(coulomb_eps, str)
    if fit and coulomb_eps != "fit":
        raise DataError(f"coulomb_eps must be 'fit', a speed or None, got {coulomb_eps!r}")
    eps = coulomb_eps_of(data.rec, None if fit else coulomb_eps)
    if model == "rigid":
        return refit(data, State(Model("rigid", coulomb_eps=eps), {"M": m0, "Fv": 0.0, "Fc": 0.0}, {}, axis=axis), {},
                     progress)
    from ..methods.identification import didim_flexible

    fl = didim_flexible(data.rec, m0, variant="paper", reversals="keep")
    if fl.model != "flexible":
        # step 1 (rigid) failed, so there are no flexible parameters to start from (a step 3 that drifted for want of
        # load friction is a start: the doctor refits it and names what is missing)
        raise BaseFitError(f"no flexible base fit on {data.rec.name or 'the record'}: {fl.message or 'it did not converge'}"
                           "; the doctor needs a converged base model (try model='rigid', or a record that shows the "
                           "flexible mode: see didim.identify(record, 'flexible'))")
    mode = fl.steps.get("mode")
    if mode is not None and mode.options.get("degenerate"):
        # step 2 found no flexible mode the record shows: a flexible base would be a rigid one with a mode the data
        # cannot hold (on DATA_EMPS, 87 Hz above the 60 Hz band: its validation force error was 313 %)
        raise BaseFitError(f"no flexible base fit on {data.rec.name or 'the record'}: {fl.message}; diagnose it with "
                           "model='rigid' (command line: --model rigid), which names flexibility when the record "
                           "shows it")
    # the flexible base keeps its law: on the truthbench's flexible records a law fitted beside the mode wandered
    # (shape and speed changing with each finding) and took the place of the coupling's damping (C12 20 % low)
    return refit(data, State(Model("flexible", coulomb_eps=eps), dict(fl.params), dict(fl.frozen), axis=axis), {}, progress)


#: Effects tried on the base model before its friction law is fitted (:meth:`_Search.before_law`), each with the
#: look-alikes it must rank above: a force so large that the model without it is no base. Its fit bends inertia and
#: friction to stand in for it (a pendulum whose m·g·l is 7 times its Coulomb friction: an inertia 600 times too small,
#: a negative Coulomb friction, a closed loop that diverges once another effect is added), and a friction law fitted on
#: that model is fitted to the wrong force.
BEFORE_LAW = {"gravity": ("offset",)}


class BaseFitError(DidimError):
    """The doctor's base model could not be fitted (it did not converge or is not physical): there is nothing to
    diagnose on top of it. The message says why and what to try."""


#: The model, its decimated training and validation residuals and its training simulation.
Fitted = Tuple[State, np.ndarray, np.ndarray, SimResult]


class _Search:
    """The doctor's rounds: the findings so far, the candidates rejected, the effects tried on the current model."""

    def __init__(self, data: Data, alpha: float, progress, law_fitted: bool = False):
        self.data, self.alpha, self.progress, self.law_fitted = data, alpha, progress, law_fitted
        self.say = progress or (lambda s: None)
        self.findings: List[Finding] = []
        self.rejected: List[Finding] = []
        self.ambiguities: List[Dict[str, Any]] = []
        self.rounds: List[Dict[str, Any]] = []
        self.done: List[str] = []
        self.history: List[Fitted] = []
        self.force_now: Tuple[float, float] = (math.nan, math.nan)  # full-rate training, validation force errors
        self._default_base: Tuple[Optional[State], Optional[Fitted]] = (None, None)  # see default_law_base

    def rank(self, cur: Fitted, only: Optional[Sequence[str]] = None) -> Tuple[List[Candidate], np.ndarray]:
        """Every effect not tried on this model (of ``only``, when given), at its best hyper-parameter, by adjusted
        p-value."""
        state, rt, _, sim = cur
        wb = orthogonalize(self.data.train_base_columns(state, sim), np.zeros((len(rt), 0)))
        a = ar_fit(rt)
        effects = [e for name, e in REGISTRY.items() if name not in self.done and (only is None or name in only)]

        def best(e: Effect) -> Optional[Candidate]:  # the core and numpy's large operations release the interpreter
            return _best_of(e.candidates(state, sim, self.data), rt, wb, self.data, a)

        workers = min(2, cores())
        if workers == 1:
            ranked = _holm_ranked([c for c in map(best, effects) if c is not None])
        else:
            from .._parallel import map_threads

            ranked = _holm_ranked([c for c in map_threads(best, effects, workers) if c is not None])
        self.rounds.append({"round": len(self.rounds) + 1, "candidates": [
            {"effect": c.effect, "hyper": c.hyper, "wald": c.test.statistic, "dof": c.test.dof, "p_value": c.test.p_value,
             "p_adjusted": c.p_adj, "explained_pct": 100 * c.test.explained} for c in ranked]})
        self.say(f"round {len(self.rounds)}: " + ", ".join(
            f"{c.effect} p={c.p_adj:.2g} ({100 * c.test.explained:.1f} %)" for c in ranked[:4]))
        return ranked, wb

    def tries(self, state: State, ranked: List[Candidate], significant: List[Candidate]) -> List[Candidate]:
        """The two best significant candidates, and the look-alike of either (Effect.tried_with) on a rigid model."""
        out = significant[:2]
        for lead in list(out):
            partner = REGISTRY[lead.effect].tried_with
            if state.kind == "rigid" and partner and partner not in self.done \
                    and not any(c.effect == partner for c in out):
                out += [c for c in ranked if c.effect == partner]
        return out

    def attempt(self, c: Candidate, cur: Fitted) -> Tuple[Optional[Finding], Optional[Fitted]]:
        """Adopts candidate ``c`` into the model and judges it on held-out data (Diebold-Mariano on the
        :data:`~didim.doctor.finding.HELDOUT_LOSS` of the errors): the finding and the new fit."""
        state, rt, rv, _ = cur
        effect: Effect = REGISTRY[c.effect]
        self.done.append(c.effect)
        same_optimiser = ""
        try:
            base = effect.baseline(state, self.data, self.progress) if effect.baseline else None
            if base is not None:  # "with" and "without" from the same optimiser and the same start
                rt, rv, _ = self.data.errors(base)
                same_optimiser = "; judged against the model without it refitted by the same optimiser from the same start"
            st_new, _, params, std = effect.adopt(c, state, self.data, self.progress)
            new = (st_new, *self.data.errors(st_new))
            if base is None:
                alt = self.from_default_law(c, state)
                if alt is not None and self.data.rel(alt[0][1], True) < self.data.rel(new[1], True):
                    new, (st_new, params, std) = alt[0], alt[1]
        except DidimError as e:
            self.rejected.append(Finding(c.effect, {}, {}, {"p_adjusted": c.p_adj}, f"not adopted: {e}",
                                         effect.physics, where={"hyper": c.hyper, "round": len(self.rounds)},
                                         accepted=False))
            return None, None
        rt_n, rv_n = new[1], new[2]
        dm, p_dm, gain = diebold_mariano(rv, rv_n, HELDOUT_LOSS)
        stat = {"wald": c.test.statistic, "dof": c.test.dof, "p_value": c.test.p_value, "p_adjusted": c.p_adj,
                "explained_pct": 100 * c.test.explained, "dm_statistic": dm, "dm_p_value": p_dm,
                "valid_mse_reduction_pct": 100 * gain}
        rel = self.data.rel
        fit = {"train_before": rel(rt, True), "train_after": rel(rt_n, True), "valid_before": rel(rv, False),
               "valid_after": rel(rv_n, False)}
        evidence = (f"explains {100 * c.test.explained:.1f} % of the prewhitened training residual (Wald "
                    f"{c.test.statistic:.1f} on {c.test.dof} dof, adjusted p = {c.p_adj:.2g}); held-out error "
                    f"{100 * fit['valid_before']:.2f} % -> {100 * fit['valid_after']:.2f} % (Diebold-Mariano p = {p_dm:.2g})"
                    + same_optimiser)
        if c.p_adj >= self.alpha:  # tried with its look-alike (Effect.tried_with), not on its own training test
            partners = [e.name for e in REGISTRY.values() if e.tried_with == c.effect]
            evidence += (f"; not significant on the training record itself: tried as the look-alike of "
                         f"{' / '.join(partners) or 'another effect'}, judged on the held-out data alone")
        practical = fit["valid_after"] < (1 - MIN_HELDOUT_GAIN) * fit["valid_before"]
        if p_dm < self.alpha and not practical:
            evidence += (f"; below the practical threshold: an effect must lower the held-out force error by at "
                         f"least {100 * MIN_HELDOUT_GAIN:.0f} % of itself")
        f = Finding(c.effect, params, std, stat, evidence, effect.describe(params, st_new), fit,
                    where={"hyper": c.hyper, "round": len(self.rounds)}, accepted=p_dm < self.alpha and practical,
                    words=effect.in_words(params, st_new))
        if not f.accepted:
            if effect.held_out_note is not None:
                try:
                    f.note = effect.held_out_note(c, state, self.data, rt, rv)
                except (DidimError, np.linalg.LinAlgError):
                    f.note = ""
            self.rejected.append(f)
            self.say(f"rejected {c.effect}: {evidence}")
            return f, None
        return f, new

    def before_law(self, cur: Fitted, base: IdentificationResult) -> Fitted:
        """The effects of :data:`BEFORE_LAW` tried on the base model before its friction law is fitted, each when it
        is significant and ranks above its look-alikes (which the later rounds still offer), or, when the ``base``
        fit did not converge to a physical model, whenever it is significant (the ranking of a residual the base
        could not fit says little: on a pendulum whose m·g·l is 7 times its Coulomb friction, an offset explained
        22.9 % of it, gravity 23.0 %): adopted and judged on held-out data as in any round, with the base's law."""
        law, self.law_fitted = self.law_fitted, False  # no law to keep or refit yet
        physical = base.converged and all(v > 0 for k, v in base.params.items() if k in ("M", "M1", "M2")) \
            and all(v >= 0 for k, v in base.params.items() if k in ("Fv", "Fc", "Fv1", "Fc1"))
        try:
            for name, rivals in BEFORE_LAW.items():
                if not REGISTRY[name].candidates(cur[0], cur[3], self.data):  # it does not apply to this axis
                    continue
                ranked, wb = self.rank(cur, only=(name, *rivals))
                significant = [c for c in ranked if c.p_adj < self.alpha]
                if physical:
                    significant = significant[:1]
                chosen = next((c for c in significant if c.effect == name), None)
                if chosen is None:
                    continue
                # judged on the absolute errors (HELDOUT_LOSS): the base's loop, fitted to a force it cannot carry,
                # swings far off at moments (on that pendulum one held-out error 5 times the next largest), and on
                # their squares a model that brings the error from 121 % to 1.0 % would not count as better (p = 0.014)
                f, new = self.attempt(chosen, cur)
                if new is not None:
                    self.note_ambiguities(chosen, significant, wb)
                    cur = self.accept(f, new)
        finally:
            self.law_fitted = law
        return cur

    def with_default_law(self, state: State) -> State:
        """``state`` with didim's default friction law: algebraic, at the record's default smoothing speed."""
        return state.with_(coulomb_law="algebraic", coulomb_eps=default_coulomb_eps(self.data.rec))

    def default_law_base(self, state: State) -> Optional[Fitted]:
        """``state`` refitted with didim's default friction law (:meth:`with_default_law`), when the search fitted
        another law on a rigid model; computed once per state."""
        if not self.law_fitted or state.kind != "rigid":
            return None
        default = self.with_default_law(state)
        if (default.model.coulomb_law, default.model.coulomb_eps) == (state.model.coulomb_law, state.model.coulomb_eps):
            return None
        if self._default_base[0] is not state:
            try:
                st, _ = refit(self.data, default, {}, self.progress)
                self._default_base = (state, (st, *self.data.errors(st)))
            except DidimError:
                self._default_base = (state, None)
        return self._default_base[1]

    def from_default_law(self, c: Candidate, state: State):
        """The effect of candidate ``c`` adopted from didim's default friction law instead of the fitted one:
        ``(fitted, (state, params, std))``, or None. The law was fitted on a model that missed the effect, and a law
        fitted so can stand in for a part of it (on didim's generator, a sharper law at rest took a part of a Stribeck
        hump of 16 N at 5 mm/s, and what remained was best explained at 58 mm/s; a softer law took a part of a
        45 Hz mode's force at the reversals). The effect's best variant is chosen again on the default law's residual
        and adopted from there; the caller keeps whichever adoption fits the training data better, and the held-out
        test still judges it against the model without the effect, with its fitted law. The law is fitted again
        after adoption (:meth:`refit_law`)."""
        base = self.default_law_base(state)
        if base is None:
            return None
        st0, rt0, _, sim0 = base
        effect = REGISTRY[c.effect]
        wb0 = orthogonalize(self.data.train_base_columns(st0, sim0), np.zeros((len(rt0), 0)))
        c0 = _best_of(effect.candidates(st0, sim0, self.data), rt0, wb0, self.data, ar_fit(rt0))
        if c0 is None:
            return None
        try:
            st_new, _, params, std = effect.adopt(c0, st0, self.data, self.progress)
            return (st_new, *self.data.errors(st_new)), (st_new, params, std)
        except DidimError:
            return None

    def refit_law(self, cur: Fitted, f: Finding) -> Fitted:
        """The friction law's smoothing speed fitted again once ``f`` is modelled (the law was fitted on a model that
        missed it: a missing delay or mode bends the fitted law), its shape kept, within √10 of the present speed
        (a law far off, as the hard sign fitted beside a missing 2-sample delay, is left to :meth:`second_start`);
        kept when it lowers the training error by ``RETUNE_GAIN`` (training data only)."""
        try:
            st, _ = fit_friction_law(self.data, cur[0], self.progress, around=cur[0].model.coulomb_eps,
                                     shapes=(cur[0].model.coulomb_law,))
        except DidimError:
            return cur
        if (st.model.coulomb_law, st.model.coulomb_eps) == (cur[0].model.coulomb_law, cur[0].model.coulomb_eps):
            return cur
        again = (st, *self.data.errors(st))
        if self.data.rel(again[1], True) < (1 - RETUNE_GAIN) * self.data.rel(cur[1], True):
            self.force_now = self.data.force_errors(st)
            self.say(f"friction law fitted again once {f.effect} was modelled: {st.model.coulomb_law}, smoothing speed "
                     f"{units.speed(st.model.coulomb_eps, st.axis)}")
            return again
        return cur

    def second_start(self, cur: Fitted) -> Fitted:
        """The law and the findings' hyper-parameters are fitted one after the other, and the path can end in a
        worse optimum than another start (on the EMPS a law fitted before the low-speed deficit was modelled kept a
        part of it). The final model is fitted again from didim's default law (algebraic, the record's default speed),
        its findings' hyper-parameters chosen again and then the law's speed; kept when it lowers the training error by
        ``RETUNE_GAIN`` (training data only)."""
        try:
            st, _ = refit(self.data, self.with_default_law(cur[0]), {}, self.progress)
            chosen = {}
            for old in [x for x in self.findings if REGISTRY[x.effect].retune is not None]:
                got = REGISTRY[old.effect].retune(st, self.data, self.progress)
                if got is not None:
                    st, chosen[id(old)] = got[0], (got[2], got[3])
            st, _ = fit_friction_law(self.data, st, self.progress, shapes=(st.model.coulomb_law,))
            alt = (st, *self.data.errors(st))
        except DidimError:
            return cur
        if self.data.rel(alt[1], True) < (1 - RETUNE_GAIN) * self.data.rel(cur[1], True):
            self.say(f"a second start from the default friction law ends lower: {st.model.coulomb_law}, smoothing speed "
                     f"{units.speed(st.model.coulomb_eps, st.axis)}")
            for old in self.findings:  # the hyper-parameters chosen again; the final values are read from st
                if id(old) in chosen:
                    old.params, old.std = dict(chosen[id(old)][0]), dict(chosen[id(old)][1])
            return alt
        return cur

    def law_instead(self, old: Finding, cur: Fitted) -> Fitted:
        """A low-speed friction finding is physics only when it is separable from the friction law's shape: the model
        without it, with the law through zero speed fitted again (shape and smoothing speed,
        :func:`fit_friction_law`), must predict the held-out data significantly worse. Otherwise the finding is taken
        out and the refitted law kept (the law's shape is part of the base model, not a finding)."""
        try:
            st_alt, _ = fit_friction_law(self.data, REGISTRY[old.effect].remove(cur[0]), self.progress,
                                         around=cur[0].model.coulomb_eps)
            alt = (st_alt, *self.data.errors(st_alt))
        except DidimError:
            return cur
        _, p_keep, _ = diebold_mariano(alt[2], cur[2], HELDOUT_LOSS)
        if p_keep < self.alpha:
            return cur
        old.accepted = False
        old.evidence += (f"; the friction law's shape, not a separate effect: without it, the law through zero speed "
                         f"fitted again ({st_alt.model.coulomb_law}, smoothing speed {units.speed(st_alt.model.coulomb_eps, st_alt.axis)}) predicts the "
                         f"held-out data as well ({100 * self.data.rel(alt[2], False):.2f} %, Diebold-Mariano p = "
                         f"{p_keep:.2g})")
        old.note = (f"the friction law's shape: the law refitted instead ({st_alt.model.coulomb_law}) explains it as well "
                    "on held-out data")
        self.findings.remove(old)
        self.rejected.append(old)
        self.done = [x.effect for x in self.findings]
        self.force_now = self.data.force_errors(st_alt)
        self.say(f"{old.effect} is the friction law's shape: the law refitted instead")
        return alt

    def note_ambiguities(self, c: Candidate, significant: List[Candidate], wb: np.ndarray) -> None:
        """Records the significant candidates whose regressor is (over :data:`AMBIGUOUS_SHARE`) that of the accepted ``c``."""
        xc = orthogonalize(c.columns, wb)
        for other in significant:
            if other is c:
                continue
            xo = orthogonalize(other.columns, wb)
            res_o = orthogonalize(xo, xc)
            share = 1 - float(np.sum(res_o**2) / max(np.sum(xo**2), 1e-300))
            if share > AMBIGUOUS_SHARE:
                # "equal": the other explains (nearly) as much of the residual, so the record cannot say which it is
                self.ambiguities.append({"effects": [c.effect, other.effect], "shared_pct": 100 * share,
                                         "equal": bool(other.test.explained >= 0.9 * c.test.explained),
                                         "experiment": separating_experiment(c.effect, other.effect)})

    def accept(self, f: Finding, new: Fitted) -> Fitted:
        """Adds the finding; the candidates rejected on the old model get another chance on the new one; an earlier
        finding the new one makes redundant (no longer improving the held-out fit) is taken out again."""
        f.fit["train_force_before"], f.fit["valid_force_before"] = self.force_now
        f.fit["train_force_after"], f.fit["valid_force_after"] = self.force_now = self.data.force_errors(new[0])
        self.findings.append(f)
        self.done = [x.effect for x in self.findings]
        self.history.append(new)
        self.say(f"accepted {f.effect}: {f.evidence}")
        cur = new
        for old in [x for x in self.findings[:-1] if x.effect != "unnamed"]:
            remove = REGISTRY[old.effect].remove
            if remove is None:
                continue
            try:
                st_drop, _ = refit(self.data, remove(cur[0]), {}, self.progress)
                dropped = (st_drop, *self.data.errors(st_drop))
            except DidimError:
                continue
            _, p_keep, _ = diebold_mariano(dropped[2], cur[2], HELDOUT_LOSS)
            # kept only while it still matters in practice (as when it was accepted): a later finding can leave an
            # earlier one significant but negligible (a ripple whose amplitude fell to a few hundredths of a newton)
            negligible = self.data.rel(cur[2], False) >= (1 - MIN_HELDOUT_GAIN) * self.data.rel(dropped[2], False)
            if p_keep >= self.alpha or negligible:
                old.accepted = False
                old.evidence += (f"; taken out again once {f.effect} was modelled (held-out error without it "
                                 f"{100 * self.data.rel(dropped[2], False):.2f} % against "
                                 f"{100 * self.data.rel(cur[2], False):.2f} % with it, Diebold-Mariano p = {p_keep:.2g})")
                self.findings.remove(old)
                self.rejected.append(old)
                cur = dropped
                self.force_now = self.data.force_errors(cur[0])
                self.say(f"removed {old.effect}: no longer improves the held-out fit")
        if self.law_fitted:
            if cur[0].kind == "rigid":  # a flexible model keeps its law (see _base_fit) unless a Stribeck term asks
                cur = self.refit_law(cur, f)
            for old in [x for x in self.findings if x.effect == "stribeck"]:
                cur = self.law_instead(old, cur)
        for old in [x for x in self.findings[:-1] if REGISTRY[x.effect].retune is not None]:
            effect = REGISTRY[old.effect]
            try:
                got = effect.retune(cur[0], self.data, self.progress)
            except DidimError:
                continue
            if got is None:
                continue
            st, _, params, std = got
            again = (st, *self.data.errors(st))
            if self.data.rel(again[1], True) < (1 - RETUNE_GAIN) * self.data.rel(cur[1], True):  # training only
                old.evidence += (f"; chosen again once {f.effect} was modelled: " + ", ".join(
                    f"{k} {old.params.get(k, math.nan):.4g} -> {v:.4g}" for k, v in params.items()))
                old.params, old.std = params, std
                old.physics, old.words = effect.describe(params, st), effect.in_words(params, st)
                cur = again
                self.force_now = self.data.force_errors(st)
                self.say(f"{old.effect} chosen again: {old.words}")
        return cur


@serial_blas
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
    coulomb_eps: Union[str, float, None] = "fit",
    controller_check: str = "error",
    initial=None,
    frozen: Optional[Dict[str, float]] = None,
) -> Diagnosis:
    """Diagnoses what the ``model`` ("rigid" or "flexible") misses on ``recording``; with a robot's record and its
    :class:`didim.Robot` as ``model``, where each joint's simulation and record differ (:mod:`didim.doctor.robot`).
    ``validate`` is a recording the
    fit does not see (otherwise the last ``holdout`` share of the record is held out). ``alpha`` is the family-wise
    level of the candidate tests and of the held-out confirmation. ``cutoff_hz`` is the decimation cutoff of the fits
    and of the residual analysis. ``coulomb_eps``: the Coulomb smoothing speed of the base model (m/s or rad/s),
    ``"fit"`` (default) to fit it with the base model before any effect is looked for
    (:func:`didim.doctor.fit.fit_friction_law`), None for didim's default. ``controller_check``: as for
    :func:`didim.identify`, on both records. ``initial``: a robot's result (of the same robot) its base fit starts
    from instead of the URDF's values (published values, say: a robot whose URDF is far from it). ``frozen``: a
    robot's parameters held at given values in the base fit and every refit (:func:`didim.identify`'s; trusted body
    parameters, say)."""
    from ..api import _has_joint_columns, _robot_plant
    from ..robots import Robot

    if _robot_plant(model, recording):
        # a bare robot: its rigid model with an offset per joint; a robot's model whole (its elastic joints, backlash,
        # terms, offset: the base the doctor grows)
        robot = model.robot if isinstance(model, Model) else model
        if not isinstance(robot, Robot) or not _has_joint_columns(recording):
            raise DataError("a robot's record is diagnosed with its didim.Robot: didim.doctor(rec, robot, "
                            "validate=...) with rec = didim.load_record(path, robot=robot)")
        if apM is not None:
            raise DataError("apM does not apply to a robot: DIDIM on a robot starts from the URDF's values")
        from .robot import doctor_robot

        return doctor_robot(recording, model, validate, progress=progress,  # type: ignore[return-value]
                            controller_check=controller_check, alpha=alpha, max_findings=max_findings,
                            initial=initial, frozen=frozen)
    if initial is not None:
        raise DataError("initial is a robot's result its doctor starts from; one axis's doctor starts from apM")
    if frozen:
        raise DataError("frozen holds a robot's parameters in its doctor's fits; one axis's doctor fits every "
                        "parameter (didim.identify(..., frozen=...) holds them in one fit)")
    apM, alpha, max_findings = _check_arguments(recording, model, validate, apM, alpha, max_findings, cutoff_hz,
                                                holdout, progress)
    from ..check import enforce

    checks = {(r.name or f"record {i}"): enforce(r, controller_check)
              for i, r in enumerate((recording, validate)) if r is not None}
    t0 = time.perf_counter()
    dec = Decimation.lowpass(cutoff_hz, recording.fs)
    n_fit = recording.n if validate is not None else int(recording.n * (1 - holdout))
    _checks.record_long_enough(dec, n_fit, recording.dt, MIN_ROWS, 1, "the doctor",
                               of="(the minimum of its fits and tests; the validation share is held out)")
    data = Data(recording, validate, dec, holdout)
    search = _Search(data, alpha, progress, law_fitted=coulomb_eps == "fit" and model == "rigid")
    search.say(f"base fit: DIDIM {model}")
    state, base = _base_fit(data, model, apM, progress, coulomb_eps)
    data.settle(state)
    cur: Fitted = (state, *data.errors(state))
    search.history.append(cur)
    search.force_now = data.force_errors(state)
    cur = search.before_law(cur, base)
    if search.law_fitted:
        st, _ = fit_friction_law(data, cur[0], progress)
        if not search.findings:  # the base model is the one with its law
            data.settle(st)
        cur = (st, *data.errors(st))
        search.force_now = data.force_errors(st)
        if not search.findings:
            search.history[0] = cur
    before = search.history[0]
    fit0 = {"train_before": data.rel(before[1], True), "valid_before": data.rel(before[2], False)}
    fit0["train_force_before"], fit0["valid_force_before"] = data.force_errors(before[0])
    locate_before = _locate(data, before[1], before[3])

    t_rounds = time.perf_counter()
    for k in range(max_findings):
        if k:  # how long the rest may take, at the pace of the rounds so far (each round may end the search)
            pace = (time.perf_counter() - t_rounds) / k
            search.say(f"{time.perf_counter() - t0:.0f} s so far; at most {max_findings - k} more round(s), up to "
                       f"about {pace * (max_findings - k):.0f} s at this pace")
        ranked, wb = search.rank(cur)
        significant = [c for c in ranked if c.p_adj < alpha]
        if not significant:
            break
        accepted = False
        for c in search.tries(cur[0], ranked, significant):
            f, new = search.attempt(c, cur)
            if new is not None:
                search.note_ambiguities(c, significant, wb)
                cur, accepted = search.accept(f, new), True
                break
        if not accepted and len(search.done) >= len(REGISTRY):
            break

    if search.law_fitted and cur[0].kind == "rigid":
        cur = search.second_start(cur)
    state, rt, rv, sim = cur
    for f in search.findings:  # in words with the final model's values (later refits move them)
        f.words = REGISTRY[f.effect].in_words(final_values(f.effect, f.params, state), state)
    un = _unnamed(data, rt, sim, data.train_base_columns(state, sim), alpha)
    if un is not None:
        search.findings.append(un)
    diag = Diagnosis(
        recording=recording.name or "recording", model=model, findings=search.findings, rejected=search.rejected,
        fit={**fit0, "train_after": data.rel(rt, True), "valid_after": data.rel(rv, False),
             **dict(zip(("train_force_after", "valid_force_after"), data.force_errors(state)))}, base=base,
        final_params=state.all_params(), final_state=state, ambiguities=search.ambiguities, rounds=search.rounds,
        locate={"before": locate_before, "after": _locate(data, rt, sim),
                "start": [x for x in (_start(r, state) for r in (recording, validate) if r is not None) if x],
                "lead_in": [x for x in (_lead_in(r) for r in (recording, validate) if r is not None) if x]},
        options=dict(alpha=alpha, max_findings=max_findings, cutoff_hz=cutoff_hz, holdout=None if validate else holdout,
                     controller_check={k: (None if c is None else c.to_dict()) for k, c in checks.items()},
                     controller_origin=recording.controller_origin,
                     friction_law="fitted" if search.law_fitted else ("default" if coulomb_eps in ("fit", None)
                                                                       else "given"),
                     _valid_record=(validate.name or "validation recording") if validate is not None else None,
                     validation=(validate.name or "validation recording") if validate else
                     f"last {int(100 * holdout)} % of the record"),
        elapsed_s=time.perf_counter() - t0,
    )
    diag._context = {"data": data, "history": search.history}
    return diag


__all__ = ["doctor", "Diagnosis", "Finding", "EFFECTS", "PHYSICS", "REGISTRY", "Effect", "start_words", "lead_in_words",
           "BaseFitError"]
