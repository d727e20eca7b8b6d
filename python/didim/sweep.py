"""Robustness sweeps: re-run an identification over a grid or random draws of initial values and noise seeds, in
parallel, and report the convergence rate and the spread of the estimates against their predicted σ.

Each point of a sweep is a dict of keyword values (the scenario or record, the noise seed, the model and method, the
initial values such as ``apM``, ``lambda0``, ``f0``, method options). :func:`run_point` builds the record and runs
:func:`didim.identify` on it; :func:`sweep` maps it over the points with a ``concurrent.futures`` executor — a local
process pool by default, or any executor, e.g. a Dask cluster's (``client.get_executor()``, or pass the
``distributed.Client`` itself): the same code path runs on one machine or many. Results come back in the order of the
points whatever the completion order, so a sweep is deterministic.
"""

from __future__ import annotations

import concurrent.futures as cf
import functools
import itertools
import json
import math
import multiprocessing
import os
import sys
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence

import numpy as np

from ._errors import DataError, DidimError, DidimWarning

#: Simulated EMPS-like records with a known truth (see :mod:`didim.scenarios`): the truth, the model that generated
#: it, and the reference trajectory.
SCENARIOS: Dict[str, Dict[str, Any]] = {
    # the three-step DIDIM's case: all friction on the motor side (Fv2 = Fc2 = 0)
    "flexible-motor-friction": dict(model="flexible", reference="trapezoid_chirp",
                                    truth=dict(M1=68.0, Fv1=200.5, Fc1=19.5, M2=38.0, Fv2=0.0, Fc2=0.0, K12=8.8e5)),
    # the paper's Table 3 values, load-side friction included
    "flexible-table3": dict(model="flexible", reference="trapezoid_chirp",
                            truth=dict(M1=68.0, Fv1=104.0, Fc1=10.0, M2=38.0, Fv2=96.5, Fc2=9.5, K12=8.8e5)),
    # a rigid axis with the EMPS benchmark's values on EMPS-like moves
    "rigid-emps": dict(model="rigid", reference="emps_like", truth=dict(M=95.1089, Fv=203.5034, Fc=20.3935)),
}

#: Keys of a point that describe the record rather than the identification.
RECORD_KEYS = ("scenario", "record", "seed", "force_noise", "controller")


@functools.lru_cache(maxsize=32)
def _record(scenario: Optional[str], record: Optional[str], seed: int, force_noise: float,
            controller: Optional[str] = None):
    from . import scenarios as sc
    from .controllers import load_controller
    from .formats.loaders import load_record

    if record is not None:
        return load_record(record, controller=load_controller(controller) if controller else None), None
    if scenario not in SCENARIOS:
        raise DataError(f"unknown scenario {scenario!r}: use one of {', '.join(SCENARIOS)} or give a record file")
    spec = SCENARIOS[scenario]
    qr = getattr(sc, spec["reference"])()
    rec = sc.make_recording(spec["truth"], spec["model"], qr, force_noise=force_noise, seed=seed,
                            name=f"{scenario} seed {seed}")
    return rec, dict(spec["truth"])


def step_truth(truth: Optional[Mapping[str, float]], step: Optional[str]) -> Optional[Dict[str, float]]:
    """The truth seen by a step of the three-step DIDIM: the rigid totals M = M1 + M2, Fv = Fv1 + Fv2,
    Fc = Fc1 + Fc2 (step 1), the mass ratio λ = M1/(M1 + M2) and the blocked-motor mode
    f_n_flex = √(K12/M2)/(2π) (step 2)."""
    if truth is None or step is None or "M1" not in truth:
        return dict(truth) if truth is not None else None
    if step == "rigid":
        return {"M": truth["M1"] + truth["M2"], "Fv": truth["Fv1"] + truth["Fv2"], "Fc": truth["Fc1"] + truth["Fc2"]}
    if step == "mode":
        return {"lambda": truth["M1"] / (truth["M1"] + truth["M2"]),
                "f_n_flex": math.sqrt(truth["K12"] / truth["M2"]) / (2 * math.pi)}
    return dict(truth)


