"""didim's rigid-body algorithms against Pinocchio's C++ on the same machine, in one run: the articulated-body
algorithm (forward dynamics), Newton-Euler (inverse dynamics) and the joint-torque regressor (n x 10n) on the UR5 and
the Panda (example-robot-data's URDFs; the Panda's fingers locked) and the data folder's UR5.

    python benches/pinocchio_compare.py               # writes docs/pinocchio.md
    python benches/pinocchio_compare.py --no-write    # prints the table only
    python benches/pinocchio_compare.py --repeats 9 --rounds 40 --states 500

Pinocchio's side is benches/pinocchio/bench.cpp, compiled here with g++ -O3 -march=native -DNDEBUG against the
headers of the `pin` wheel (its cmeel.prefix): the algorithms are templates, instantiated in that file for this
processor, as a user building Pinocchio gets them. Its model is the one pin's URDF parser builds (from Python),
handed over as joint types, placements and inertias and rebuilt there (Model::addJoint): the wheel's compiled parser
returns a Model laid out for its own build, which a -march=native program cannot share. didim's side is the Rust
example crates/didim-core/examples/pinocchio_compare.rs (cargo build --release, the build users get), reading the
URDF itself. Both read the same states, write their results, which are checked against each other (1e-9 of the
largest entry, as tests/test_robot.py), and only then time each algorithm: ns per call over the states, best and
median of the rounds; the two programs alternate `--repeats` times so that a busy spell of the machine falls on both.

Needs: g++ (apt-get install -y g++), cargo, the `pin` wheel (pip install pin) and Eigen's headers, which the wheel
does not ship (pip install cmeel-eigen, or apt-get install -y libeigen3-dev); example-robot-data (pip install
example-robot-data) for the URDFs. What is missing is named and the benchmark is skipped (exit status 0).
"""

from __future__ import annotations

import argparse
import datetime
import hashlib
import importlib.metadata
import os
import pathlib
import platform
import shutil
import subprocess
import sys
import sysconfig

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent
SOURCE = HERE / "pinocchio" / "bench.cpp"
DOC = ROOT / "docs" / "pinocchio.md"
ROBOTS_DIR = pathlib.Path(os.environ.get("DIDIM_ROBOTS_DIR", ROOT.parent / "shared" / "data" / "robots"))
PANDA_ARM = [f"panda_joint{i}" for i in range(1, 8)]
#: the issue's bound, as tests/test_robot.py: relative to the largest entry of Pinocchio's result
RTOL = 1e-9
ALGORITHMS = ("aba", "rnea", "regressor")
#: the compile definitions of pinocchio::pinocchio_headers (the wheel's lib/cmake/pinocchio/pinocchioTargets.cmake);
#: without PINOCCHIO_ENABLE_TEMPLATE_INSTANTIATION the algorithms are compiled in bench.cpp, for this processor
DEFINES = ["BOOST_MPL_LIMIT_LIST_SIZE=30", "BOOST_MPL_LIMIT_VECTOR_SIZE=30", "BOOST_MPL_CFG_NO_PREPROCESSED_HEADERS",
           "BOOST_FUSION_INVOKE_MAX_ARITY=12"]
CXXFLAGS = ["-std=c++17", "-O3", "-march=native", "-DNDEBUG"]
#: pin's joint models as bench.cpp builds them
JOINT_TYPES = {"JointModelRX": "RX", "JointModelRY": "RY", "JointModelRZ": "RZ", "JointModelRevoluteUnaligned": "RU",
               "JointModelPX": "PX", "JointModelPY": "PY", "JointModelPZ": "PZ", "JointModelPrismaticUnaligned": "PU"}


class Missing(Exception):
    """Something the benchmark needs is not on this machine (the message says how to get it)."""


def _prefixes() -> list[pathlib.Path]:
    """Every cmeel.prefix on the import path (the wheels' C++ trees), then the system's."""
    dirs = [pathlib.Path(p) for p in sys.path if p] + [pathlib.Path(sysconfig.get_paths()["purelib"])]
    seen, out = set(), []
    for d in dirs:
        p = d / "cmeel.prefix"
        if p.is_dir() and p.resolve() not in seen:
            seen.add(p.resolve())
            out.append(p)
    return out + [pathlib.Path("/usr")]


