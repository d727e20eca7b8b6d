"""Tests the paper's robustness claims with didim's sweeps and writes docs/robustness.md and its figures.

Claims (section VI of the paper): the rigid step converges from an a priori mass apM anywhere in 25..1000 kg; step 2
(Nelder-Mead on λ and f_n_flex) converges from λ⁰ in 0.25..0.95 and f⁰ in 15..50 Hz. Each is swept inside and outside
those ranges on simulated EMPS-like records with a known truth (``didim.sweep.SCENARIOS``), several noise seeds each,
and the rigid claim also on the real EMPS record.

    python benches/robustness.py [--workers N] [--seeds N] [--quick]

The same sweeps from the command line, e.g.:

    didim sweep --scenario flexible-motor-friction --model rigid --grid apM=5,10,25,100,1000,10000 --seeds 5
    didim sweep --scenario flexible-motor-friction --model flexible --grid lambda0=0.05,0.25,0.95 \\
        --grid f0=5,15,50,150 --seeds 2 --step mode --plot step2.png
"""

from __future__ import annotations

import argparse
import os
import pathlib
import platform
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))

import numpy as np  # noqa: E402

from didim.formats._io import save_figure, write_text  # noqa: E402
from didim.sweep import SCENARIOS, grid_points, step_truth, sweep  # noqa: E402

EMPS = pathlib.Path(os.environ.get("DIDIM_EMPS_DIR", ROOT.parent / "shared" / "data" / "emps")) / "DATA_EMPS.mat"

APM = [5.0, 10.0, 25.0, 50.0, 100.0, 250.0, 500.0, 1000.0, 2000.0, 5000.0, 20000.0]
LAMBDA0 = [0.05, 0.15, 0.25, 0.4, 0.55, 0.7, 0.85, 0.95, 0.99]
F0 = [5.0, 10.0, 15.0, 20.0, 30.0, 40.0, 50.0, 75.0, 100.0, 150.0]


def fmt(x, digits=4):
    return "-" if x is None or not np.isfinite(x) else f"{x:.{digits}g}"


def spread_table(res, step=None) -> str:
    lines = ["| parameter | truth | consensus | spread (std over runs) | mean predicted σ | spread/σ | rms (χ̂ − χ)/σ |",
             "|---|---|---|---|---|---|---|"]
    for s in res.spread(step):
        lines.append(f"| {s['name']} | {fmt(s['truth'])} | {fmt(s['consensus'], 5)} | {fmt(s['spread'], 3)} | "
                     f"{fmt(s['sigma'], 3)} | {fmt(s['ratio'], 2)} | {fmt(s['z_rms'], 2)} |")
    return "\n".join(lines)


def rate_table_1d(res, key, step=None, inside=None) -> str:
    rows = res.rates_by(key, step)
    lines = [f"| {key} | " + " | ".join(f"{v:g}" + ("" if inside is None or inside(v) else " ✱") for v, *_ in rows) + " |",
             "|---|" + "---|" * len(rows),
             "| converged | " + " | ".join(f"{c}/{m}" for _, m, c, _ in rows) + " |",
             "| reached the consensus | " + " | ".join(f"{a}/{m}" for _, m, _, a in rows) + " |"]
    return "\n".join(lines)