def _summary(r) -> Dict[str, Any]:
    return dict(converged=bool(r.converged), params=dict(r.params), std=dict(r.std), output_error=r.output_error,
                iterations=r.iterations, simulations=r.simulations, elapsed_s=r.elapsed_s, message=r.message)


def run_point(point: Mapping[str, Any]) -> Dict[str, Any]:
    """Runs one point of a sweep: builds the record (``scenario`` and ``seed``, or a ``record`` file) and identifies it
    with the other keys (``model``, ``method`` and :func:`didim.identify`'s options, e.g. ``apM``, ``lambda0``,
    ``f0``). Returns a JSON-ready dict: ``converged``, ``params``, ``std``, ``output_error``, ``iterations``,
    ``simulations``, ``elapsed_s``, ``message``, ``truth`` and, for the three-step DIDIM, its steps; an error that
    stops the identification is returned in ``error`` (with ``converged`` False), not raised."""
    from .api import identify

    p = dict(point)
    rec_args = (p.pop("scenario", None), p.pop("record", None), int(p.pop("seed", 0)), float(p.pop("force_noise", 1.0)),
                p.pop("controller", None))
    out: Dict[str, Any] = dict(point=dict(point), error=None, truth=None)
    t0 = time.perf_counter()
    try:
        rec, truth = _record(*rec_args)
        out["truth"] = truth
        model = p.pop("model", SCENARIOS.get(rec_args[0] or "", {}).get("model", "rigid"))
        method = p.pop("method", "didim")
        with warnings.catch_warnings(record=True) as caught:  # a worker's warnings go back with its result
            warnings.simplefilter("always", DidimWarning)
            r = identify(rec, model, method, **p)
        out["warnings"] = [str(w.message) for w in caught if issubclass(w.category, DidimWarning)]
    except DidimError as e:
        out.update(converged=False, error=f"{type(e).__name__}: {e}", elapsed_s=time.perf_counter() - t0)
        return out
    out.update(_summary(r))
    out["steps"] = {k: _summary(s) for k, s in r.steps.items()}
    return out


#: Most points of one sweep (grid size times draws); a larger sweep is refused before anything runs.
MAX_POINTS = 100_000


def check_points(points: Sequence[Mapping[str, Any]]) -> None:
    """Refuses, before anything runs, what would fail every point alike: an unknown scenario, a record that cannot
    be opened, an option the method does not take (a DataError naming it)."""
    from . import _checks
    from .api import check_options

    seen = set()
    checked = set()
    for p in points:
        for k, v in p.items():  # values: a bad one would fail its points alike
            if (k, repr(v)) in checked:
                continue
            checked.add((k, repr(v)))
            if k == "apM" and v is not None:
                _checks.real("apM (a priori mass)", v, "kg", lo=0.0)
            elif _checks.is_option(k) and v is not None:
                _checks.options(**{k: v})
            elif k == "seed":
                _checks.whole("seed", v, lo=0)
        opts = {k: v for k, v in p.items() if k not in RECORD_KEYS and k not in ("model", "method")}
        key = (p.get("scenario"), p.get("record"), p.get("model"), p.get("method"), tuple(sorted(opts)))
        if key in seen:
            continue
        seen.add(key)
        if p.get("record") is None and p.get("scenario") not in SCENARIOS:
            raise DataError(f"unknown scenario {p.get('scenario')!r}: use one of {', '.join(SCENARIOS)} or give a record "
                            "file")
        if p.get("record") is not None:  # a record every point reads: one that cannot be loaded fails here, once
            _record(None, p["record"], 0, 1.0, p.get("controller"))
        model = p.get("model", SCENARIOS.get(p.get("scenario") or "", {}).get("model", "rigid"))
        check_options(model, p.get("method", "didim"), opts)


def grid_points(grid: Mapping[str, Sequence[Any]], fixed: Optional[Mapping[str, Any]] = None) -> List[Dict[str, Any]]:
    """The cartesian product of ``grid`` (key → values), each point completed with ``fixed``; at most
    :data:`MAX_POINTS`."""
    keys = list(grid)
    size = math.prod(len(list(grid[k])) for k in keys)
    if size > MAX_POINTS:
        raise DataError(f"the grid has {size} points ({' × '.join(str(len(list(grid[k]))) for k in keys)}); at most "
                        f"{MAX_POINTS} are run: use fewer values or random draws")
    return [{**(fixed or {}), **dict(zip(keys, vals))} for vals in itertools.product(*(list(grid[k]) for k in keys))]