def _find(prefixes, relative: str, what: str, how: str) -> pathlib.Path:
    """The first prefix holding `relative` (returns the prefix's directory that holds it)."""
    for p in prefixes:
        for base in (p / "include", p / "include" / "eigen3"):
            if (base / relative).exists():
                return base
    raise Missing(f"{what} not found ({relative} in {', '.join(str(p) for p in prefixes)}): {how}")


def compile_pinocchio(build: pathlib.Path) -> pathlib.Path:
    """bench.cpp built against the pin wheel (rebuilt when the source or the wheel changes)."""
    gxx = os.environ.get("CXX") or shutil.which("g++")
    if not gxx:
        raise Missing("no C++ compiler: apt-get install -y g++ (or set CXX)")
    try:
        version = importlib.metadata.version("pin")
    except importlib.metadata.PackageNotFoundError:
        raise Missing("Pinocchio's wheel is not installed: pip install pin") from None
    pre = _prefixes()
    incs = [_find(pre, "pinocchio/algorithm/aba.hpp", "Pinocchio's headers", "pip install pin"),
            _find(pre, "boost/variant.hpp", "boost's headers", "pip install cmeel-boost"),
            _find(pre, "Eigen/Core", "Eigen's headers",
                  "pip install cmeel-eigen (or apt-get install -y libeigen3-dev)")]
    flags = [*CXXFLAGS, *(f"-D{d}" for d in DEFINES), *(f"-I{i}" for i in dict.fromkeys(incs))]
    key = hashlib.sha1(SOURCE.read_bytes() + " ".join([gxx, *flags]).encode()).hexdigest()[:10]
    exe = build / f"pinocchio_bench-{version}-{key}"  # built again when the source or the flags change
    if exe.exists():
        return exe
    build.mkdir(parents=True, exist_ok=True)
    cmd = [gxx, *flags, str(SOURCE), "-o", str(exe)]
    print("compiling Pinocchio's side:", " ".join(cmd), file=sys.stderr)
    r = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if r.returncode:
        sys.stderr.write(r.stderr[-4000:])
        raise SystemExit("bench.cpp did not compile (above)")
    return exe


def build_didim() -> pathlib.Path:
    """The Rust example, release build, in CARGO_TARGET_DIR (or the workspace's target/)."""
    cargo = shutil.which("cargo")
    if not cargo:
        raise Missing("no cargo: install Rust (rustup) to build didim's side")
    print("building didim's side: cargo build --release -p didim-core --example pinocchio_compare", file=sys.stderr)
    subprocess.run([cargo, "build", "--release", "-q", "-p", "didim-core", "--example", "pinocchio_compare"],
                   cwd=ROOT, check=True)
    target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
    return target / "release" / "examples" / "pinocchio_compare"


def _example_robot(name: str) -> str:
    try:
        files = importlib.metadata.files("example-robot-data") or []
    except importlib.metadata.PackageNotFoundError:
        raise Missing("example-robot-data is not installed: pip install example-robot-data") from None
    for f in files:
        if str(f).endswith(f"/{name}"):
            return str(f.locate())
    raise Missing(f"example-robot-data has no {name}")


def robots() -> list[tuple[str, str, list[str] | None]]:
    out = [("UR5", _example_robot("ur5_robot.urdf"), None),
           ("Panda (arm, fingers locked)", _example_robot("panda.urdf"), PANDA_ARM)]
    cad = ROBOTS_DIR / "ur5_cad.urdf"
    if cad.exists():
        out.append(("UR5 (data folder's ur5_cad)", str(cad), None))
    return out


def write_model(path: pathlib.Path, urdf: str, joints):
    """The model that pin's URDF parser builds (reduced to `joints` as tests/test_robot.py does), written for
    bench.cpp: per joint its type, parent, axis, placement, mass, centre of mass and inertia about it."""
    import pinocchio as pin

    m = pin.buildModelFromUrdf(urdf)
    if joints is not None:
        m = pin.buildReducedModel(m, [m.getJointId(j) for j in m.names[1:] if j not in joints], pin.neutral(m))
    lines = [str(m.njoints - 1)]
    for i in range(1, m.njoints):
        kind = m.joints[i].shortname()
        if kind not in JOINT_TYPES:
            raise Missing(f"joint {m.names[i]} is a {kind}, which bench.cpp does not build")
        axis = m.joints[i].extract().axis if kind.endswith("Unaligned") else np.zeros(3)
        body, place = m.inertias[i], m.jointPlacements[i]
        ii = body.inertia
        nums = [*axis, *place.rotation.reshape(-1), *place.translation, body.mass, *body.lever,
                ii[0, 0], ii[0, 1], ii[1, 1], ii[0, 2], ii[1, 2], ii[2, 2]]
        lines.append(f"{JOINT_TYPES[kind]} {m.parents[i]} " + " ".join(repr(float(x)) for x in nums))
    path.write_text("\n".join(lines) + "\n")
    return m


