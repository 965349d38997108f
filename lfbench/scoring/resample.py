"""Resampling engines of the bootstrap (:mod:`lfbench.scoring.stats`, and the resampling families of
:mod:`lfbench.scoring.pixelwise`): means of index resamples, the exact law of a resampled order statistic,
cluster draw counts and the quantile of pooled clusters. Pure functions of arrays and a NumPy generator;
the memory of one call stays bounded by resampling in chunks of about ``_CHUNK_ELEMENTS`` elements.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

__all__ = ["chunks", "group_counts", "index_means", "order_stat_replicates", "weighted_quantile_replicates"]

_CHUNK_ELEMENTS = 1 << 22  # elements per resampling chunk (~16 MiB of int32 indices)


def chunks(total: int, row: int) -> Iterator[int]:
    """Chunk sizes (rows) covering ``total`` rows of ``row`` elements each."""
    step = max(1, _CHUNK_ELEMENTS // max(row, 1))
    for start in range(0, total, step):
        yield min(step, total - start)


def index_means(values: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n,) means of i.i.d. resamples (with replacement, same size) of ``values``."""
    size = values.size
    out = [values[rng.integers(0, size, size=(c, size), dtype=np.int64 if size >= 2**31 else np.int32)]
           .mean(axis=1, dtype=np.float64) for c in chunks(n, size)]
    return np.concatenate(out)


def order_stat_replicates(values: np.ndarray, k: int, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n,) draws of the k-th smallest (0-based) value of an i.i.d. resample of ``values``.

    Exact: with sorted values x_(0..N-1), the resampled k-th order statistic has rank <= j when at
    least k+1 of the N draws have rank <= j, i.e. P = P(Binomial(N, (j+1)/N) >= k+1).
    """
    import scipy.stats  # when a quantile is resampled, not when a metric is looked up

    x = np.sort(values)
    size = x.size
    cdf = scipy.stats.binom.sf(k, size, np.arange(1, size + 1) / size)
    cdf[-1] = 1.0
    ranks = np.searchsorted(cdf, rng.random(n), side="left")
    return x[np.minimum(ranks, size - 1)].astype(np.float64)


def group_counts(n_groups: int, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, G) how often each of G groups is drawn in G draws with replacement, per resample."""
    rows = []
    for c in chunks(n, n_groups):
        idx = rng.integers(0, n_groups, size=(c, n_groups)) + n_groups * np.arange(c)[:, None]
        rows.append(np.bincount(idx.ravel(), minlength=c * n_groups).reshape(c, n_groups))
    return np.concatenate(rows).astype(np.float64)


def weighted_quantile_replicates(values: np.ndarray, gid: np.ndarray, counts: np.ndarray,
                                 percentage: float) -> np.ndarray:
    """Per row of ``counts`` (n, G): the metric's quantile of the pooled pixels, each group repeated
    counts[g] times (index int(W * p / 100) of the sorted pooled values, W = pooled size)."""
    order = np.argsort(values, kind="stable")
    x, g = values[order], gid[order]
    n_groups = counts.shape[1]
    sizes = np.bincount(gid, minlength=n_groups).astype(np.float64)
    k = np.floor((counts @ sizes) * percentage / 100.0)  # 0-based index in each pooled resample
    out = np.full(counts.shape[0], np.nan)
    todo = np.arange(counts.shape[0])
    centre = int(x.size * percentage / 100.0)
    half = max(1024, x.size // 64)
    # The answer lies near the full-sample quantile: scan a window of sorted pixels around it, and
    # widen it (up to everything) only for the resamples whose quantile falls outside.
    while todo.size:
        lo, hi = max(0, centre - half), min(x.size, centre + half)
        before = counts[todo] @ np.bincount(g[:lo], minlength=n_groups).astype(np.float64)
        found = np.zeros(todo.size, bool)
        start = 0
        for c in chunks(todo.size, hi - lo):
            rows = todo[start:start + c]
            cum = before[start:start + c, None] + np.cumsum(counts[rows][:, g[lo:hi]], axis=1)
            kk = k[rows][:, None]
            inside = (before[start:start + c] <= k[rows]) & (cum[:, -1] > k[rows])
            pos = lo + (cum <= kk).sum(axis=1)  # first sorted index whose cumulative weight exceeds k
            out[rows[inside]] = x[pos[inside]]
            found[start:start + c] = inside
            start += c
        if lo == 0 and hi == x.size:
            break
        todo = todo[~found]
        half *= 4
    return out
