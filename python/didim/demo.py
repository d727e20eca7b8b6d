"""``didim demo``: a simulated flexible EMPS-like axis with the paper's Table 3 values as truth, excited as the paper
did (trapezoidal moves, then a chirp superimposed on a slow constant-speed move), identified by IDIM-LS, the
three-step DIDIM and the exact-sensitivity output-error solver (OE-LM), printed side by side with the truth. A second
table shows the same axis with the chirp played at rest, where the paper's variant of the three-step procedure cannot
hold the mode and didim's friction split (beyond the paper) does."""

from __future__ import annotations

import time
from typing import Callable, Dict, Optional

from . import scenarios
from .api import identify
from .result import IdentificationResult, compare
from .simulation import DEFAULT_COULOMB_EPS


def _record(truth, qr, *, seed: int, force_noise: float, name: str):
    return scenarios.make_recording(truth, "flexible", qr, load_encoder=True, force_noise=force_noise, seed=seed,
                                    name=name)


def run_demo(*, seed: int = 0, force_noise: float = 1.0, progress: Optional[Callable[[str], None]] = None,
             truth: Optional[Dict[str, float]] = None) -> Dict[str, IdentificationResult]:
    """Builds the record (chirp during motion) and runs the three methods; returns the results by method name."""
    truth = dict(truth or scenarios.TABLE3_TRUTH)
    say = progress or (lambda s: None)
    t0 = time.perf_counter()
    rec = _record(truth, scenarios.trapezoid_moving_chirp(), seed=seed, force_noise=force_noise,
                  name="demo (Table 3 truth, chirp during motion)")
    say(f"simulated record: {rec} ({time.perf_counter() - t0:.2f} s)")
    results = {}
    say("IDIM-LS (motor force, motor and load positions; command aligned to the held force, smooth Coulomb sign)")
    results["IDIM-LS"] = identify(rec, "flexible", "idim-ls", zoh_align=True, coulomb_eps=DEFAULT_COULOMB_EPS)
    say("three-step DIDIM (motor force only)")
    results["DIDIM"] = identify(rec, "flexible", "didim")
    say("exact-sensitivity output error, Levenberg-Marquardt (motor force only)")
    results["OE-LM"] = identify(rec, "flexible", "oe-lm")
    return results


def run_rest_case(*, seed: int = 0, force_noise: float = 1.0, progress: Optional[Callable[[str], None]] = None
                  ) -> Dict[str, IdentificationResult]:
    """The same axis with the chirp played at rest: the paper's variant and didim's default (friction split)."""
    say = progress or (lambda s: None)
    rec = _record(scenarios.TABLE3_TRUTH, scenarios.trapezoid_chirp(), seed=seed, force_noise=force_noise,
                  name="demo (Table 3 truth, chirp at rest)")
    say("chirp at rest: three-step DIDIM, the paper's variant and didim's default")
    return {"DIDIM (paper)": identify(rec, "flexible", "didim", variant="paper"),
            "DIDIM (auto)": identify(rec, "flexible", "didim")}


def _status(results: Dict[str, IdentificationResult]) -> list:
    out = []
    for name, r in results.items():
        variant = r.options.get("variant")
        state = "converged" if r.converged else "NOT converged: " + r.message
        out.append(f"{name}: {state}" + (f" [variant: {variant}]" if variant else ""))
        out.extend(f"  note: {n}" for n in r.notes)
    return out


def demo_report(results: Dict[str, IdentificationResult], rest: Optional[Dict[str, IdentificationResult]] = None,
                truth: Optional[Dict[str, float]] = None) -> str:
    truth = dict(truth or scenarios.TABLE3_TRUTH)
    out = ["didim demo: flexible EMPS-like axis, truth = the paper's Table 3 IDIM-LS values (SI units, load side:",
           "M in kg, Fv in N/(m/s), Fc in N, K12 in N/m); trapezoidal moves + a 2-40 Hz chirp on a slow constant-speed",
           "move (the paper's excitation), EMPS controller, 1 N coloured force noise, 0.05 um encoders", ""]
    out.append(compare(results, truth=truth))
    out.extend(["(rel. error: ‖Y − Wχ‖/‖Y‖ of the final regression, or ‖Y − Ys‖/‖Y‖ for OE-LM)", ""])
    out.extend(_status(results))
    d = results.get("DIDIM")
    if d is not None and "rigid" in d.steps:
        r1, r2 = d.steps["rigid"], d.steps["mode"]
        out.append(f"DIDIM step 1 (rigid): M = {r1.params['M']:.2f} kg, Fv = {r1.params['Fv']:.1f} N/(m/s), "
                   f"Fc = {r1.params['Fc']:.2f} N in {r1.iterations} iterations; step 2: λ = {r2.params['lambda']:.3f}, "
                   f"f_n_flex = {r2.params['f_n_flex']:.2f} Hz in {r2.iterations} iterations")
    if rest:
        out += ["", "The same axis with the chirp played at rest (the load's Coulomb friction reverses twice per period):",
                ""]
        out.append(compare(rest, truth=truth))
        out.append("")
        out.extend(_status(rest))
    return "\n".join(out)


__all__ = ["run_demo", "run_rest_case", "demo_report"]