def write_states(path: pathlib.Path, m, k: int, seed: int) -> int:
    """K random states within the joints' limits (±π where there are none), speeds and accelerations N(0, 1),
    torques 10·N(0, 1), and an armature 0.01..0.3 per joint; returns the number of joints."""
    n = m.nv
    lo = np.where(np.isfinite(m.lowerPositionLimit), m.lowerPositionLimit, -np.pi)
    hi = np.where(np.isfinite(m.upperPositionLimit), m.upperPositionLimit, np.pi)
    rng = np.random.default_rng(seed)
    q = rng.uniform(lo, hi, size=(k, n))
    v, a, tau = rng.normal(size=(k, n)), rng.normal(size=(k, n)), 10 * rng.normal(size=(k, n))
    arm = rng.uniform(0.01, 0.3, size=n)
    with open(path, "w") as f:
        f.write(f"{n} {k}\n")
        for block in (q, v, a, tau):
            f.writelines(" ".join(repr(float(x)) for x in row) + "\n" for row in block)
        f.write(" ".join(repr(float(x)) for x in arm) + "\n")
    return n


def read_results(path: pathlib.Path, n: int) -> dict[str, np.ndarray]:
    rows = np.loadtxt(path, ndmin=2)
    return {"aba": rows[:, :n], "rnea": rows[:, n:2 * n], "regressor": rows[:, 2 * n:].reshape(len(rows), n, 10 * n)}


def check(didim_out, pin_out) -> dict[str, float]:
    """Each algorithm's worst relative difference over the states (of the largest entry of Pinocchio's, per state)."""
    errs = {}
    for name in ALGORITHMS:
        got, want = didim_out[name], pin_out[name]
        axes = tuple(range(1, want.ndim))
        errs[name] = float(np.max(np.max(np.abs(got - want), axis=axes) / np.max(np.abs(want), axis=axes)))
    return errs


def run(exe, inputs, states, out, rounds) -> dict[str, tuple[float, float]]:
    """One program run: `exe MODEL STATES OUT ROUNDS` (Pinocchio's) or `exe URDF STATES OUT ROUNDS [JOINTS]`
    (didim's); its times per algorithm, best and median pass."""
    cmd = [str(exe), inputs[0], str(states), str(out), str(rounds), *inputs[1:]]
    r = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if r.returncode:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{r.stderr}")
    times = {}
    for line in r.stdout.splitlines():
        name, best, median = line.split()
        times[name] = (float(best), float(median))
    return times