def rate_table_2d(res, kx, ky, step=None, inside=None) -> str:
    agree = res.agrees(step)
    conv = res.converged(step)
    xs = sorted({p[kx] for p in res.points})
    ys = sorted({p[ky] for p in res.points})
    cell = {}
    for p, c, a in zip(res.points, conv, agree):
        k = (p[kx], p[ky])
        m, cc, aa = cell.get(k, (0, 0, 0))
        cell[k] = (m + 1, cc + c, aa + a)
    head = f"| {ky} \\ {kx} | " + " | ".join(f"{x:g}" for x in xs) + " |"
    lines = [head, "|---|" + "---|" * len(xs)]
    for y in ys:
        row = []
        for x in xs:
            m, c, a = cell.get((x, y), (0, 0, 0))
            mark = "" if inside is None or inside(x, y) else " ✱"
            row.append(f"{a}/{m}{mark}")
        lines.append(f"| {y:g} | " + " | ".join(row) + " |")
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=os.cpu_count())
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--quick", action="store_true", help="a few points only (smoke test)")
    ap.add_argument("--out", default=str(ROOT / "docs"))
    args = ap.parse_args()
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    apm, lam, f0 = (APM[::4], LAMBDA0[::4], F0[::4]) if args.quick else (APM, LAMBDA0, F0)
    seeds = list(range(1 if args.quick else args.seeds))
    t_all = time.perf_counter()
    doc = []

    # --- step 1: rigid DIDIM from apM, simulated flexible EMPS-like records --------------------------------------
    pts = grid_points(dict(apM=apm, seed=seeds), dict(scenario="flexible-motor-friction", model="rigid", method="didim"))
    s1 = sweep(pts, workers=args.workers, label="step 1 (simulated)")
    s1.meta["title"] = "rigid DIDIM (step 1) from apM, simulated flexible EMPS"
    save_figure(s1.plot(), out / "robustness_step1.png", dpi=100)
    print("\n" + s1.summary())

    # --- step 1 on the real EMPS record --------------------------------------------------------------------------
    s1r = None
    if EMPS.exists():
        pts = grid_points(dict(apM=apm), dict(record=str(EMPS), model="rigid", method="didim", offset=True))
        s1r = sweep(pts, workers=args.workers, label="step 1 (EMPS)")
        print("\n" + s1r.summary())

    # --- step 2: Nelder-Mead on (λ, f_n_flex) from (λ⁰, f⁰), then step 3 -----------------------------------------
    pts = grid_points(dict(lambda0=lam, f0=f0, seed=seeds[: max(1, len(seeds) // 2)]),
                      dict(scenario="flexible-motor-friction", model="flexible", method="didim", apM=78.0))
    s2 = sweep(pts, workers=args.workers, label="step 2")
    s2.meta["title"] = "three-step DIDIM from (λ⁰, f⁰), simulated flexible EMPS"
    save_figure(s2.plot("mode"), out / "robustness_step2.png", dpi=100)
    print("\n" + s2.summary("mode"))
    print("\n" + s2.summary())

    # --- the same starts with step 2's grid start (not in the paper) ---------------------------------------------
    pts = grid_points(dict(lambda0=lam, f0=f0, seed=seeds[:1]),
                      dict(scenario="flexible-motor-friction", model="flexible", method="didim", apM=78.0,
                           grid_start=True))
    s2g = sweep(pts, workers=args.workers, label="step 2, grid start")
    print("\n" + s2g.summary("mode"))

    truth = SCENARIOS["flexible-motor-friction"]["truth"]
    t2 = step_truth(truth, "mode")
    t1 = step_truth(truth, "rigid")
    in_apm = lambda v: 25 <= v <= 1000  # noqa: E731
    in_mode = lambda x, y: 0.25 <= x <= 0.95 and 15 <= y <= 50  # noqa: E731

    def inside_rate(res, pred, step=None):
        sel = [i for i, p in enumerate(res.points) if pred(p)]
        a = res.agrees(step)
        return sum(a[i] for i in sel), len(sel)

    a_in, n_in = inside_rate(s1, lambda p: in_apm(p["apM"]))
    a_out, n_out = inside_rate(s1, lambda p: not in_apm(p["apM"]))
    b_in, m_in = inside_rate(s2, lambda p: in_mode(p["lambda0"], p["f0"]), "mode")
    b_out, m_out = inside_rate(s2, lambda p: not in_mode(p["lambda0"], p["f0"]), "mode")
    c_in, k_in = inside_rate(s2, lambda p: in_mode(p["lambda0"], p["f0"]))
    c_out, k_out = inside_rate(s2, lambda p: not in_mode(p["lambda0"], p["f0"]))
    g_in, h_in = inside_rate(s2g, lambda p: in_mode(p["lambda0"], p["f0"]), "mode")
    g_out, h_out = inside_rate(s2g, lambda p: not in_mode(p["lambda0"], p["f0"]), "mode")

    doc.append("# Robustness of DIDIM to its initial values: the paper's claims tested\n")
    doc.append(f"Generated by `python benches/robustness.py --seeds {args.seeds}` on {platform.machine()} "
               f"({os.cpu_count()} cores, {args.workers} workers), {time.strftime('%Y-%m-%d')}, in "
               f"{time.perf_counter() - t_all:.0f} s. Records: `didim.sweep.SCENARIOS['flexible-motor-friction']` — "
               "the two-mass EMPS of Table 3 with all friction on the motor side (M1 = 68 kg, Fv1 = 200.5 N/(m/s), "
               "Fc1 = 19.5 N, M2 = 38 kg, K12 = 8.8e5 N/m; the case the three-step procedure is built for), "
               "trapezoidal moves and a 2–40 Hz chirp under the EMPS controller, 1 N coloured force noise, 0.05 µm "
               "encoders, one record per noise seed. A run *reaches the consensus* when it converges (the method's "
               "own criterion) and every estimate lies within 1 % of the median of the converged runs; ✱ marks "
               "values outside the paper's ranges.\n")
    doc.append("## Summary\n")
    doc.append("| claim | inside the paper's range | outside it |\n|---|---|---|")
    doc.append(f"| rigid step converges from apM in 25..1000 kg | {a_in}/{n_in} runs | {a_out}/{n_out} runs "
               f"(apM = {', '.join(f'{v:g}' for v in apm if not in_apm(v))} kg) |")
    if s1r is not None:
        r_in, rn_in = inside_rate(s1r, lambda p: in_apm(p["apM"]))
        r_out, rn_out = inside_rate(s1r, lambda p: not in_apm(p["apM"]))
        doc.append(f"| the same on the real EMPS record (DATA_EMPS, with OF) | {r_in}/{rn_in} runs | {r_out}/{rn_out} runs |")
    doc.append(f"| step 2 converges from λ⁰ in 0.25..0.95, f⁰ in 15..50 Hz | {b_in}/{m_in} runs | {b_out}/{m_out} runs |")
    doc.append(f"| the three-step result (step 3) from those step-2 starts | {c_in}/{k_in} runs | {c_out}/{k_out} runs |")
    doc.append(f"| step 2 with didim's grid start (`grid_start=True`, not in the paper) | {g_in}/{h_in} runs | "
               f"{g_out}/{h_out} runs |\n")

    doc.append("## Step 1: rigid DIDIM from the a priori mass apM\n")
    doc.append(f"Simulated records, {len(seeds)} noise seed(s) per apM; the truth of this step is the rigid totals "
               f"M = {t1['M']:g} kg, Fv = {t1['Fv']:g} N/(m/s), Fc = {t1['Fc']:g} N (decimation at 5 Hz).\n")
    doc.append(rate_table_1d(s1, "apM", inside=in_apm) + "\n")
    doc.append(spread_table(s1) + "\n")
    doc.append("![step 1](robustness_step1.png)\n")
    if s1r is not None:
        doc.append("On the real EMPS record (DATA_EMPS, with the offset OF):\n")
        doc.append(rate_table_1d(s1r, "apM", inside=in_apm) + "\n")
        cons = s1r.consensus()
        doc.append("Consensus: " + ", ".join(f"{k} = {fmt(v, 5)}" for k, v in cons.items()) + ".\n")
        fails = [(p["apM"], r.get("message") or r.get("error") or "") for p, r in zip(s1r.points, s1r.results)
                 if not r.get("converged")]
        if fails:
            doc.append("Failures on the real record (the same with `integrator=\"rk4\"`):\n")
            for apm_v, msg in fails:
                doc.append(f"- apM = {apm_v:g} kg: {msg.split('; stopped')[0]}")
            doc.append("")
    doc.append("## Step 2: Nelder–Mead on (λ, f_n_flex) from (λ⁰, f⁰), then step 3\n")
    doc.append(f"Step 2's targets here: λ = M1/(M1 + M2) = {t2['lambda']:.4f}, f_n_flex = √(K12/M2)/2π = "
               f"{t2['f_n_flex']:.3f} Hz; step 1 from apM = 78 kg. Runs reaching step 2's consensus, per (λ⁰, f⁰) "
               f"({max(1, len(seeds) // 2)} seed(s) each):\n")
    doc.append(rate_table_2d(s2, "lambda0", "f0", "mode", inside=in_mode) + "\n")
    doc.append(spread_table(s2, "mode") + "\n")
    doc.append("The three-step result (step 3, flexible DIDIM) over the same runs:\n")
    doc.append(rate_table_2d(s2, "lambda0", "f0", inside=in_mode) + "\n")
    doc.append(spread_table(s2) + "\n")
    doc.append("![step 2](robustness_step2.png)\n")
    doc.append("## Step 2 with a grid start\n")
    doc.append("`fit_flexible_mode(..., grid_start=True)` (or `identify(..., grid_start=True)`) first evaluates step 2's "
               "criterion on 9 × 10 points (λ in 0.1..0.9, f_n_flex in 3..120 Hz, geometric) and (λ⁰, f⁰), in one "
               "parallel batch, and starts the Nelder–Mead from the best. Runs reaching step 2's consensus (one seed):\n")
    doc.append(rate_table_2d(s2g, "lambda0", "f0", "mode", inside=in_mode) + "\n")
    doc.append(f"Cost: {np.mean([r['steps']['mode']['simulations'] for r in s2g.results if r.get('steps')]):.0f} "
               f"simulations per step 2 on average, against "
               f"{np.mean([r['steps']['mode']['simulations'] for r in s2.results if r.get('steps')]):.0f} without.\n")
    write_text(out / "robustness.md", "\n".join(doc))
    print(f"\nwrote {out / 'robustness.md'} in {time.perf_counter() - t_all:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