def random_points(ranges: Mapping[str, tuple], n: int, *, seed: int = 0,
                  fixed: Optional[Mapping[str, Any]] = None) -> List[Dict[str, Any]]:
    """``n`` random draws: ``ranges`` maps a key to ``(low, high)`` (uniform), ``(low, high, "log")`` (log-uniform)
    or ``(low, high, "int")`` (integers in [low, high]); reproducible with ``seed``."""
    if not 0 <= int(n) <= MAX_POINTS:
        raise DataError(f"the number of draws must be between 0 and {MAX_POINTS}, got {n}")
    for k, spec in ranges.items():
        ok = len(spec) in (2, 3) and all(isinstance(x, (int, float)) and math.isfinite(x) for x in spec[:2])
        if not ok or (len(spec) == 3 and spec[2] not in ("lin", "log", "int")):
            raise DataError(f"draw range of {k}: {spec!r} must be (low, high) or (low, high, 'log' | 'int') with "
                            "finite numbers (CLI: --draw KEY=LO:HI[:log|:int])")
        if spec[0] > spec[1]:
            raise DataError(f"draw range of {k}: low {spec[0]:g} is above high {spec[1]:g}")
        if len(spec) == 3 and spec[2] == "log" and min(spec[0], spec[1]) <= 0:
            raise DataError(f"draw range of {k}: a log range needs low and high > 0, got {spec[0]}, {spec[1]}")
    rng = np.random.default_rng(seed)
    pts = []
    for _ in range(int(n)):
        d = dict(fixed or {})
        for k, spec in ranges.items():
            lo, hi = float(spec[0]), float(spec[1])
            kind = spec[2] if len(spec) > 2 else "lin"
            if kind == "log":
                d[k] = float(math.exp(rng.uniform(math.log(lo), math.log(hi))))
            elif kind == "int":
                d[k] = int(rng.integers(int(lo), int(hi) + 1))
            else:
                d[k] = float(rng.uniform(lo, hi))
        pts.append(d)
    return pts


def _init_worker() -> None:
    # one Rust thread per worker process: the pool already spreads the points over the cores
    os.environ["RAYON_NUM_THREADS"] = "1"


class _Bar:
    """A one-line progress bar on stderr (or a callback receiving the line)."""

    def __init__(self, total: int, enabled, label: str = "sweep"):
        self.total, self.done, self.ok, self.t0, self.label = total, 0, 0, time.perf_counter(), label
        self.say = enabled if callable(enabled) else ((lambda s: print(s, end="", file=sys.stderr, flush=True))
                                                      if enabled else None)
        # a bar redrawn in place on a terminal; one line per update in a log (a captured \r runs the bars together)
        self.tty = callable(enabled) or (bool(enabled) and sys.stderr.isatty())

    def update(self, converged: bool) -> None:
        self.done += 1
        self.ok += bool(converged)
        if self.say is None:
            return
        el = time.perf_counter() - self.t0
        eta = el / self.done * (self.total - self.done)
        width = 30
        fill = int(width * self.done / self.total)
        line = (f"{self.label} [{'#' * fill}{'.' * (width - fill)}] {self.done}/{self.total}, "
                f"{self.ok} converged, {el:.1f} s, ETA {eta:.1f} s")
        if self.tty:
            self.say("\r" + line + ("\n" if self.done == self.total else ""))
        else:
            self.say(line + "\n")