def machine() -> dict[str, str]:
    cpu = "?"
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next((x.split(":", 1)[1].strip() for x in f if x.startswith("model name")), cpu)
    except OSError:
        pass

    def version(cmd):
        try:
            return subprocess.run(cmd, capture_output=True, text=True, check=False).stdout.splitlines()[0]
        except (OSError, IndexError):
            return "?"

    rev = version(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"])
    dirty = version(["git", "-C", str(ROOT), "status", "--porcelain", "--untracked-files=no"]) != "?"
    return {"cpu": f"{cpu}, {os.cpu_count()} cores ({platform.machine()})",
            "pin": importlib.metadata.version("pin"), "gxx": version(["g++", "--version"]),
            "rustc": version(["rustc", "--version"]), "didim": rev + (" (with uncommitted changes)" if dirty else "")}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--states", type=int, default=1000, help="random states per robot (each timed call is one)")
    ap.add_argument("--rounds", type=int, default=30, help="timed passes over the states per program run")
    ap.add_argument("--repeats", type=int, default=5, help="program runs per side, alternating didim and Pinocchio")
    ap.add_argument("--seed", type=int, default=37)
    ap.add_argument("--didim-exe", help="a didim timing binary built before (another commit's, to compare two)")
    ap.add_argument("--no-write", action="store_true", help="print the table, leave docs/pinocchio.md as it is")
    args = ap.parse_args(argv)
    build = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target")) / "pinocchio-bench"
    try:
        pin_exe = compile_pinocchio(build)
        didim_exe = pathlib.Path(args.didim_exe) if args.didim_exe else build_didim()
        cases = robots()
    except Missing as e:
        print(f"skipped: {e}")
        return 0
    load_before = os.getloadavg()
    rows = []
    for label, urdf, joints in cases:
        states, pin_res, didim_res = build / "states.txt", build / "pinocchio.txt", build / "didim.txt"
        model = build / "model.txt"
        n = write_states(states, write_model(model, urdf, joints), args.states, args.seed)
        inputs = {"pin": [str(model)], "didim": [urdf] + ([",".join(joints)] if joints else [])}
        # the first run of each writes its results: compared before anything is timed
        run(pin_exe, inputs["pin"], states, pin_res, 1)
        run(didim_exe, inputs["didim"], states, didim_res, 1)
        errs = check(read_results(didim_res, n), read_results(pin_res, n))
        bad = {k: e for k, e in errs.items() if not e < RTOL}
        if bad:
            raise SystemExit(f"{label}: didim and Pinocchio disagree ({bad}, bound {RTOL:g}): nothing timed")
        runs = {"pin": [], "didim": []}
        for rep in range(args.repeats):
            for side, exe in (("pin", pin_exe), ("didim", didim_exe))[:: 1 if rep % 2 == 0 else -1]:
                runs[side].append(run(exe, inputs[side], states, build / f"{side}-timed.txt", args.rounds))
        for alg in ALGORITHMS:
            t = {s: (min(r[alg][0] for r in runs[s]), float(np.median([r[alg][1] for r in runs[s]])))
                 for s in runs}
            rows.append((label, n, alg, t["pin"], t["didim"], errs[alg]))
            print(f"{label:30s} {alg:10s} Pinocchio {t['pin'][0]:9.1f} ns  didim {t['didim'][0]:9.1f} ns  "
                  f"ratio {t['didim'][0] / t['pin'][0]:.2f}  (medians {t['pin'][1]:.1f} / {t['didim'][1]:.1f}; "
                  f"agree to {errs[alg]:.1e})", flush=True)
    load_after = os.getloadavg()
    table = ["| robot | n | algorithm | Pinocchio C++ (ns/call) | didim (ns/call) | didim / Pinocchio | "
             "medians (ns) Pinocchio / didim | max. rel. difference |",
             "|---|---|---|---|---|---|---|---|"]
    for label, n, alg, tp, td, err in rows:
        table.append(f"| {label} | {n} | {alg} | {tp[0]:.0f} | {td[0]:.0f} | **{td[0] / tp[0]:.2f}** | "
                     f"{tp[1]:.0f} / {td[1]:.0f} | {err:.1e} |")
    m = machine()
    when = datetime.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z")
    setup = [f"- date: {when}; machine: {m['cpu']}; load average (1, 5, 15 min) "
             f"{' '.join(f'{x:.2f}' for x in load_before)} before, {' '.join(f'{x:.2f}' for x in load_after)} after",
             f"- Pinocchio {m['pin']} (the `pin` wheel's headers and libraries), {m['gxx']}, "
             f"`{' '.join(CXXFLAGS)}`",
             f"- didim {m['didim']}, {m['rustc']}, `cargo build --release` (the workspace's profile: thin LTO, "
             "4 codegen units; no target-cpu flag: aba picks its AVX2+FMA build at run time)",
             f"- {args.states} random states per robot (seed {args.seed}), {args.rounds} timed passes over them per "
             f"program run, {args.repeats} runs per side alternating; ns per call is the best pass of all runs, the "
             "medians beside it the median of each run's median pass"]
    print("\n".join(setup + [""] + table))
    if not args.no_write:
        text = DOC.read_text() if DOC.exists() else ""
        start, end = "<!-- results: written by benches/pinocchio_compare.py -->", "<!-- end of results -->"
        block = "\n".join([start, *setup, "", *table, end])
        if start in text and end in text:
            text = text[:text.index(start)] + block + text[text.index(end) + len(end):]
        else:
            text = text + "\n" + block + "\n"
        DOC.write_text(text)
        print(f"wrote {DOC}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
