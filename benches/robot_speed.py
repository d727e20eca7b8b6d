"""Robot DIDIM's time on every robot record at hand, on one core: its CPU time, iterations and closed-loop
simulations, the time per simulation, and the record's size; writes docs/robot_speed.md.

    python benches/robot_speed.py [--heldout /tmp/didim_heldout] [--out docs/robot_speed.md] [--only NAME ...]

Records: ../shared/data/robots, robotdoctor and flexrobots (the rigid model), and the held-out arms of
``benches/heldout_robots.py`` when ``--heldout`` names their folder. Issue 37's targets: at most 10 s of CPU for a
6-joint, 20 s record, 20 s for 7 joints. The CPU time is the process's (user + system) over the identification alone,
the record loaded; the machine is shared, so the load average is printed with the table.
"""

from __future__ import annotations

import os

os.environ.setdefault("RAYON_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import pathlib  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402

import didim  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
DATA = pathlib.Path(os.environ.get("DIDIM_DATA_DIR", ROOT.parent / "shared" / "data"))


def cases(heldout: pathlib.Path | None):
    out = [(DATA / "robots", "ur5", "ur5_train.csv"), (DATA / "robots", "pendulum", "pendulum_train.csv")]
    out += [(DATA / "robotdoctor", "ur5", f"ur5_d{k}_train.csv") for k in range(1, 6)]
    out += [(DATA / "flexrobots", bot, f"{bot}_train.csv") for bot in ("ur5flex", "arm2")]
    if heldout is not None:
        out += [(heldout, p.name[:-len("_train.csv")], p.name) for p in sorted(heldout.glob("*_train.csv"))]
    return [(folder, bot, name) for folder, bot, name in out if (folder / name).exists()]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--heldout", type=pathlib.Path, default=None)
    ap.add_argument("--out", type=pathlib.Path, default=ROOT / "docs" / "robot_speed.md")
    ap.add_argument("--only", nargs="*", default=None, help="record file names to time")
    args = ap.parse_args()
    warnings.simplefilter("ignore", didim.DidimWarning)
    load0 = os.getloadavg()[0]
    rows = []
    for folder, bot, name in cases(args.heldout):
        if args.only and name not in args.only:
            continue
        robot = didim.Robot.from_urdf(folder / f"{bot}_cad.urdf")
        rec = didim.load_record(folder / name, robot=robot, controller=folder / f"{bot}_controller.json")
        c0 = time.process_time()
        try:
            r = didim.identify(rec, robot, "didim", controller_check="warn")
            cpu = time.process_time() - c0
            what = (f"{r.iterations} | {r.simulations} | {1e3 * cpu / max(r.simulations, 1):.0f} ms | "
                    f"{100 * r.force_error:.2f} %")
        except didim.DidimError as e:
            cpu = time.process_time() - c0
            what = f"failed: {str(e)[:80]} | | |"
        target = 10.0 if rec.ndof <= 6 else 20.0
        scaled = cpu * 20.0 / (rec.n * rec.dt)
        row = (f"| {folder.name}/{name} | {rec.ndof} | {1 / rec.dt:.0f} Hz | {rec.n * rec.dt:.1f} s | {rec.n} | "
               f"{cpu:.1f} s | {scaled:.1f} s{'' if scaled <= target else ' (over)'} | {what} |")
        print(row, flush=True)
        rows.append(row)
    load1 = os.getloadavg()[0]
    head = [
        "# Robot DIDIM's time, record by record",
        "",
        f"Made by `python benches/robot_speed.py{' --heldout …' if args.heldout else ''}` on {platform.node()} "
        f"({os.cpu_count()} cores, shared; load average {load0:.1f} at the start, {load1:.1f} at the end), "
        f"{time.strftime('%Y-%m-%d %H:%M')}, one core (RAYON_NUM_THREADS=1, OPENBLAS_NUM_THREADS=1). CPU: the "
        "process time of `didim.identify(rec, robot, \"didim\")` alone, the record loaded; per 20 s: that time "
        "scaled to a 20 s record of the same rate (the work grows with the samples), against issue 37's targets "
        "(10 s for up to 6 joints, 20 s for 7); simulations: the closed loops simulated (DIDIM's iterations, their "
        "pull-backs, the start's checks and the friction law's search in closed loop).",
        "",
        "| record | joints | rate | length | samples | CPU | per 20 s | iterations | simulations | CPU per simulation "
        "| force error |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    args.out.write_text("\n".join(head + rows) + "\n", encoding="utf-8")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