def _executor(executor, workers: int):
    """(executor, owned) from a name, an Executor, or an object with ``get_executor()`` (a Dask client)."""
    if executor is None:
        executor = "process" if workers > 1 else "serial"
    if isinstance(executor, str):
        if executor == "serial":
            return None, False
        if executor == "thread":
            return cf.ThreadPoolExecutor(max_workers=workers), True
        if executor == "process":
            ctx = multiprocessing.get_context("spawn")  # forking a process with live Rust threads is unsafe
            return cf.ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_init_worker), True
        raise DataError(f"unknown executor {executor!r}: use 'serial', 'thread', 'process', an Executor or a Dask client")
    if hasattr(executor, "get_executor"):
        return executor.get_executor(), False
    if isinstance(executor, cf.Executor) or hasattr(executor, "submit"):
        return executor, False
    raise DataError(f"executor must be a name, a concurrent.futures.Executor or a Dask client, got {type(executor).__name__}")


def _stop(ex) -> None:
    """Stops an owned executor at once: pending points cancelled, worker processes terminated and reaped."""
    held = getattr(ex, "_processes", None)  # ProcessPoolExecutor's workers (no public accessor)
    procs = list(held.values()) if isinstance(held, dict) else []
    ex.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        if proc.is_alive():
            proc.terminate()
    for proc in procs:
        proc.join(timeout=5)
        if proc.is_alive():
            proc.kill()
            proc.join(timeout=5)


def sweep(points: Sequence[Mapping[str, Any]], *, task: Callable[[Mapping[str, Any]], Dict[str, Any]] = run_point,
          workers: Optional[int] = None, executor=None, progress=True, agree_rtol: float = 0.01,
          label: str = "sweep") -> "SweepResult":
    """Runs ``task`` (default :func:`run_point`) on every point, in parallel, with a progress bar.

    Args:
        points: the points (dicts of keyword values), e.g. from :func:`grid_points` or :func:`random_points`.
        workers: parallel workers (default: the number of cores).
        executor: "process" (default with several workers: a local process pool), "thread", "serial", any
            ``concurrent.futures.Executor``, or a ``distributed.Client`` (its executor: the same code path on a Dask
            cluster).
        progress: True for a progress bar on stderr, False for none, or a callable receiving the bar's text.
        agree_rtol: relative distance to the consensus (median of the converged runs) within which a converged run
            counts as having reached the same estimate.
    """
    points = [dict(p) for p in points]
    if not points:
        raise DataError("the sweep has no points")
    workers = int(workers or os.cpu_count() or 1)
    ex, owned = _executor(executor, workers)
    bar = _Bar(len(points), progress, label)
    results: List[Optional[Dict[str, Any]]] = [None] * len(points)
    t0 = time.perf_counter()
    try:
        if ex is None:
            for i, p in enumerate(points):
                results[i] = task(p)
                bar.update(results[i].get("converged", False))
        else:
            futures = {ex.submit(task, p): i for i, p in enumerate(points)}
            for fut in cf.as_completed(futures):
                i = futures[fut]
                try:
                    results[i] = fut.result()
                except Exception as e:  # a worker crash is a result, not the end of the sweep
                    results[i] = dict(point=points[i], converged=False, error=f"{type(e).__name__}: {e}", truth=None)
                bar.update(results[i].get("converged", False))
    except BaseException:
        if owned:  # interrupted (Ctrl-C, SIGTERM): no waiting for running points, no worker left behind
            _stop(ex)
            owned = False
        raise
    finally:
        if owned:
            ex.shutdown(wait=True)
    _warn_once(results)
    return SweepResult(points=points, results=results, elapsed_s=time.perf_counter() - t0, workers=workers,
                       agree_rtol=agree_rtol)


def _warn_once(results: Sequence[Optional[Dict[str, Any]]]) -> None:
    """Issues the warnings the runs returned (a worker process's own would print in Python's raw format, past the
    command line's one-line handler), each distinct message once, with the number of runs that gave it."""
    counts: Dict[str, int] = {}
    for r in results:
        for w in (r or {}).get("warnings", ()):
            counts[w] = counts.get(w, 0) + 1
    for w, k in counts.items():
        warnings.warn(w + (f" ({k} runs)" if k > 1 else ""), DidimWarning, stacklevel=3)


def _median(xs):
    return float(np.median(xs)) if len(xs) else float("nan")


