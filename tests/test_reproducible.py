"""Reproducible: the same input and options give bit-identical results, run after run and whatever the number of
threads of the parallel paths (rayon decimation of Y and the columns of W, the parallel QR of large regressors).
A new parallel path (e.g. a batch of simulations) gets its line in SCRIPT."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import didim
from didim import _core
from didim import scenarios as sc


def fingerprint(r: didim.IdentificationResult) -> str:
    """Every number of a result except the wall time, as exact text (repr of floats is exact)."""
    d = r.to_dict()
    d.pop("elapsed_s")
    for s in d.get("steps", {}).values():
        s.pop("elapsed_s")
    cov = b"" if r.covariance is None else np.ascontiguousarray(r.covariance).tobytes()
    return hashlib.sha256(json.dumps(d, sort_keys=True).encode() + cov).hexdigest()


def test_identification_twice_gives_the_same_bits(emps):
    for method in ("idim-ls", "didim", "oe-gn"):
        kw = {} if method == "idim-ls" else dict(apM=78.0)
        a = didim.identify(emps, "rigid", method, offset=True, **kw)
        b = didim.identify(emps, "rigid", method, offset=True, **kw)
        assert fingerprint(a) == fingerprint(b), method


def test_simulated_records_are_reproducible_from_their_seed():
    a = sc.make_recording(sc.TABLE3_TRUTH, "flexible", qr=sc.chirp(duration_s=2.0), seed=5)
    b = sc.make_recording(sc.TABLE3_TRUTH, "flexible", qr=sc.chirp(duration_s=2.0), seed=5)
    assert a.force.tobytes() == b.force.tobytes() and a.qm.tobytes() == b.qm.tobytes()
    c = sc.make_recording(sc.TABLE3_TRUTH, "flexible", qr=sc.chirp(duration_s=2.0), seed=6)
    assert c.force.tobytes() != a.force.tobytes()


#: Runs every parallel path of the core and prints one hash per path.
SCRIPT = textwrap.dedent(
    """
    import hashlib, json, sys, warnings
    import numpy as np
    import didim
    from didim import _core, scenarios as sc

    def h(*arrays):
        m = hashlib.sha256()
        for a in arrays:
            m.update(np.ascontiguousarray(a, dtype=float).tobytes())
        return m.hexdigest()[:16]

    rec = didim.load_mat(sys.argv[1])
    out = {}
    rng = np.random.default_rng(1)
    w = rng.standard_normal((rec.n, 12)) * np.array([10.0 ** k for k in range(-6, 6)])
    for kind in ("butter", "matlab"):
        dec = didim.Decimation.lowpass(5.0, rec.fs) if kind == "butter" else didim.Decimation.matlab(10)
        yd, wd = dec.apply(rec.force, w)
        out["decimate " + kind] = h(yd, wd)
    big = rng.standard_normal((40000, 8))  # 320000 entries: the QR and Q^T y run on rayon
    # the right-hand sides by NumPy's own sums: a product through the BLAS rounds with its thread count
    sol = _core.lstsq(big, (big * np.arange(8.0)).sum(axis=1) + rng.standard_normal(40000))
    out["lstsq (parallel QR)"] = h(sol["params"], sol["covariance"], sol["residual"])
    wide = rng.standard_normal((10500, 63)) * np.geomspace(1e-3, 1e3, 63)  # a 7-joint arm's system
    sol = _core.lstsq(wide, wide.sum(axis=1) + rng.standard_normal(10500))
    out["lstsq (a robot's width)"] = h(sol["params"], sol["covariance"], sol["residual"])
    sim = didim.simulate(rec, dict(M=95.1089, Fv=203.5034, Fc=20.3935, OF=-3.1648))
    out["simulate"] = h(sim.force, sim.q, sim.qd, sim.qdd)
    s = didim.simulation.problem(rec, "flexible").simulate_sensitivity(np.array(list(sc.TABLE3_TRUTH.values())))
    out["sensitivities"] = h(*s.values())
    r = didim.identify(rec, "rigid", "didim", apM=78.0, offset=True)
    out["didim"] = h(list(r.params.values()), r.covariance, [x.output_error for x in r.history])
    r = didim.identify(rec, "rigid", "oe-gn", apM=78.0, offset=True)
    out["oe-gn"] = h(list(r.params.values()), r.covariance)
    if len(sys.argv) > 2:
        from pathlib import Path
        d = Path(sys.argv[2])
        robot = didim.Robot.from_urdf(d / "ur5_cad.urdf")
        r = didim.identify(didim.load_record(d / "ur5_train.csv", robot=robot, controller=d / "ur5_controller.json"),
                           robot, "didim")
        out["robot didim"] = h(list(r.params.values()), r.covariance)
    print(json.dumps(out))
    """
)


def run_with_threads(threads: int, emps_path, robots=None) -> dict:
    # the core's pool and the BLAS's (NumPy's and SciPy's OpenBLAS, or MKL) at the same count
    env = dict(os.environ, RAYON_NUM_THREADS=str(threads), OPENBLAS_NUM_THREADS=str(threads),
               OMP_NUM_THREADS=str(threads), MKL_NUM_THREADS=str(threads))
    p = subprocess.run([sys.executable, "-c", SCRIPT, str(emps_path), *([str(robots)] if robots else [])],
                       capture_output=True, text=True, env=env, timeout=900)
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout.strip().splitlines()[-1])


def test_parallel_paths_give_the_same_bits_with_one_two_and_three_threads(emps_path):
    """Every parallel path gives the same bits whatever the thread count: the results are the same on any machine
    (a robot's DIDIM amplified the rounding of faer's parallel QR on a 7-joint arm's system to 0.1 % of its force
    error: its least squares now run on one thread; the data folder's UR5 ended at 1.3672 % or 1.3644 % with the
    BLAS on one thread or two: the identification runs it on one, didim._parallel.serial_blas)."""
    from conftest import ROBOTS_DIR

    robots = ROBOTS_DIR if (ROBOTS_DIR / "ur5_train.csv").exists() else None  # the robot's path where its data is
    one = run_with_threads(1, emps_path, robots)
    for n in (2, 3):
        other = run_with_threads(n, emps_path, robots)
        differ = [k for k in one if one[k] != other.get(k)]
        assert not differ, f"results depend on the thread count ({n} vs 1): {differ}"
    assert {"decimate butter", "decimate matlab", "lstsq (parallel QR)", "lstsq (a robot's width)", "didim",
            "oe-gn"} | ({"robot didim"} if robots else set()) <= set(one)


def test_the_loops_threads_follow_the_affinity_and_rayon_num_threads(monkeypatch):
    """One count of processors for every thread pool of the loops (didim._parallel.cores): the process's affinity,
    capped by RAYON_NUM_THREADS when set, so that "one core" means one for the core's pool and the Python pools alike."""
    from didim._parallel import cores

    try:
        allowed = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        allowed = os.cpu_count() or 1
    monkeypatch.delenv("RAYON_NUM_THREADS", raising=False)
    assert cores() == allowed
    monkeypatch.setenv("RAYON_NUM_THREADS", "1")
    assert cores() == 1
    monkeypatch.setenv("RAYON_NUM_THREADS", str(allowed + 5))
    assert cores() == allowed
    monkeypatch.setenv("RAYON_NUM_THREADS", "junk")
    assert cores() == allowed


