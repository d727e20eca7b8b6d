"""The robot doctor on a second held-out sweep (issue 40): 27 record pairs of benches/robot_doctor_heldout.py's
independent loop (Pinocchio RK4, its Panda, UR10 and RPR arm, their controllers, rates and friction laws) with seeds,
joints and sizes that no test or earlier bench used, 14 with one concealed effect and 13 clean. It prints one line per
pair: what the doctor named (effect, joint) against the truth, the wall time; docs/robot_doctor_sweep.md is written
by hand from its output.

    python benches/robot_doctor_sweep.py [--data /tmp/didim_rdoc_sweep] [--only n1,k35]

The records are made once into --data (kept). The doctor runs on one core (RAYON_NUM_THREADS=1), one pair at a time.
"""

from __future__ import annotations

import os

os.environ.setdefault("RAYON_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import pathlib  # noqa: E402
import sys  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import robot_doctor_heldout as H  # noqa: E402

#: The pairs: as robot_doctor_heldout's CASES (``effect`` None: clean).
SWEEP = {
    "n1": dict(robot="panda", seed=31, effect=dict(kind="stribeck", joint=1, dF_over_Fc=0.7, vst=0.05), want="stribeck"),
    "n2": dict(robot="ur10", seed=32, effect=dict(kind="asymmetric", joint=0, plus=1.25, minus=0.8),
               want="asymmetric_friction"),
    "n3": dict(robot="ur10", seed=33, effect=dict(kind="spring", joint=1, k=15.0, phi=0.5, c=3.0),
               want="position_dependent_torque"),
    "n4": dict(robot="rpr", seed=34, effect=dict(kind="load", joint=1, mu=0.05), want="load_dependent_friction"),
    "n5": dict(robot="panda", seed=35, effect=dict(kind="load", joint=3, mu=0.05), want="load_dependent_friction"),
    "n6": dict(robot="panda", seed=36, effect=dict(kind="delay"), want="delay"),
    "n7": dict(robot="rpr", seed=37, effect=dict(kind="lag", T_samples=4), want="delay"),
    "n8": dict(robot="panda", seed=38, effect=dict(kind="asymmetric", joint=5, plus=0.8, minus=1.2),
               want="asymmetric_friction"),
    "n9": dict(robot="ur10", seed=39, effect=dict(kind="spring", joint=0, k=10.0, phi=0.3, c=2.0),
               want="position_dependent_torque"),
    "n10": dict(robot="ur10", seed=40, effect=dict(kind="stribeck", joint=3, dF_over_Fc=0.7, vst=0.04),
                want="stribeck"),
    "n11": dict(robot="ur10", seed=44, effect=dict(kind="lag", T_samples=2), want="delay"),
    "n12": dict(robot="panda", seed=52, effect=dict(kind="spring", joint=0, k=3.0, phi=0.2, c=1.0),
                want="position_dependent_torque"),
    "n13": dict(robot="rpr", seed=53, effect=dict(kind="stribeck", joint=2, dF_over_Fc=0.6, vst=0.05),
                want="stribeck"),
    "n14": dict(robot="ur10", seed=54, effect=dict(kind="delay"), want="delay"),
    **{k: dict(robot=r, seed=s, effect=None, want=None) for k, r, s in (
        ("c4", "panda", 41), ("c5", "ur10", 42), ("c6", "rpr", 43), ("k33", "ur10", 33), ("k35", "panda", 35),
        ("k36", "panda", 36), ("k39", "ur10", 39), ("k45", "panda", 45), ("k46", "panda", 46), ("k47", "panda", 47),
        ("k48", "panda", 48), ("k49", "panda", 49), ("k50", "panda", 50))},
}


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default="/tmp/didim_rdoc_sweep")
    ap.add_argument("--only", default=None, help="comma-separated keys")
    args = ap.parse_args()
    data = pathlib.Path(args.data)
    data.mkdir(parents=True, exist_ok=True)
    H.CASES.update(SWEEP)
    keys = args.only.split(",") if args.only else list(SWEEP)
    tp = data / "truth.json"
    truth = json.loads(tp.read_text()) if tp.exists() else {}
    for k in keys:
        if k not in truth or not (data / f"{k}_valid.csv").exists():
            truth[k] = H.make_case(k, data)
            tp.write_text(json.dumps(truth, indent=1) + "\n")
        t = truth[k]
        got = H.run_doctor(k, t, data)
        want = (SWEEP[k]["want"], t.get("joint"))
        if "crash" in got or "stopped" in got:
            print(f"{k}: {got.get('crash') or got.get('stopped')}", flush=True)
            continue
        named = [(e, j) for e, j in got["named"]]
        right = bool(named) and named[0][0] == want[0] and (want[1] is None or named[0][1] == want[1]) \
            if want[0] else not named
        print(f"{k} ({SWEEP[k]['robot']}, seed {SWEEP[k]['seed']}): truth {want[0] or 'clean'}"
              f"{' on ' + want[1] if want[1] else ''}; named {named or 'nothing'}; {'right' if right else 'WRONG'}; "
              f"{got['wall']:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
