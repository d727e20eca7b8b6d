"""Signals and malformed sweep options: SIGTERM gives 143 and one line, Ctrl-C 130; a command killed at any moment
(SIGINT, SIGTERM, SIGKILL) leaves the previous outputs intact and no temporary file; sweep workers do not outlive
their parent; a malformed --grid or --draw is a user error (exit 2, one line, no traceback)."""

import os
import random
import signal
import subprocess
import sys
import time

import pytest

CLI = [sys.executable, "-m", "didim"]


def _children(pid: int):
    out = subprocess.run(["ps", "-o", "pid=", "--ppid", str(pid)], capture_output=True, text=True).stdout
    return [int(x) for x in out.split()]


def _wait_for(pred, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.1)
    return False


def test_sigterm_stops_a_sweep_and_its_workers(tmp_path):
    out = tmp_path / "out.json"
    p = subprocess.Popen(CLI + ["sweep", "--scenario", "flexible-motor-friction", "--model", "flexible", "--seeds", "60",
                                "--workers", "2", "--json", str(out), "--quiet"],
                         cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert _wait_for(lambda: len(_children(p.pid)) >= 2, 60), "the sweep started no workers"
    workers = _children(p.pid)
    time.sleep(1.0)
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 143, err
    assert "terminated" in err and "Traceback" not in err
    assert not out.exists()
    assert _wait_for(lambda: not any(os.path.exists(f"/proc/{w}") and _alive(w) for w in workers), 10), \
        "sweep workers outlived their parent"
    assert sorted(os.listdir(tmp_path)) == []


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split()[2] != "Z"
    except OSError:
        return False


@pytest.mark.parametrize("args", [
    ["--grid", "apM=1:2:x"], ["--draws", "3", "--draw", "apM=1"], ["--draws", "3", "--draw", "apM=x:y"],
    ["--grid", "apM=1:1e9:1000000000"], ["--grid", "apM=1:10:1000", "--grid", "f0=1:2:1000"],
    ["--grid", "bogus=1,2"], ["--grid", "apM=-1:5:3:log"],
])
def test_malformed_sweep_options_are_user_errors(tmp_path, args):
    r = subprocess.run(CLI + ["sweep", "--scenario", "flexible-motor-friction", "--model", "rigid", *args, "--quiet"],
                       cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr and r.stderr.strip().count("\n") == 0, r.stderr


def test_unknown_scenario_is_a_user_error(tmp_path):
    r = subprocess.run(CLI + ["sweep", "--scenario", "nope", "--seeds", "2", "--quiet"], cwd=tmp_path,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "unknown scenario 'nope'" in r.stderr


def test_killed_at_random_moments_a_command_leaves_previous_outputs_intact(tmp_path, emps_path):
    """Fault injection: the doctor writing over existing outputs is killed (SIGINT, SIGTERM, SIGKILL) at 18 random
    moments spread over a whole run (the first run, uninterrupted, gives its length); every time, each output holds
    either its previous content or a complete new one, the exit code is the signal's, and no temporary file remains.
    The record is the first 9 s of DATA_EMPS, so that a run lasts seconds. (Seeded: the same moments on every run.)"""
    import scipy.io

    d = scipy.io.loadmat(emps_path)
    n = 9000
    rec = tmp_path / "rec.mat"
    scipy.io.savemat(rec, {k: (v[:n] if getattr(v, "shape", (1,))[0] > 1 else v)
                           for k, v in d.items() if not k.startswith("__")})
    js, html = tmp_path / "d.json", tmp_path / "d.html"
    cmd = CLI + ["doctor", str(rec), "--json", str(js), "--html", str(html)]
    lengths = []
    for _ in range(2):  # the shorter of two whole runs: the first may pay for cold caches, and moments spread over
        t0 = time.perf_counter()  # a run much longer than the later ones would mostly land after they finished
        subprocess.run(cmd, cwd=tmp_path, capture_output=True, check=True, timeout=300)
        lengths.append(time.perf_counter() - t0)
    length = min(lengths)
    js.write_text('{"previous": true}\n')
    html.write_text("<p>previous</p>\n")
    rng = random.Random(13)
    outcomes = {"complete": 0, "killed": 0}
    for i in range(18):
        sig = (signal.SIGINT, signal.SIGTERM, signal.SIGKILL)[i % 3]
        p = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        first = p.stderr.readline()  # the doctor has started (Python's own start-up is not what is tested)
        time.sleep(rng.uniform(0.0, 1.1 * length))
        p.send_signal(sig)
        _, err = p.communicate(timeout=120)
        err = first + err
        outcomes["complete" if p.returncode == 0 else "killed"] += 1
        if p.returncode != 0:
            assert p.returncode == {signal.SIGINT: 130, signal.SIGTERM: 143, signal.SIGKILL: -9}[sig], (sig, err)
        assert "Traceback" not in err, err
        assert "didim: error" not in err, err
        text = js.read_text()
        assert text == '{"previous": true}\n' or (text.startswith("{") and text.rstrip().endswith("}")), text[-200:]
        page = html.read_text()
        assert page == "<p>previous</p>\n" or page.rstrip().endswith("</html>"), page[-200:]
        leftovers = [f for f in os.listdir(tmp_path) if f not in ("rec.mat", "d.json", "d.html")]
        assert leftovers == [], leftovers
    assert outcomes["killed"] >= 9, outcomes  # most signals land while the doctor runs


def test_an_unused_compressed_variable_is_never_expanded(tmp_path, emps_path):
    """A MAT file with an unused variable that decompresses to 480 MB (a bomb of 1 MB) loads within a small
    memory budget: only the record's variables are decompressed, and their sizes are checked from their headers."""
    bomb = tmp_path / "bomb.mat"
    make = ("import numpy as np, scipy.io as sio, sys\n"
            "d = {k: v for k, v in sio.loadmat(sys.argv[1]).items() if not k.startswith('__')}\n"
            "d['junk'] = np.zeros((60_000_000, 1))\n"
            "sio.savemat(sys.argv[2], d, do_compression=True)\n")
    subprocess.run([sys.executable, "-c", make, str(emps_path), str(bomb)], check=True)
    assert bomb.stat().st_size < 5_000_000
    load = ("import resource, sys, didim\n"
            "before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
            "r = didim.load_mat(sys.argv[1])\n"
            "print(r.n, (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) // 1024)\n")
    out = subprocess.run([sys.executable, "-c", load, str(bomb)], check=True, capture_output=True, text=True).stdout
    n, grown_mb = map(int, out.split())
    assert n == 24841
    assert grown_mb < 100, f"loading grew the process by {grown_mb} MB: the unused variable was decompressed"


LONG_CALL = """
import sys, time
import numpy as np
import didim
qr = np.tile(np.concatenate([np.linspace(0, 0.2, 2000), np.linspace(0.2, 0, 2000)]), 100)
rec = didim.Recording(dt=1e-3, qr=qr, force=np.zeros_like(qr), qm=qr, controller=didim.EmpsCascade())
p = {"M": 95.0, "Fv": 200.0, "Fc": 20.0}
print("start", flush=True)
t = time.perf_counter()
try:
    if sys.argv[1] == "one":
        didim.simulate(rec, p, integrator="rk4", substeps=400)
    else:
        didim.simulate_batch(rec, [dict(p, M=95.0 + i) for i in range(4)], integrator="rk4", substeps=200)
    print("finished", flush=True)
except KeyboardInterrupt:
    print("interrupted", flush=True)
"""


@pytest.mark.parametrize("mode", ["one", "batch"])
def test_ctrl_c_stops_a_long_core_call(mode):
    """Ctrl-C reaches a simulation running in the Rust core (alone or as a parallel batch): it stops at its next
    check with KeyboardInterrupt, instead of running to the end (minutes here)."""
    out, err = _signalled_after_a_second(LONG_CALL, [mode], signal.SIGINT)
    assert out.strip() == "interrupted", (out, err)


def _signalled_after_a_second(code: str, args, sig):
    """Runs ``code`` in a new interpreter, sends ``sig`` a second after it prints "start"; returns (stdout, stderr)
    of the rest of its run, or fails when it does not stop within 30 s."""
    p = subprocess.Popen([sys.executable, "-c", code, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "start"
    time.sleep(1.0)
    p.send_signal(sig)
    try:
        return p.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        p.kill()
        pytest.fail(f"the core call did not stop within 30 s of signal {sig!r}")


TWO_THREADS = """
import signal, threading, time
import numpy as np
import didim
qr = np.tile(np.concatenate([np.linspace(0, 0.2, 2000), np.linspace(0.2, 0, 2000)]), 100)
rec = didim.Recording(dt=1e-3, qr=qr, force=np.zeros_like(qr), qm=qr, controller=didim.EmpsCascade())
p = {"M": 95.0, "Fv": 200.0, "Fc": 20.0}

class Terminated(KeyboardInterrupt):
    pass

def on_term(signum, frame):
    raise Terminated()

signal.signal(signal.SIGTERM, on_term)
seen = {}

def other():
    try:
        didim.simulate(rec, p, integrator="rk4", substeps=400)
        seen["other"] = "finished"
    except BaseException as e:
        seen["other"] = type(e).__name__

t = threading.Thread(target=other)
t.start()
print("start", flush=True)
try:
    didim.simulate(rec, p, integrator="rk4", substeps=400)
    print("main finished", flush=True)
except BaseException as e:
    t.join()
    print("main", type(e).__name__, "other", seen.get("other"), flush=True)
"""


def test_the_signal_handlers_exception_reaches_the_main_thread_when_two_threads_run_the_core():
    """SIGTERM, whose handler raises its own class (the CLI's ``Terminated``, which sets exit code 143), arrives while
    the main thread and another thread both run long core calls (as the doctor ranks its candidates on two threads):
    both calls stop, the main thread gets the handler's exception and the other thread a plain KeyboardInterrupt.
    Before, whichever call ended first took the handler's exception, and the main thread could get the plain one:
    a SIGTERM then exited with Ctrl-C's code (seen once in the fault-injection test)."""
    for _ in range(3):
        out, err = _signalled_after_a_second(TWO_THREADS, [], signal.SIGTERM)
        assert out.strip() == "main Terminated other KeyboardInterrupt", (out, err)


def test_a_batch_too_large_for_memory_is_a_memory_error_not_an_abort(emps_path):
    """Under a 4 GB address-space limit, 20,000 simulations of DATA_EMPS (26 GB of signals) raise MemoryError
    naming the size, before anything is allocated, instead of aborting the interpreter."""
    code = ("import resource, sys\nimport numpy as np\nimport didim\n"
            "rec = didim.load_mat(sys.argv[1])\n"
            "resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))\n"
            "try:\n    didim.simulate_batch(rec, np.tile([95.0, 200.0, 20.0], (20000, 1)), 'rigid')\n"
            "    print('no error')\nexcept MemoryError as e:\n    print('MemoryError', e)\n")
    r = subprocess.run([sys.executable, "-c", code, str(emps_path)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-500:]
    assert r.stdout.startswith("MemoryError") and "20000 simulations" in r.stdout and "GB" in r.stdout, r.stdout


def test_an_interrupt_python_swallows_in_a_finaliser_still_ends_the_run_as_interrupted():
    """Python cannot raise KeyboardInterrupt from a finaliser (a __del__ or weakref callback during garbage collection):
    it prints "Exception ignored ... Traceback" and carries on. The CLI notes every signal, hides that report, and
    exits 130 with its line once the command ends (found by a fresh-clone run of the fault-injection test)."""
    code = (
        "import os, signal, sys\n"
        "import didim.cli as cli\n"
        "class Finaliser:\n"
        "    def __del__(self):\n"
        "        os.kill(os.getpid(), signal.SIGINT)\n"
        "        for _ in range(100000):\n"
        "            pass\n"
        "def command(args):\n"
        "    Finaliser()\n"
        "    print('command finished')\n"
        "    return 0\n"
        "cli.cmd_identify = command\n"
        "sys.exit(cli.main(['identify', 'x.csv']))\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 130, (r.returncode, r.stdout, r.stderr)
    assert "command finished" in r.stdout and "Traceback" not in r.stderr, r.stderr
    assert r.stderr.strip().splitlines()[-1].startswith("didim: interrupted"), r.stderr


def test_a_process_forked_after_a_core_call_runs_its_own():
    """Core computations run on a worker thread of the calling thread, started at its first and kept, and their
    parallel loops on rayon's pool: a process forked after that (``multiprocessing``'s default on Linux) inherits the
    worker's channel and the pool's state but none of their threads, and must start its own (else its first call, or
    its first parallel loop, would wait forever). The child's simulation and decimation equal the parent's."""
    code = r"""
import multiprocessing as mp, sys
import numpy as np
import didim

rec = didim.Recording(dt=1e-3, qr=0.01 * np.sin(np.linspace(0, 6, 400)), force=np.zeros(400), qm=np.zeros(400),
                      controller=didim.controllers.PD(kp=2e4, kd=400.0), lead_in=None)
params = {"M": 95.0, "Fv": 200.0, "Fc": 20.0}

from didim.signal import Decimation
dec = Decimation.lowpass(40.0, 1000.0)
cols = np.random.default_rng(0).standard_normal((4000, 16))

def both():
    return didim.simulate(rec, params, "rigid").force, dec.apply(np.zeros(len(cols)), cols)[1]

def child(_):
    return both()

parent = both()  # starts this thread's worker and rayon's pool (16 columns decimated in parallel)
with mp.get_context("fork").Pool(1) as pool:
    got = pool.map_async(child, [0]).get(timeout=60)[0]
for g, p in zip(got, parent):
    np.testing.assert_array_equal(g, p)
print("ok")
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-2000:]