def test_an_interrupt_stops_the_calls_already_running_on_a_pool(emps):
    """An interrupt of the thread waiting for a pool (didim._parallel.map_threads) stops the core calls running on its
    workers, not only the queued ones: a signal caught on the main thread does not reach a worker's computation, and a
    whole refit ran on (a CI run's doctor did not exit within 120 s of its signal); and it does so when the signal
    reaches a worker thread, not the waiting one. Each worker simulates in a loop
    until stopped or done; the interrupt must end every one of them with KeyboardInterrupt, and the core must run again
    afterwards."""
    import signal
    import threading

    from didim._parallel import map_threads

    params = {"M": 95.0, "Fv": 210.0, "Fc": 20.0, "OF": -3.0}
    outcome, workers = {}, []

    def work(k):
        workers.append(threading.get_ident())
        try:
            for _ in range(2000):  # minutes if nothing stops it
                didim.simulate(emps, params, substeps=1)
        except KeyboardInterrupt:
            outcome[k] = "stopped"
            raise
        outcome[k] = "ran to its end"

    # the signal handed to a worker thread, as the kernel may hand a Ctrl-C (a CI run's): the thread waiting for the
    # pool must still wake and raise it
    timer = threading.Timer(0.5, lambda: signal.pthread_kill(workers[0], signal.SIGINT))
    timer.start()
    with pytest.raises(KeyboardInterrupt):
        map_threads(work, [0, 1], 2)
    timer.cancel()
    assert outcome == {0: "stopped", 1: "stopped"}
    sim = didim.simulate(emps, params, substeps=1)  # the stop is released
    assert np.all(np.isfinite(sim.force))



@pytest.mark.parametrize("where, name", [("methods.robot", "didim"), ("methods.robot", "didim_elastic"),
                                         ("methods.robot", "oe_lm"), ("methods.robot", "idim_ls"),
                                         ("methods.robot", "payload"), ("methods.identification", "didim_rigid"),
                                         ("methods.identification", "didim_flexible"), ("methods.identification", "idim_ls"),
                                         ("methods.oe", "oe_lm"), ("methods.oe", "oe_nm"), ("api", "identify"),
                                         ("doctor", "doctor")])
def test_every_public_method_runs_the_blas_on_one_thread(where, name):
    """Called directly (the README's example, the benches), not only through ``didim.identify``, each method is
    :func:`didim._parallel.serial_blas`'s wrapper: its least squares run with the BLAS on one thread, so its result
    does not depend on the machine's thread count."""
    import importlib

    import didim._parallel as par

    fn = getattr(importlib.import_module(f"didim.{where}"), name)
    assert fn.__code__ is par.serial_blas(lambda: None).__code__ and callable(fn.__wrapped__)


def test_serial_blas_holds_one_thread_also_when_nested():
    threadpoolctl = pytest.importorskip("threadpoolctl")
    import scipy.linalg  # noqa: F401  (its BLAS loaded before the count is taken)

    import didim._parallel as par

    def blas_threads():
        return [i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]

    seen = []
    inner = par.serial_blas(lambda: seen.append(blas_threads()))
    outer = par.serial_blas(lambda: (seen.append(blas_threads()), inner(), seen.append(blas_threads())))
    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        before = blas_threads()
        outer()
        after = blas_threads()
    assert [n for s in seen for n in s] == [1] * sum(len(s) for s in seen) and seen[0]
    assert after == before  # the limit is lifted when the outermost call returns
