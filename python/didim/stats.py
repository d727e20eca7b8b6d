"""Statistics that stay valid when residuals are autocorrelated: AR prewhitening, HAC (Newey-West) covariance,
Wald tests of added regressors, Holm's correction for many tests, and the Diebold-Mariano test of two fits."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, Optional, Sequence

import numpy as np


def ar_fit(x: np.ndarray, max_order: int = 8) -> np.ndarray:
    """AR polynomial ``a`` (a[0] = 1) of the residual by Yule-Walker, order chosen by AIC up to ``max_order``."""
    x = np.asarray(x, float) - np.mean(x)
    n = len(x)
    max_order = max(0, min(max_order, n // 4))  # a short residual supports only a low order
    r = np.correlate(x, x, "full")[n - 1 : n + max_order] / n
    best, best_aic = np.array([1.0]), n * math.log(max(r[0], 1e-300))
    lags = np.abs(np.subtract.outer(np.arange(max_order), np.arange(max_order)))
    for p in range(1, max_order + 1):
        try:  # the Yule-Walker equations: a p × p Toeplitz system (p ≤ 8), solved directly
            phi = np.linalg.solve(r[lags[:p, :p]], r[1 : p + 1])
        except np.linalg.LinAlgError:
            break
        s2 = r[0] - phi @ r[1 : p + 1]
        if s2 <= 0:
            break
        aic = n * math.log(s2) + 2 * p
        if aic < best_aic:
            best, best_aic = np.concatenate([[1.0], -phi]), aic
    return best


def prewhiten(a: np.ndarray, *arrays: np.ndarray) -> List[np.ndarray]:
    """Filters each array (along axis 0) by the AR polynomial ``a`` and drops the first len(a) − 1 samples: the FIR
    filter e[t] = Σ a[i] x[t − i] on the samples t ≥ len(a) − 1, whose past is all in the record."""
    a = np.asarray(a, float)
    k = len(a) - 1
    out = []
    for x in arrays:
        x = np.asarray(x, float)
        n = len(x)
        e = a[0] * x[k:]
        for i in range(1, k + 1):
            e = e + a[i] * x[k - i:n - i]
        out.append(e)
    return out


def newey_west_lag(n: int) -> int:
    return int(math.floor(4 * (n / 100.0) ** (2.0 / 9.0)))


@dataclass
class WaldTest:
    """Test that added regressors explain part of a residual."""

    beta: np.ndarray
    cov: np.ndarray
    statistic: float
    dof: int
    p_value: float
    explained: float  # fraction of the (prewhitened) residual's sum of squares explained


def wald_added(r: np.ndarray, x: np.ndarray, a: Optional[np.ndarray] = None) -> WaldTest:
    """Regresses the residual ``r`` on the (already orthogonalized) columns ``x`` after prewhitening both with the AR
    polynomial ``a`` (fitted on ``r`` when None); Wald test with an F reference distribution."""
    x = np.asarray(x, float)
    if x.ndim == 1:
        x = x[:, None]
    if a is None:
        a = ar_fit(r)
    rw, xw = prewhiten(a, r, x)
    return wald_whitened(rw, xw)


def wald_whitened(rw: np.ndarray, xw: np.ndarray) -> WaldTest:
    """:func:`wald_added` on a residual and columns already prewhitened alike (prewhitening is linear and per column,
    so the columns of many tests can be prewhitened in one call and tested one group at a time)."""
    scale = np.linalg.norm(xw, axis=0)
    keep = scale > 1e-12 * max(float(np.max(scale)) if scale.size else 0.0, 1e-300)
    if not np.any(keep):
        return WaldTest(np.zeros(xw.shape[1]), np.zeros((xw.shape[1],) * 2), 0.0, xw.shape[1], 1.0, 0.0)
    xs = xw[:, keep] / scale[keep]
    beta_s, *_ = np.linalg.lstsq(xs, rw, rcond=None)
    e = rw - xs @ beta_s
    k = int(keep.sum())
    n = len(rw)
    # After prewhitening the errors are close to white: the classical covariance σ²(XᵀX)⁻¹ with an F reference
    # distribution keeps its size (a Newey-West covariance over-rejects with persistent regressors such as
    # indicators of time or velocity bins: 5 % rejections at the 1 % level on white noise).
    s2 = float(e @ e) / max(n - k, 1)
    cov_s = s2 * np.linalg.pinv(xs.T @ xs)
    try:
        stat = float(beta_s @ np.linalg.solve(cov_s, beta_s))
    except np.linalg.LinAlgError:
        stat = float(beta_s @ np.linalg.pinv(cov_s) @ beta_s)
    beta = np.zeros(xw.shape[1])
    beta[keep] = beta_s / scale[keep]
    cov = np.zeros((xw.shape[1], xw.shape[1]))
    cov[np.ix_(keep, keep)] = cov_s / np.outer(scale[keep], scale[keep])
    explained = 1.0 - float(e @ e) / float(rw @ rw) if rw @ rw > 0 else 0.0
    from scipy.special import fdtrc  # the F distribution's survival function (scipy.stats' own), without its import

    return WaldTest(beta, cov, stat, k, float(fdtrc(k, max(n - k, 1), stat / k)), explained)


#: :func:`wald_groups` tests groups of up to this many columns together by their normal equations.
GROUPED_MAX = 4
#: ... when every column of the group is kept and its normal matrix (unit diagonal) is this far from singular: its
#: smallest eigenvalue at least this (a condition number below 10⁸; beyond, :func:`wald_whitened`'s pseudo-inverse).
GROUPED_MIN_EIGENVALUE = 1e-8


def wald_groups(rw: np.ndarray, xw: np.ndarray, sizes: Sequence[int]) -> List[WaldTest]:
    """:func:`wald_whitened` of each group of consecutive columns of ``xw`` (``sizes`` columns each, in order): a grid
    of one effect's variants (80 periods of a sine and a cosine) is tested in a few array operations instead of one
    least-squares solve per variant. A group of at most :data:`GROUPED_MAX` columns, all kept and well conditioned,
    is solved by its normal equations on columns scaled to unit norm (XᵀX has a unit diagonal: its condition is that
    of the columns' correlations); the same statistic, coefficients and covariance as :func:`wald_whitened`'s SVD
    solve to within the rounding that condition allows. Any other group goes through :func:`wald_whitened`."""
    from scipy.special import fdtrc

    sizes = [int(k) for k in sizes]
    ends = np.cumsum(sizes, dtype=int)
    starts = ends - np.asarray(sizes, dtype=int)
    if len(sizes) and ends[-1] != xw.shape[1]:
        raise ValueError(f"wald_groups: groups of {int(ends[-1])} columns for {xw.shape[1]} columns")
    out: List[Optional[WaldTest]] = [None] * len(sizes)
    scale = np.linalg.norm(xw, axis=0)
    n = len(rw)
    rr = float(rw @ rw)
    by_size: dict = {}
    for g, (s, k) in enumerate(zip(starts, sizes)):
        sc = scale[s:s + k]
        if 0 < k <= GROUPED_MAX and np.all(sc > 1e-12 * max(float(np.max(sc)), 1e-300)):
            by_size.setdefault(k, []).append(g)
    for k, groups in by_size.items():
        idx = (starts[groups][:, None] + np.arange(k)).ravel()
        x = (xw[:, idx] / scale[idx]).reshape(n, len(groups), k)
        gram = np.einsum("nmi,nmj->mij", x, x)
        b = rw @ x.reshape(n, -1)
        b = b.reshape(len(groups), k)
        ok = np.linalg.eigvalsh(gram)[:, 0] >= GROUPED_MIN_EIGENVALUE
        if not np.any(ok):
            continue
        inv = np.linalg.inv(gram[ok])
        beta_s = np.einsum("mij,mj->mi", inv, b[ok])
        fit = np.einsum("mi,mi->m", beta_s, b[ok])  # β'Xᵀr = β'XᵀXβ: the explained sum of squares
        ee = np.maximum(rr - fit, 0.0)
        s2 = ee / max(n - k, 1)
        stat = fit / np.where(s2 > 0, s2, 1.0)
        p = fdtrc(k, max(n - k, 1), stat / k)
        for i, g in enumerate(np.asarray(groups)[ok]):
            if not s2[i] > 0:  # an exact fit: wald_whitened's pseudo-inverse of a zero covariance
                continue
            sc = scale[starts[g]:starts[g] + k]
            out[g] = WaldTest(beta_s[i] / sc, s2[i] * inv[i] / np.outer(sc, sc), float(stat[i]), k, float(p[i]),
                              1.0 - float(ee[i]) / rr if rr > 0 else 0.0)
    for g, (s, k) in enumerate(zip(starts, sizes)):
        if out[g] is None:
            out[g] = wald_whitened(rw, xw[:, s:s + k])
    return out  # type: ignore[return-value]


def holm(p_values: Sequence[float]) -> np.ndarray:
    """Holm-Bonferroni adjusted p-values (family-wise error control for many candidates)."""
    p = np.asarray(p_values, float)
    m = len(p)
    order = np.argsort(p)
    adj = np.empty(m)
    running = 0.0
    for i, idx in enumerate(order):
        running = max(running, min(1.0, (m - i) * p[idx]))
        adj[idx] = running
    return adj


def diebold_mariano(e_before: np.ndarray, e_after: np.ndarray, loss: str = "squared") -> tuple:
    """One-sided test that the squared (``loss="absolute"``: absolute) errors ``e_after`` are smaller than
    ``e_before`` on the same samples (HAC variance of the loss differential). Returns (statistic, p-value, mean
    relative improvement of the squared errors)."""
    if loss not in ("squared", "absolute"):
        raise ValueError(f"loss must be 'squared' or 'absolute', got {loss!r}")
    power = 2 if loss == "squared" else 1
    d = np.abs(np.asarray(e_before, float)) ** power - np.abs(np.asarray(e_after, float)) ** power
    n = len(d)
    lag = newey_west_lag(n)
    dc = d - d.mean()
    s = dc @ dc / n
    for l in range(1, lag + 1):
        s += 2 * (1 - l / (lag + 1)) * (dc[l:] @ dc[:-l]) / n
    if s <= 0:
        return 0.0, 1.0, 0.0
    stat = d.mean() / math.sqrt(s / n)
    from scipy.special import ndtr  # the normal distribution's survival function is ndtr(−x), as in scipy.stats

    gain = np.mean(np.asarray(e_before, float) ** 2 - np.asarray(e_after, float) ** 2)
    return float(stat), float(ndtr(-stat)), float(gain / np.mean(np.asarray(e_before, float) ** 2))


def orthogonalize(x: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The part of the columns of ``x`` orthogonal to the columns of ``w`` (least-squares projection)."""
    if w.size == 0:
        return x
    q, _ = np.linalg.qr(w)
    return x - q @ (q.T @ x)


__all__ = ["ar_fit", "prewhiten", "wald_added", "wald_whitened", "wald_groups", "WaldTest", "holm", "diebold_mariano", "orthogonalize"]
