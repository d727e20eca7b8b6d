import os
import pathlib

import pytest

_BENCHES = pathlib.Path(__file__).resolve().parents[1] / "benches"
_bench_modules = {}


def bench_module(name: str):
    """The script ``benches/<name>.py`` as a module, loaded once: the independent plants the tests share with the
    benchmarks (e.g. ``doctor_independent``, a rigid axis simulated apart from didim's simulator)."""
    if name not in _bench_modules:
        import importlib.util

        spec = importlib.util.spec_from_file_location(name, _BENCHES / f"{name}.py")
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        _bench_modules[name] = mod
    return _bench_modules[name]


def robot_doctor_case(key: str, case: dict, tmp: pathlib.Path, robot: dict = None):
    """One record pair of benches/robot_doctor_heldout.py's independent loop (``case`` as its ``CASES`` entries, with
    ``robot`` a ``ROBOTS`` entry of its own under the key when given), made into ``tmp``: the CAD robot, the truth and
    the training and validation records."""
    import didim

    pytest.importorskip("pinocchio")
    bench = bench_module("robot_doctor_heldout")
    if robot is not None:
        bench.ROBOTS[key] = robot
    bench.CASES[key] = case
    truth = bench.make_case(key, tmp)
    cad = didim.Robot.from_urdf(tmp / truth["urdf"])
    ctl = tmp / truth["controller"]
    return cad, truth, *(didim.load_record(tmp / f"{key}_{p}.csv", robot=cad, controller=ctl)
                         for p in ("train", "valid"))


#: The EMPS records live outside the package, in the shared data folder next to the checkout.
EMPS_DIR = pathlib.Path(os.environ.get("DIDIM_EMPS_DIR", pathlib.Path(__file__).resolve().parents[2] / "shared" / "data" / "emps"))


def _emps(name):
    path = EMPS_DIR / name
    if not path.exists():
        pytest.skip(f"EMPS record {path} not available (set DIDIM_EMPS_DIR)")
    return path


@pytest.fixture(scope="session")
def emps_path():
    return _emps("DATA_EMPS.mat")


@pytest.fixture(scope="session")
def emps_pulses_path():
    return _emps("DATA_EMPS_PULSES.mat")


@pytest.fixture(scope="session")
def emps(emps_path):
    import didim

    return didim.load_mat(emps_path)


@pytest.fixture(scope="session")
def emps_pulses(emps_pulses_path):
    import didim

    return didim.load_mat(emps_pulses_path)


#: Records with known truth from an independent simulator (../shared/data/truthbench, see its README).
TRUTHBENCH_DIR = pathlib.Path(
    os.environ.get("DIDIM_TRUTHBENCH_DIR", pathlib.Path(__file__).resolve().parents[2] / "shared" / "data" / "truthbench")
)


@pytest.fixture(scope="session")
def truthbench():
    """(load, truth): ``load("flexible/paperlike_moving_chirp")`` reads a record, ``truth[key]`` its truth.json entry."""
    import json

    import didim

    if not (TRUTHBENCH_DIR / "truth.json").exists():
        pytest.skip(f"truthbench {TRUTHBENCH_DIR} not available (set DIDIM_TRUTHBENCH_DIR)")
    truth = json.loads((TRUTHBENCH_DIR / "truth.json").read_text())
    cache = {}

    def load(key):
        if key not in cache:
            cache[key] = didim.load_mat(TRUTHBENCH_DIR / f"{key}.mat")
        return cache[key]

    return load, truth


def cut_log(rec, i0: int, name: str = "cut log"):
    """``rec`` from sample ``i0`` on, as a log that began there (the same controller and encoder)."""
    import didim

    return didim.Recording(dt=rec.dt, qr=rec.qr[i0:], force=rec.force[i0:], qm=rec.qm[i0:], controller=rec.controller,
                           position_resolution=rec.position_resolution, name=name)


def resolved(model, rec, coulomb_eps=None):
    """``model`` as a result identified on ``rec`` carries it: a Coulomb smoothing left to the record resolved to the
    record's (``didim.simulation.default_coulomb_eps``), or to ``coulomb_eps`` when the method was given one."""
    import dataclasses

    from didim.simulation import default_coulomb_eps

    if model.coulomb_eps is not None:
        return model
    return dataclasses.replace(model, coulomb_eps=default_coulomb_eps(rec) if coulomb_eps is None else coulomb_eps)


#: Robot records with known truth from a simulator built on Pinocchio (../shared/data/robots, see its README).
ROBOTS_DIR = pathlib.Path(
    os.environ.get("DIDIM_ROBOTS_DIR", pathlib.Path(__file__).resolve().parents[2] / "shared" / "data" / "robots"))
#: Flexible-joint robot records with known truth from another simulator (../shared/data/flexrobots, see its README).
FLEXROBOTS_DIR = pathlib.Path(
    os.environ.get("DIDIM_FLEXROBOTS_DIR",
                   pathlib.Path(__file__).resolve().parents[2] / "shared" / "data" / "flexrobots"))


@pytest.fixture(scope="session")
def flexrobots_dir():
    if not (FLEXROBOTS_DIR / "truth.json").exists():
        pytest.skip(f"flexible-joint robot records {FLEXROBOTS_DIR} not available (set DIDIM_FLEXROBOTS_DIR)")
    return FLEXROBOTS_DIR


@pytest.fixture(scope="session")
def robots_dir():
    if not (ROBOTS_DIR / "truth.json").exists():
        pytest.skip(f"robot records {ROBOTS_DIR} not available (set DIDIM_ROBOTS_DIR)")
    return ROBOTS_DIR
