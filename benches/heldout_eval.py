"""didim on robots it was not built around: the records of benches/heldout_robots.py (an independent simulator over
Pinocchio: a prismatic joint, 500 Hz to 4 kHz, algebraic, tanh, atan and exp friction laws with a smoothing speed per
joint, PID and cascade controllers) and of ../shared/data/robots. For each robot: DIDIM and IDIM-LS on the training
record, each joint's Fv and Fc against the truth, the validation record simulated with the estimate against its truth
floor, the payload's mass, the CPU time. Writes docs/heldout_robots.md.

    python benches/heldout_robots.py --out /tmp/didim_heldout      # the records (about 8 min on 2 cores)
    python benches/heldout_eval.py --heldout /tmp/didim_heldout [--only rpr,panda_alg] [--out docs/heldout_robots.md]
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform
import time
import warnings

import numpy as np

import didim
from didim.robots import payload
from didim.methods.robot import force_errors, simulate_robot

ROOT = pathlib.Path(__file__).resolve().parents[1]
SHARED = pathlib.Path(os.environ.get("DIDIM_ROBOTS_DIR", ROOT.parent / "shared" / "data" / "robots"))


def _law_name(truth: dict) -> str:
    """The truth's friction law's shape (the shared folder writes it as a formula)."""
    if truth.get("friction_shape"):
        return str(truth["friction_shape"])
    text = str(truth.get("friction_law", ""))
    return next((name for name in ("algebraic", "tanh", "atan", "exp") if name in text), text)


def evaluate(folder: pathlib.Path, name: str, truth: dict) -> list:
    """One robot's rows: per method, the worst Fv and Fc errors (and where), validation/floor, payload, time."""
    robot = didim.Robot.from_urdf(folder / f"{name}_cad.urdf")
    ctl = folder / f"{name}_controller.json"
    rec = didim.load_record(folder / f"{name}_train.csv", robot=robot, controller=ctl)
    val = didim.load_record(folder / f"{name}_valid.csv", robot=robot, controller=ctl)
    floor = truth["records"]["valid"]["truth_floor_total"]
    rows = []
    for method in ("didim", "idim-ls"):
        t0 = time.process_time()
        r = didim.identify(rec, robot, method)
        cpu = time.process_time() - t0
        fv = [r.params[f"Fv_{j}"] / truth["Fv"][i] - 1 for i, j in enumerate(robot.joint_names)]
        fc = [r.params[f"Fc_{j}"] / truth["Fc"][i] - 1 for i, j in enumerate(robot.joint_names)]
        e, _ = force_errors(val, simulate_robot(val, r)["force"])
        row = dict(robot=name, method=method, joints=robot.ndof, kinds=sorted(set(robot.joint_kinds)),
                   rate_hz=round(1 / rec.dt), law=_law_name(truth),
                   law_found=r.law[0] if r.law else "", fv=fv, fc=fc, worst_fv=float(np.max(np.abs(fv))),
                   worst_fc=float(np.max(np.abs(fc))), valid_ratio=e / floor, cpu_s=cpu, converged=r.converged)
        if method == "didim" and (folder / f"{name}_payload.csv").exists():
            prec = didim.load_record(folder / f"{name}_payload.csv", robot=robot, controller=ctl)
            p = payload(prec, r)
            row["payload"] = (p.mass, truth["payload"]["mass"])
        rows.append(row)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--heldout", default="/tmp/didim_heldout")
    ap.add_argument("--only", default=None)
    ap.add_argument("--out", default=str(ROOT / "docs" / "heldout_robots.md"))
    args = ap.parse_args()
    warnings.simplefilter("ignore", didim.DidimWarning)
    sets = []
    held = pathlib.Path(args.heldout)
    if (held / "truth.json").exists():
        sets.append((held, json.loads((held / "truth.json").read_text())["robots"], "heldout_robots.py"))
    if (SHARED / "truth.json").exists():
        sets.append((SHARED, json.loads((SHARED / "truth.json").read_text())["robots"], "shared/data/robots"))
    only = set(args.only.split(",")) if args.only else None
    rows = []
    for folder, truths, source in sets:
        for name, truth in truths.items():
            if only and name not in only:
                continue
            for row in evaluate(folder, name, truth):
                row["source"] = source
                rows.append(row)
                pay = f", payload {row['payload'][0]:.4f} kg for {row['payload'][1]:g}" if "payload" in row else ""
                print(f"{name} {row['method']}: worst Fv {100 * row['worst_fv']:.2f} %, Fc {100 * row['worst_fc']:.2f} %, "
                      f"validation {row['valid_ratio']:.3f}x floor, law {row['law_found']} (truth {row['law']}){pay}, "
                      f"{row['cpu_s']:.1f} s CPU", flush=True)
    lines = ["# didim on robots it was not built around", "",
             "Made by `python benches/heldout_eval.py` (records of `benches/heldout_robots.py`, an independent simulator, "
             f"and of `../shared/data/robots`), on {platform.node()} ({os.cpu_count()} cores), "
             f"{time.strftime('%Y-%m-%d')}. Fv, Fc: the worst joint's relative error against the truth; validation: the "
             "closed-loop force error on the validation record with the estimate, over its truth floor; CPU: process "
             "time of the identification.", "",
             "| robot | joints | rate | truth law | method | worst Fv | worst Fc | validation / floor | law found | payload (truth) | CPU |",
             "|---|---|---|---|---|---:|---:|---:|---|---|---:|"]
    for r in rows:
        pay = f"{r['payload'][0]:.4f} kg ({r['payload'][1]:g})" if "payload" in r else ""
        lines.append(f"| {r['robot']} | {r['joints']} ({', '.join(r['kinds'])}) | {r['rate_hz']} Hz | {r['law']} | "
                     f"{r['method']} | {100 * r['worst_fv']:.2f} % | {100 * r['worst_fc']:.2f} % | "
                     f"{r['valid_ratio']:.3f} | {r['law_found']} | {pay} | {r['cpu_s']:.1f} s |")
    pathlib.Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
