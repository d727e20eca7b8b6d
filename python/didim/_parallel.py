"""Thread pools for the identification loops (the core releases the interpreter while it simulates)."""

import functools
import os
import threading
from concurrent.futures import ThreadPoolExecutor, wait
from typing import Any, Callable, Iterable, List, TypeVar

T = TypeVar("T")
R = TypeVar("R")
F = TypeVar("F", bound=Callable[..., Any])


def serial_blas(fn: F) -> F:
    """``fn`` with the BLAS libraries (NumPy's and SciPy's OpenBLAS, MKL, BLIS) on one thread while it runs, through
    threadpoolctl: a threaded BLAS splits a long dot product or a matrix product between its threads and rounds
    differently with each count, and an identification carries such last digits into its results where a parameter
    is weakly determined (the held-out UR10's rigid step at 1.25 Hz: wrist 1's base parameters two to five times apart
    with the BLAS on one thread or two, and step 2 then found its 21 Hz mode or none). The same record gives the same
    result on every machine; the loops' own threads (:func:`map_threads`, the core's) are kept."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        global _serial_depth
        with _serial_lock:
            outer = _serial_depth == 0
            _serial_depth += 1
        try:
            if not outer:  # already limited (the limit is the process's): the methods call one another
                return fn(*args, **kwargs)
            from threadpoolctl import threadpool_limits

            import scipy.linalg  # noqa: F401  (SciPy's own BLAS loaded, so limited as well)

            with threadpool_limits(limits=1, user_api="blas"):
                return fn(*args, **kwargs)
        finally:
            with _serial_lock:
                _serial_depth -= 1

    return wrapper  # type: ignore[return-value]


_serial_depth = 0
_serial_lock = threading.Lock()


def cores() -> int:
    """The processors the identification loops may use: those this process may run on (its affinity: ``taskset -c
    0`` gives one), not the machine's count, and no more than ``RAYON_NUM_THREADS`` when it is set (the core's own
    pool obeys it: one setting says "one core" to both). Threads beyond them only add switching."""
    try:
        n = max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # not every platform has affinities
        n = max(1, os.cpu_count() or 1)
    env = os.environ.get("RAYON_NUM_THREADS", "").strip()
    if env.isdigit() and int(env) > 0:
        n = min(n, int(env))
    return n


#: How long the thread waiting for a pool waits at a time before it lets Python run a pending signal handler (s).
WAIT_SLICE_S = 0.05


def map_threads(fn: Callable[[T], R], items: Iterable[T], workers: int) -> List[R]:
    """``[fn(x) for x in items]`` on a pool of ``workers`` threads, in order. On an interrupt (Ctrl-C, SIGTERM raised
    as one) or an error, the calls not yet started are cancelled and only the running ones are waited for: a pool left
    by ``with`` waits for every queued call, and a doctor interrupted while its refits were queued ran on for minutes
    before it exited (a fault-injection test's 120 s)."""
    pool = ThreadPoolExecutor(max(1, int(workers)))
    try:
        futures = [pool.submit(fn, x) for x in items]
        out = []
        for f in futures:
            # waited for in short slices: a signal the kernel hands to another thread does not wake a wait without a
            # timeout, and Python runs its handler on this thread only when it next runs (a SIGINT sent to the
            # process was raised only once every call had ended, on a CI machine)
            while not f.done():
                wait([f], timeout=WAIT_SLICE_S)
            out.append(f.result())
        return out
    except BaseException:
        # the calls already running are stopped too: a signal caught on this thread does not reach the core's
        # computations on the workers (a whole refit would run on), so every core call stops at its next check and
        # no new one starts until the pool is closed
        pool.shutdown(wait=False, cancel_futures=True)
        _hold(True)
        try:
            pool.shutdown(wait=True)
        finally:
            _hold(False)
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


_holds = 0
_holds_lock = threading.Lock()


def _hold(on: bool) -> None:
    """Holds the core's stop while any pool of this process is being stopped (pools nest: a doctor's refits run step
    2's grids on pools of their own)."""
    global _holds
    from . import _core

    with _holds_lock:
        _holds += 1 if on else -1
        _core.hold_stop(_holds > 0)
