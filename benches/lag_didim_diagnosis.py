"""Why the robot doctor misses a force lag of several sample periods (held-out Panda e8, 3 ms at 1 kHz): DIDIM with
the lag is exact on a record of its own loop, but on e8's record its refit from the base model (the doctor's) stalls
far above the truth floor, where output-error LM from the same start reaches it.

    python benches/lag_didim_diagnosis.py [--data /tmp/didim_rdoc_heldout]

Needs the held-out records of benches/robot_doctor_heldout.py (made with --make-only). Prints, for the true lag:
1. one least-squares step from an estimate on a noise-free, unrounded record of didim's own loop with that estimate
   (the fixed point: the step's largest relative change);
2. DIDIM's iterations from that estimate on the same record with the encoders' rounding, with and without the lag
   (each iterate's joints' force error, RMS of the relative ones);
3. on the e8 record itself: DIDIM with the true lag from the base model (the doctor's refit) and from the URDF's
   values, and output-error LM from the base model: training and held-out force errors, the time.
"""

import argparse
import dataclasses
import pathlib
import time

import numpy as np

import didim
from didim.methods import robot as R


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default="/tmp/didim_rdoc_heldout")
    ap.add_argument("--lag", type=float, default=0.003, help="the lag (s) tried (e8's truth: 3 ms)")
    a = ap.parse_args()
    d = pathlib.Path(a.data)
    robot = didim.Robot.from_urdf(d / "panda_cad.urdf")
    ctl = d / "e8_controller.json"
    rec = didim.load_record(d / "e8_train.csv", robot=robot, controller=ctl)
    val = didim.load_record(d / "e8_valid.csv", robot=robot, controller=ctl)
    base = didim.identify(rec, robot, "didim")
    print(f"base (no lag): training {100 * base.force_error:.2f} %, held-out "
          f"{100 * R.force_errors(val, R.simulate_robot(val, base)['force'])[0]:.2f} %")
    model, bp = base.structure, R.base_parameters(robot)
    theta = np.array([base.params.get(k, 0.0) for k in R._theta_names(model, bp)])

    for lag in (0.0, a.lag):
        exact = dataclasses.replace(rec, force_lag=(lag,) * robot.ndof, position_resolution=None)
        sim = R.simulate_robot(exact, base, quantize=False)
        own = dataclasses.replace(exact, force=sim["force"], qm=sim["q"], name="own")
        plant = R._RobotPlant(own, model, bp, R._decimation(own), base.law, {}, 1e-3, lambda s: None, {})
        step = np.asarray(plant.solve(theta, plant.simulate(theta))["params"])
        rel = np.abs(step - theta) / np.maximum(np.abs(theta), 1e-3 * np.abs(theta).max())
        print(f"lag {1e3 * lag:g} ms, own noise-free loop: one LS step from the estimate moves it by at most {rel.max():.1e}")
        rounded = dataclasses.replace(own, position_resolution=rec.position_resolution)
        errs = []
        R.didim(rounded, model, start=base, max_iter=12, tol=1e-9,
                progress=lambda s: errs.append(s.split("RMS")[1].strip()) if "DIDIM iteration" in s else None)
        print(f"lag {1e3 * lag:g} ms, own loop with the encoders' rounding, DIDIM from the estimate: " + ", ".join(errs))

    kw = dict(force_lag=(a.lag,) * robot.ndof)
    tr, va = dataclasses.replace(rec, **kw), dataclasses.replace(val, **kw)
    for name, fit in (("DIDIM from the base", lambda: R.didim(tr, model, start=base)),
                      ("DIDIM from the URDF's values", lambda: R.didim(tr, model)),
                      ("OE-LM from the base", lambda: R.oe_lm(tr, model, start=base))):
        t0 = time.perf_counter()
        r = fit()
        ev = R.force_errors(va, R.simulate_robot(va, r)["force"])[0]
        print(f"e8 with the {1e3 * a.lag:g} ms lag, {name}: training {100 * r.force_error:.2f} %, held-out "
              f"{100 * ev:.2f} %, {r.iterations} iterations, {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