@dataclass
class SweepResult:
    """The points of a sweep, their results (see :func:`run_point`), and the statistics of the study."""

    points: List[Dict[str, Any]]
    results: List[Dict[str, Any]]
    elapsed_s: float = float("nan")
    workers: int = 1
    agree_rtol: float = 0.01
    meta: Dict[str, Any] = field(default_factory=dict)

    def varied(self) -> List[str]:
        """The keys whose value differs between points."""
        keys = []
        for k in self.points[0]:
            vals = {json.dumps(p.get(k), sort_keys=True, default=str) for p in self.points}
            if len(vals) > 1:
                keys.append(k)
        return keys

    def params(self, step: Optional[str] = None) -> List[str]:
        for r in self.results:
            src = r.get("steps", {}).get(step) if step else r
            if src and src.get("params"):
                return list(src["params"])
        return []

    def _src(self, r, step):
        return r.get("steps", {}).get(step) if step else r

    def converged(self, step: Optional[str] = None) -> List[bool]:
        """Per run: the method's (or the step's) own convergence flag."""
        return [bool((self._src(r, step) or {}).get("converged")) for r in self.results]

    def consensus(self, step: Optional[str] = None) -> Dict[str, float]:
        """Median of each estimate over the converged runs."""
        conv = [self._src(r, step) for r, c in zip(self.results, self.converged(step)) if c]
        return {n: _median([c["params"][n] for c in conv]) for n in self.params(step)}

    def agrees(self, step: Optional[str] = None) -> List[bool]:
        """Per run: converged and every estimate within ``agree_rtol`` of the consensus."""
        cons = self.consensus(step)
        out = []
        for r, c in zip(self.results, self.converged(step)):
            src = self._src(r, step)
            ok = c
            if ok:
                for n, c in cons.items():
                    v = src["params"].get(n, float("nan"))
                    ok &= abs(v - c) <= self.agree_rtol * max(abs(c), 1e-12)
            out.append(ok)
        return out

    def convergence_rate(self, step: Optional[str] = None) -> float:
        return float(np.mean(self.converged(step)))

    def rates_by(self, key: str, step: Optional[str] = None) -> List[tuple]:
        """(value, runs, converged, agreeing) per value of ``key``."""
        agree = self.agrees(step)
        groups: Dict[str, list] = {}
        for p, c, a in zip(self.points, self.converged(step), agree):
            groups.setdefault(json.dumps(p.get(key), default=str), []).append((p.get(key), c, a))
        rows = []
        for _, items in groups.items():
            rows.append((items[0][0], len(items), sum(c for _, c, _ in items), sum(a for _, _, a in items)))
        try:
            rows.sort(key=lambda x: x[0])
        except TypeError:
            pass
        return rows

    def spread(self, step: Optional[str] = None) -> List[Dict[str, float]]:
        """Per parameter, over the runs that reached the consensus: truth, consensus, spread (sample std), mean
        predicted σ, spread/σ, and RMS of (estimate − truth)/σ when the truth is known. A rigid identification of a
        flexible record is compared with the rigid totals (see :func:`step_truth`)."""
        conv = [(r, self._src(r, step)) for r, a in zip(self.results, self.agrees(step)) if a]
        names = self.params(step)
        if step is None and "M" in names:
            step_of_truth: Optional[str] = "rigid"
        elif step is None and "lambda" in names:
            step_of_truth = "mode"
        else:
            step_of_truth = step
        rows = []
        for n in names:
            est = np.array([c["params"][n] for _, c in conv], dtype=float)
            sig = np.array([c.get("std", {}).get(n, np.nan) for _, c in conv], dtype=float)
            truth = step_truth(conv[0][0].get("truth"), step_of_truth) if conv else None
            tv = truth.get(n) if truth else None
            mean_sig = float(np.nanmean(sig)) if sig.size and np.isfinite(sig).any() else float("nan")
            spread = float(np.std(est, ddof=1)) if est.size > 1 else float("nan")
            z = ((est - tv) / sig) if tv is not None and sig.size else np.array([])
            z = z[np.isfinite(z)]
            rows.append(dict(name=n, truth=float(tv) if tv is not None else float("nan"), consensus=_median(est),
                             spread=spread, sigma=mean_sig,
                             ratio=spread / mean_sig if mean_sig and math.isfinite(mean_sig) else float("nan"),
                             z_rms=float(np.sqrt(np.mean(z**2))) if z.size else float("nan"), runs=int(est.size)))
        return rows

    def summary(self, step: Optional[str] = None) -> str:
        n = len(self.results)
        conv = sum(self.converged(step))
        agree = sum(self.agrees(step))
        errs = sum(r.get("error") is not None for r in self.results)
        reasons: Dict[str, int] = {}
        for r in self.results:
            if r.get("error") is not None:
                reasons[r["error"]] = reasons.get(r["error"], 0) + 1
        lines = [f"{n} runs in {self.elapsed_s:.1f} s on {self.workers} worker(s): {conv} converged "
                 f"({100 * conv / n:.0f} %), {agree} reached the consensus within {100 * self.agree_rtol:g} %"
                 + (f" (step {step})" if step else "") + (f", {errs} failed" if errs else "")]
        for key in self.varied():
            if key == "seed":
                continue
            lines.append(f"by {key}: " + ", ".join(f"{v:g}: {a}/{m}" if isinstance(v, (int, float)) else f"{v}: {a}/{m}"
                                                    for v, m, c, a in self.rates_by(key, step)))
        rows = self.spread(step)
        known = any(math.isfinite(s["truth"]) for s in rows)  # a real record has no truth: no columns of NaN
        lines.append(f"{'parameter':<10}" + (f"{'truth':>12}" if known else "") + f"{'consensus':>12}{'spread':>11}"
                     f"{'mean σ':>11}{'spread/σ':>9}" + (f"{'rms z':>7}" if known else ""))
        for s in rows:
            lines.append(f"{s['name']:<10}" + (f"{s['truth']:>12.5g}" if known else "") + f"{s['consensus']:>12.5g}"
                         f"{s['spread']:>11.3g}{s['sigma']:>11.3g}{s['ratio']:>9.2f}"
                         + (f"{s['z_rms']:>7.2f}" if known else ""))
        if rows:
            lines.append("  (over the runs that reached the consensus: spread = sample std of the estimates, mean σ = "
                         "their mean predicted σ, spread/σ near 1 or below: σ is honest"
                         + ("; rms z = RMS of (estimate − truth)/σ, near 1 when unbiased, large when the model "
                            "cannot hold the truth (e.g. a rigid model of a flexible axis)" if known else "") + ")")
        for why, count in sorted(reasons.items(), key=lambda kv: -kv[1])[:3]:
            lines.append(f"failed ({count} run{'s' if count > 1 else ''}): {why}")
        return "\n".join(lines)

    def to_dict(self) -> Dict[str, Any]:
        def clean(x):
            if isinstance(x, float) and not math.isfinite(x):
                return None
            if isinstance(x, dict):
                return {k: clean(v) for k, v in x.items()}
            if isinstance(x, (list, tuple)):
                return [clean(v) for v in x]
            if isinstance(x, np.generic):
                return clean(x.item())
            return x

        return clean(dict(elapsed_s=self.elapsed_s, workers=self.workers, agree_rtol=self.agree_rtol,
                          convergence_rate=self.convergence_rate(), varied=self.varied(), meta=self.meta,
                          spread=self.spread(), results=self.results))

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=1)

    def plot(self, step: Optional[str] = None, params: Optional[Sequence[str]] = None):
        """Convergence map (one or two varied keys) and the estimates relative to the consensus against the first
        varied key; non-converged runs in red."""
        import matplotlib.pyplot as plt

        keys = [k for k in self.varied() if k != "seed"] or self.varied()
        names = list(params or self.params(step))
        fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
        conv = np.array(self.converged(step))
        agree = np.array(self.agrees(step))
        color = np.where(agree, "tab:green", np.where(conv, "tab:orange", "tab:red"))
        ax = axes[0]
        if len(keys) >= 2:
            x = np.array([float(p[keys[0]]) for p in self.points])
            y = np.array([float(p[keys[1]]) for p in self.points])
            jitter = np.array([p.get("seed", 0) for p in self.points], dtype=float)
            jitter = 0.0 if np.ptp(jitter) == 0 else (jitter - jitter.mean()) / (np.ptp(jitter) + 1e-12)
            dx = 0.15 * np.min(np.diff(np.unique(x))) if len(np.unique(x)) > 1 else 0.0
            ax.scatter(x + jitter * dx, y, c=color, s=40, edgecolors="k", linewidths=0.3)
            ax.set_xlabel(keys[0])
            ax.set_ylabel(keys[1])
            ax.set_title("green: consensus, orange: converged elsewhere, red: not converged", fontsize=9)
        elif keys:
            rows = self.rates_by(keys[0], step)
            xs = [float(v) for v, *_ in rows]
            ax.plot(xs, [100 * c / m for _, m, c, _ in rows], "o-", label="converged")
            ax.plot(xs, [100 * a / m for _, m, _, a in rows], "s--", label="reached the consensus")
            ax.set_xlabel(keys[0])
            ax.set_ylabel("% of runs")
            ax.set_ylim(-5, 105)
            ax.legend()
            if min(xs) > 0 and max(xs) / min(xs) > 20:
                ax.set_xscale("log")
        ax.grid(True, alpha=0.3)
        ax = axes[1]
        cons = self.consensus(step)
        if keys:
            x = np.array([float(p[keys[0]]) for p in self.points])
            for n in names:
                vals = np.array([(self._src(r, step) or {}).get("params", {}).get(n, np.nan) for r in self.results],
                                dtype=float)
                c = cons.get(n, np.nan)
                rel = (vals / c - 1) * 100 if c else vals
                ax.plot(x[conv], rel[conv], "o", ms=4, label=n)
                if (~conv).any():
                    ax.plot(x[~conv], rel[~conv], "x", color="tab:red", ms=5)
            ax.set_xlabel(keys[0])
            if min(x) > 0 and max(x) / min(x) > 20:
                ax.set_xscale("log")
        ax.set_ylabel("estimate / consensus − 1 (%)")
        lim = max((abs(v) for line in ax.get_lines() for v in line.get_ydata() if np.isfinite(v)), default=0.0)
        if lim > 20:
            ax.set_yscale("symlog", linthresh=1.0)
        ax.grid(True, alpha=0.3)
        ax.legend(ncol=3, fontsize=8)
        fig.suptitle(self.meta.get("title", "sweep") + (f", step {step}" if step else "") + f" — {len(self.results)} "
                     f"runs, {100 * self.convergence_rate(step):.0f} % converged", fontsize=10)
        fig.tight_layout()
        return fig


