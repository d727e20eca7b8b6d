"""Thread pools for the identification loops (the core releases the interpreter while it simulates)."""

from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Iterable, List, TypeVar

T = TypeVar("T")
R = TypeVar("R")


def map_threads(fn: Callable[[T], R], items: Iterable[T], workers: int) -> List[R]:
    """``[fn(x) for x in items]`` on a pool of ``workers`` threads, in order. On an interrupt (Ctrl-C, SIGTERM raised
    as one) or an error, the calls not yet started are cancelled and only the running ones are waited for: a pool left
    by ``with`` waits for every queued call, and a doctor interrupted while its refits were queued ran on for minutes
    before it exited (a fault-injection test's 120 s)."""
    pool = ThreadPoolExecutor(max(1, int(workers)))
    try:
        return list(pool.map(fn, items))
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
