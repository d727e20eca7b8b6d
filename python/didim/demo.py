"""``didim demo``: a simulated flexible EMPS record with the paper's Table 3 values as truth, identified by IDIM-LS,
the three-step DIDIM and the exact-sensitivity output-error solver, printed side by side with the truth."""

from __future__ import annotations

import time
from typing import Callable, Dict, Optional

from . import scenarios
from .api import identify
from .result import IdentificationResult, compare
from .simulation import DEFAULT_COULOMB_EPS


def run_demo(*, seed: int = 0, force_noise: float = 1.0, progress: Optional[Callable[[str], None]] = None,
             truth: Optional[Dict[str, float]] = None) -> Dict[str, IdentificationResult]:
    """Builds the record and runs the three methods; returns the results by method name."""
    truth = dict(truth or scenarios.TABLE3_TRUTH)
    say = progress or (lambda s: None)
    t0 = time.perf_counter()
    rec = scenarios.make_recording(truth, "flexible", load_encoder=True, force_noise=force_noise, seed=seed,
                                   name="demo (Table 3 truth)")
    say(f"simulated record: {rec} ({time.perf_counter() - t0:.2f} s)")
    results = {}
    say("IDIM-LS (motor force, motor and load positions; command aligned to the held force, smooth Coulomb sign)")
    results["IDIM-LS"] = identify(rec, "flexible", "idim-ls", zoh_align=True, coulomb_eps=DEFAULT_COULOMB_EPS)
    say("three-step DIDIM (motor force only)")
    results["DIDIM"] = identify(rec, "flexible", "didim", apM=78.0)
    say("exact-sensitivity output error (motor force only)")
    results["OE-GN"] = identify(rec, "flexible", "oe-gn", apM=78.0)
    return results


#: The same axis with all friction on the motor side: the case the three-step DIDIM is built for.
MOTOR_FRICTION_TRUTH = dict(scenarios.TABLE3_TRUTH, Fv1=200.5, Fc1=19.5, Fv2=0.0, Fc2=0.0)


def run_didim_case(*, seed: int = 0, force_noise: float = 1.0) -> IdentificationResult:
    rec = scenarios.make_recording(MOTOR_FRICTION_TRUTH, "flexible", force_noise=force_noise, seed=seed,
                                   name="demo (friction on the motor side)")
    return identify(rec, "flexible", "didim", apM=78.0)


def demo_report(results: Dict[str, IdentificationResult], truth: Optional[Dict[str, float]] = None) -> str:
    truth = dict(truth or scenarios.TABLE3_TRUTH)
    out = ["didim demo: flexible EMPS-like axis, truth = the paper's Table 3 IDIM-LS values,",
           "trapezoidal moves + chirp, EMPS controller, 1 N coloured force noise, 0.05 um encoders", ""]
    out.append(compare(results, truth=truth))
    out.append("")
    for name, r in results.items():
        if not r.converged:
            out.append(f"{name}: {'converged' if r.converged else 'NOT converged'}{': ' + r.message if r.message else ''}")
    d = results.get("DIDIM")
    if d is not None and "rigid" in d.steps:
        r1, r2 = d.steps["rigid"], d.steps["mode"]
        out.append(f"DIDIM step 1 (rigid): M = {r1.params['M']:.2f} kg, Fv = {r1.params['Fv']:.1f}, Fc = {r1.params['Fc']:.2f} "
                   f"in {r1.iterations} iterations; step 2: λ = {r2.params['lambda']:.3f}, f_n_flex = {r2.params['f_n_flex']:.2f} Hz "
                   f"in {r2.iterations} iterations / {r2.simulations} simulations")
    return "\n".join(out)


def didim_case_report(r: IdentificationResult) -> str:
    t = MOTOR_FRICTION_TRUTH
    lines = ["", "Same axis with all friction on the motor side (Fv2 = Fc2 = 0), three-step DIDIM from the motor force only:",
             f"{'parameter':<10}{'truth':>12}{'DIDIM':>12}{'error %':>9}"]
    for n in ("M1", "Fv1", "Fc1", "M2", "K12"):
        lines.append(f"{n:<10}{t[n]:>12.4g}{r.params[n]:>12.4g}{100 * (r.params[n] / t[n] - 1):>9.2f}")
    lines.append(f"{'converged' if r.converged else 'NOT converged: ' + r.message}; {r.iterations} iterations in step 3, "
                 f"{r.simulations} simulations in all, {r.elapsed_s:.2f} s; output error {100 * r.output_error:.2f} %")
    return "\n".join(lines)


__all__ = ["run_demo", "demo_report"]