def parse_values(spec: str) -> List[Any]:
    """Values of a command-line grid: ``a,b,c`` or ``start:stop:count`` (linear) or ``start:stop:count:log``."""
    if ":" in spec:
        parts = spec.split(":")
        if len(parts) not in (3, 4) or (len(parts) == 4 and parts[3] not in ("log", "lin")):
            raise DataError(f"range {spec!r} must be start:stop:count[:log]")
        try:
            a, b, n = float(parts[0]), float(parts[1]), int(parts[2])
        except ValueError:
            raise DataError(f"range {spec!r}: start and stop must be numbers and count a whole number "
                            "(start:stop:count[:log])") from None
        if not (math.isfinite(a) and math.isfinite(b)):
            raise DataError(f"range {spec!r}: start and stop must be finite")
        if not 1 <= n <= MAX_POINTS:
            raise DataError(f"range {spec!r}: count must be between 1 and {MAX_POINTS}, got {n}")
        if len(parts) == 4 and parts[3] == "log":
            if a <= 0 or b <= 0:
                raise DataError(f"range {spec!r}: a log range needs start and stop > 0")
            return [float(v) for v in np.geomspace(a, b, n)]
        return [float(v) for v in np.linspace(a, b, n)]
    out: List[Any] = []
    for v in spec.split(","):
        v = v.strip()
        try:
            out.append(int(v))
        except ValueError:
            try:
                out.append(float(v))
            except ValueError:
                out.append(v)
    return out


__all__ = ["sweep", "run_point", "grid_points", "random_points", "SweepResult", "SCENARIOS", "parse_values",
           "step_truth"]
