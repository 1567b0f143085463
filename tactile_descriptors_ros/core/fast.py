"""Fast, exact paths for the per-cell quantities (paper eq. 1-5), numpy only.

The straightforward way to get the correlations of eq. 4-5 expands the slow
deformation signal V onto the fast vibration time base (zero-order hold,
:mod:`.alignment`), broadcasts every S channel against every V channel
(``n_s x n_v x n`` copies) and ranks the expanded series by sorting.  On a
NAO window (116 cells, 2 s) that costs tens to hundreds of milliseconds, and
ranking is most of it.  This module computes the *same*
numbers without any of that:

* **Held V is piecewise constant.**  Fast samples ``i`` holding slow sample
  ``k`` form one contiguous run (time stamps are sorted), of length ``w_k``.
  Every sum over the expanded series is a sum over runs:
  ``sum_i V(i) = sum_k w_k V_k``, ``sum_i V(i)^2 = sum_k w_k V_k^2`` and
  ``sum_i S_i V(i) = sum_k V_k (sum_{i in run k} S_i)``, the inner sums taken
  with one :func:`numpy.add.reduceat` over the fast signal.  The cross sums
  of all channel pairs are then one small matrix product per cell.
* **Ranks of held V are weighted ranks** of the slow samples, with the run
  lengths as weights (a value held for 4 fast samples is 4 tied samples).
* **Integer sensor data are ranked by counting** (one ``bincount`` over all
  signals, no sort), and twice the centred average rank,
  ``2 r - (n + 1) = 2 below + count - n``, is an *integer*, so Spearman's
  sums are exact.
* **Integer data give exact moments.**  For ADC counts, ``n sum x^2 -
  (sum x)^2`` and the cross terms are computed exactly (float64 sums of
  integers below 2**53, combined in int64), so there is no cancellation
  however large the offset.  The Hjorth variances of the first and second
  differences (eq. 2-3) follow exactly from ``sum x``, ``sum x^2`` and the
  lag-1 and lag-2 products ``sum x_i x_{i+1}``, ``sum x_i x_{i+2}``: no
  difference arrays are formed.

Float data (SI units) take the same run-sum route with a centred two-pass
mean and sort-based ranks.  Every function here returns what the reference
functions in :mod:`.descriptors` return on the expanded series -- values
(to rounding) and :class:`~.descriptors.Quality` flags -- which the tests
check with property-based tests (ties, flat channels, NaN, short windows,
cells with their own time bases).  Edge cases the fast route does not cover
(fewer than 3 paired samples, no V sample) are delegated to the reference.

Integer data are computed by a compiled kernel when numba is installed
(:mod:`._numba_kernel`: the same exact sums in one pass per cell, the same
floating-point operations after them, so bit-identical results; loaded on
first use, see :func:`accelerator`, :func:`set_accelerator`,
:func:`warm_up`; ``TACTILE_NO_NUMBA=1`` disables it).  This module stays
the reference and computes everything the compiled kernel hands back.

Large scratch arrays live in a per-thread workspace reused between calls:
on these machines a fresh multi-megabyte array costs more in page faults
than the arithmetic done on it.  :func:`release_buffers` frees it.
"""

from __future__ import annotations

import os
import threading
import time
from typing import NamedTuple

import numpy as np
from scipy import stats

from ..errors import SignalError
from .alignment import hold_indices
from .descriptors import FLAT_RELATIVE_TOLERANCE, Hjorth, Quality, hjorth, pearson, spearman

__all__ = [
    "HoldRuns",
    "hold_runs",
    "hjorth_fast",
    "held_correlations",
    "held_correlations_reference",
    "cell_quantities",
    "cell_quantities_reference",
    "exact_integer_ok",
    "release_buffers",
    "accelerator",
    "cell_bounds",
    "set_accelerator",
    "warm_up",
    "CHUNK_SAMPLES",
    "MAX_SEGMENTS",
]

#: Cells are processed in chunks of about this many fast samples (all S
#: channels of all cells of a chunk); it bounds the scratch memory (about
#: 30 bytes per sample) and keeps a chunk's passes within the caches.
CHUNK_SAMPLES: int = 1 << 20

#: Hold runs are summed stretch by stretch while there are fewer than this
#: many stretches of equal run length (regular sampling gives 1 to 3), else
#: with :func:`numpy.add.reduceat`.
MAX_SEGMENTS: int = 16

_F64_EXACT = float(2**53)
_I64_SAFE = float(2**62)
_F32_EXACT = 2**24
_FLAT2 = FLAT_RELATIVE_TOLERANCE**2
_U_FLAT = np.uint32(Quality.FLAT)
_U_NONFINITE = np.uint32(Quality.NONFINITE)


# ---------------------------------------------------------------- workspace
class _Workspace(threading.local):
    """Scratch arrays reused between calls, one set per thread."""

    def __init__(self) -> None:
        self.buffers: dict[tuple[str, str], np.ndarray] = {}

    def get(self, slot: str, shape: tuple[int, ...], dtype) -> np.ndarray:
        dtype = np.dtype(dtype)
        size = 1
        for d in shape:
            size *= int(d)
        key = (slot, dtype.str)
        buf = self.buffers.get(key)
        if buf is None or buf.size < size:
            buf = np.empty(max(size, 1), dtype=dtype)
            self.buffers[key] = buf
        return buf[:size].reshape(shape)


_WS = _Workspace()

#: Rows of a counting-rank table handled at once: small tables stay in the L2
#: cache and their scratch arrays below the allocator's mmap threshold.
_BLOCK_BINS = 1 << 14


def _rowdot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``sum(a * b, axis=-1)`` without a temporary (BLAS dot per row where available)."""
    vecdot = getattr(np, "vecdot", None)  # numpy >= 2.0
    if vecdot is not None:
        return vecdot(a, b)
    return np.einsum("...i,...i->...", a, b)


def _ws_cast(slot: str, x: np.ndarray, dtype) -> np.ndarray:
    """``x`` as ``dtype`` in a workspace array (``x`` itself if already so)."""
    if x.dtype == dtype:
        return x
    out = _WS.get(slot, x.shape, dtype)
    np.copyto(out, x, casting="unsafe")
    return out


def release_buffers() -> int:
    """Free this thread's scratch arrays; return the bytes released."""
    total = sum(b.nbytes for b in _WS.buffers.values())
    _WS.buffers.clear()
    return total


# ---------------------------------------------------------------- hold runs
class HoldRuns(NamedTuple):
    """The zero-order hold of a slow time base on a fast one, as runs.

    Attributes
    ----------
    first : int
        Index of the first fast sample that has a slow sample to pair with;
        fast samples ``first:`` are paired (a suffix, since stamps are sorted).
    starts : numpy.ndarray of intp, shape (n_runs,)
        Start of each run, relative to ``first``.
    slow_index : numpy.ndarray of intp, shape (n_runs,)
        Slow sample held during each run.
    weights : numpy.ndarray of int64, shape (n_runs,)
        Run lengths (fast samples per held slow sample); they sum to
        ``n_paired``.
    n_paired : int
        Number of paired fast samples.
    segments : tuple of (int, int, int) or None
        Maximal stretches of consecutive runs of equal length, as
        ``(first_run, end_run, length)``; None when there are
        :data:`MAX_SEGMENTS` or more (irregular stamps).
    """

    first: int
    starts: np.ndarray
    slow_index: np.ndarray
    weights: np.ndarray
    n_paired: int
    segments: tuple[tuple[int, int, int], ...] | None = None


def hold_runs(t_slow_ns: np.ndarray, t_fast_ns: np.ndarray) -> HoldRuns:
    """Runs of fast samples that hold the same slow sample (zero-order hold).

    Parameters
    ----------
    t_slow_ns, t_fast_ns : array_like of int64, shape (n_slow,), (n_fast,)
        Non-decreasing time stamps.

    Returns
    -------
    HoldRuns
        Equivalent to :func:`~.alignment.hold_indices`: fast sample
        ``first + starts[k] + j`` (``0 <= j < weights[k]``) holds slow sample
        ``slow_index[k]``.
    """
    idx = hold_indices(t_slow_ns, t_fast_ns)
    first = int(np.searchsorted(idx, 0, side="left"))
    held = idx[first:]
    n = held.shape[0]
    if n == 0:
        empty = np.zeros(0, dtype=np.intp)
        return HoldRuns(first, empty, empty, np.zeros(0, dtype=np.int64), 0, ())
    change = np.flatnonzero(held[1:] != held[:-1]) + 1
    starts = np.concatenate(([0], change)).astype(np.intp)
    weights = np.diff(np.concatenate((starts, [n]))).astype(np.int64)
    bounds = np.flatnonzero(weights[1:] != weights[:-1]) + 1
    segments = None
    if bounds.size < MAX_SEGMENTS:
        edges = [0, *bounds.tolist(), weights.size]
        segments = tuple((a, b, int(weights[a])) for a, b in zip(edges[:-1], edges[1:]))
    return HoldRuns(first, starts, held[starts].astype(np.intp), weights, n, segments)


def _run_sums(x: np.ndarray, runs: HoldRuns, slot: str, dtype=None) -> np.ndarray:
    """Sum of each row of ``x`` (rows, n_paired) over every run: (rows, n_runs).

    Stretches of equal-length runs are summed with strided slices (or one
    matrix-vector product for long runs), several times faster than
    :func:`numpy.add.reduceat` with many short segments.  Sums are taken in
    ``dtype`` (default ``x.dtype``; the caller makes sure they are exact).
    The result is a workspace array (valid until the next call with the
    same ``slot``).
    """
    dtype = x.dtype if dtype is None else np.dtype(dtype)
    if runs.segments is None:
        return np.add.reduceat(x, runs.starts, axis=-1, dtype=dtype)
    rows = x.shape[0]
    out = _WS.get(slot, (rows, runs.starts.size), dtype)
    for k0, k1, length in runs.segments:
        x0 = int(runs.starts[k0])
        block = x[:, x0:x0 + (k1 - k0) * length]
        o = out[:, k0:k1]
        if length == 1:
            np.copyto(o, block, casting="unsafe")
        elif length <= 8 or not np.issubdtype(dtype, np.floating):
            np.add(block[:, 0::length], block[:, 1::length], out=o)
            for j in range(2, length):
                o += block[:, j::length]
        else:
            np.matmul(block.reshape(rows, k1 - k0, length), np.ones(length, dtype=dtype), out=o)
    return out


# ------------------------------------------------------------ exact integers
def _is_int(x: np.ndarray) -> bool:
    return bool(np.issubdtype(x.dtype, np.integer) or x.dtype == bool)


def _no_bool(x: np.ndarray) -> np.ndarray:
    return x.astype(np.uint8) if x.dtype == bool else x


def _peak(x: np.ndarray) -> float:
    """Largest magnitude of an integer array (0 when empty)."""
    if x.size == 0:
        return 0.0
    return float(max(abs(int(x.min())), abs(int(x.max()))))


def exact_integer_ok(n: int, *peaks: float) -> bool:
    """Whether integer data of ``n`` samples and these peaks have exact moments.

    Sums of products of two signals (or of a signal's second difference, up
    to 4 peaks) must stay below 2**53 to be exact in float64, and ``n`` times
    them below 2**62 to combine exactly in int64.

    Examples
    --------
    >>> exact_integer_ok(2000, 4095)       # 2 s of 12-bit force at 1 kHz
    True
    >>> exact_integer_ok(2000, 2.0**40)
    False
    """
    p = 4.0 * max(max(peaks, default=0.0), 1.0)
    return n * p * p < _F64_EXACT and float(n) * n * p * p < _I64_SAFE


def _as_i64(x: np.ndarray) -> np.ndarray:
    """Float64 exact integers to int64 (exact under :func:`exact_integer_ok`)."""
    return np.rint(x).astype(np.int64)


class _Prepared(NamedTuple):
    """Rows of one modality as float64 (rows = cells x channels)."""

    xf: np.ndarray  # (rows, n) float64 (a workspace array for integer input)
    exact: bool  # integer data within the exact bounds
    peak: float
    s1: np.ndarray | None  # row sums (exact path only)
    q: np.ndarray | None  # row sums of squares (exact path only)


def _prepare(rows: np.ndarray, slot: str) -> _Prepared:
    n = rows.shape[-1]
    if _is_int(rows) and n:
        peak = _peak(rows)
        xf = _ws_cast(slot, rows, np.float64)
        if exact_integer_ok(n, peak):
            return _Prepared(xf, True, peak, xf @ np.ones(n), _rowdot(xf, xf))
        return _Prepared(xf, False, peak, None, None)
    return _Prepared(np.asarray(rows, dtype=np.float64), False, 0.0, None, None)


def _hjorth_from_moments(prep: _Prepared, fs: float) -> Hjorth:
    """Exact Hjorth parameters of integer rows from sums and lag products (eq. 1-3).

    ``prep.xf`` holds exact integers, shape (rows, n), n >= 3.
    """
    xf = prep.xf
    n = xf.shape[-1]
    r1 = _as_i64(_rowdot(xf[:, 1:], xf[:, :-1]))
    r2 = _as_i64(_rowdot(xf[:, 2:], xf[:, :-2]))
    s1, q = _as_i64(prep.s1), _as_i64(prep.q)
    x0, x1, xm, xl = (_as_i64(xf[:, j]) for j in (0, 1, n - 2, n - 1))
    return _hjorth_from_ints(n, s1, q, r1, r2, x0, x1, xm, xl, fs)


def _hjorth_from_ints(n: int, s1: np.ndarray, q: np.ndarray, r1: np.ndarray, r2: np.ndarray, x0: np.ndarray,
                      x1: np.ndarray, xm: np.ndarray, xl: np.ndarray, fs: float) -> Hjorth:
    """Hjorth parameters from exact int64 row moments (sum, sum of squares, lag-1 and
    lag-2 products, samples 0, 1, n-2, n-1).  The compiled kernel's ``_hjorth_row`` makes
    the same floating-point operations in the same order."""
    # n^2 var(x)
    num_x = n * q - s1 * s1
    # first difference d_i = x_{i+1} - x_i, i < n-1: (n-1)^2 var(d)
    sd = xl - x0
    sd2 = 2 * q - x0 * x0 - xl * xl - 2 * r1
    num_d = (n - 1) * sd2 - sd * sd
    # second difference dd_i = x_{i+2} - 2 x_{i+1} + x_i, i < n-2: (n-2)^2 var(dd)
    sdd = (xl - xm) - (x1 - x0)
    sdd2 = ((q - x0 * x0 - x1 * x1) + 4 * (q - x0 * x0 - xl * xl) + (q - xm * xm - xl * xl)
            - 4 * (r1 - x0 * x1) - 4 * (r1 - xm * xl) + 2 * r2)
    num_dd = (n - 2) * sdd2 - sdd * sdd
    var_x = num_x / float(n * n)
    var_d = num_d / float((n - 1) * (n - 1))
    var_dd = num_dd / float((n - 2) * (n - 2))
    # For integer data a non-zero variance is at least 1/n^2 (and the signal's
    # peak is below 2**29/n), far above the reference's float64 flatness
    # tolerance: flat means exactly zero here.
    flat = num_x == 0
    flat_d = num_d == 0
    mob_x = np.zeros(var_x.shape)
    np.divide(var_d, var_x, out=mob_x, where=~flat)
    np.sqrt(mob_x, out=mob_x)
    mob_d = np.zeros(var_x.shape)
    np.divide(var_dd, var_d, out=mob_d, where=~flat_d)
    np.sqrt(mob_d, out=mob_d)
    complexity = np.zeros(var_x.shape)
    np.divide(mob_d, mob_x, out=complexity, where=~(flat | flat_d))
    quality = np.where(flat | flat_d, _U_FLAT, np.uint32(0)).astype(np.uint32)
    return Hjorth(var_x, mob_x * fs, complexity, quality)


def _check_rate(fs_hz: float) -> float:
    fs = float(fs_hz)
    if not np.isfinite(fs) or fs <= 0:
        raise SignalError(f"fs_hz must be a positive finite rate, got {fs_hz!r}")
    return fs


def hjorth_fast(x: np.ndarray, fs_hz: float) -> Hjorth:
    """Hjorth parameters along the last axis, like :func:`~.descriptors.hjorth` (eq. 1-3).

    Integer data (ADC counts) within :func:`exact_integer_ok` bounds take the
    exact moment route (module docstring); everything else is passed to
    :func:`~.descriptors.hjorth`.  Values equal the reference to rounding,
    flags exactly.

    Parameters
    ----------
    x : array_like
        Signals, samples along the last axis.
    fs_hz : float
        Sampling rate (derivative per second, Mobility in rad/s).

    Returns
    -------
    Hjorth
    """
    arr = np.asarray(x)
    if arr.ndim == 0 or arr.shape[-1] < 3 or not _is_int(arr):
        return hjorth(arr, fs_hz)
    prep = _prepare(_no_bool(arr).reshape(-1, arr.shape[-1]), "h.xf")
    if not prep.exact:
        return hjorth(arr, fs_hz)
    h = _hjorth_from_moments(prep, _check_rate(fs_hz))
    return Hjorth(*(a.reshape(arr.shape[:-1]) for a in h))


# ------------------------------------------------------------------- ranks
def _row_span(x: np.ndarray) -> tuple[np.ndarray, int] | None:
    """Row minima and the widest row's value span, or None when counting would
    cost more than sorting (a table much larger than the data)."""
    n_rows = x.shape[0]
    lo = x.min(axis=1)
    span_f = float((x.max(axis=1).astype(np.float64) - lo.astype(np.float64)).max()) + 1.0
    if n_rows * span_f > max(4 * x.size, 1 << 16):
        return None
    return lo, int(span_f)


def _counting_blocks(x: np.ndarray, lo: np.ndarray, span: int, weights: np.ndarray | None, n: int,
                     out: np.ndarray) -> np.ndarray:
    """Twice the centred average ranks of integer rows, by counting, into ``out``.

    Rows are ranked a block at a time: ``bin = value - row_min + row * span``,
    one ``bincount`` (with ``weights`` per sample, if given) counts every
    bin, and the running count gives each bin's rank; ``below`` (samples of
    the row strictly smaller) is the running count minus ``row * n``, so
    ``2 r - (n + 1) = 2 below + count - n = 2 cumsum - count - (2 row + 1) n``.
    Returns the row sums of ``count * rank^2``.
    """
    n_rows, m = x.shape
    block = max(1, min(n_rows, _BLOCK_BINS // span))
    idx_ws = _WS.get("k.idx", (block, m), np.intp)
    ss = np.empty(n_rows)
    for r0 in range(0, n_rows, block):
        r1 = min(n_rows, r0 + block)
        nb = r1 - r0
        idx = idx_ws[:nb]
        offset = np.arange(nb, dtype=np.intp) * span - lo[r0:r1].astype(np.intp)
        np.add(x[r0:r1], offset[:, None], out=idx, casting="unsafe")
        flat = idx.ravel()
        if weights is None:
            counts = np.bincount(flat, minlength=nb * span)
        else:
            counts = _as_i64(np.bincount(flat, weights=weights[r0:r1].ravel(), minlength=nb * span))
        table = np.cumsum(counts)
        table *= 2
        table -= counts
        table.reshape(nb, span)[...] -= (np.arange(1, 2 * nb, 2, dtype=np.int64) * n)[:, None]
        np.take(table.astype(out.dtype), idx, out=out[r0:r1], mode="wrap")
        counts *= table
        counts *= table
        ss[r0:r1] = counts.reshape(nb, span).sum(axis=1)
    return ss


def _centred_ranks(x: np.ndarray, max_run: int) -> tuple[np.ndarray, np.ndarray]:
    """Twice the centred average ranks ``2 r - (n + 1)`` of each row, and their sums of squares.

    Integer rows are ranked by counting (``bincount``, no sort); others with
    :func:`scipy.stats.rankdata`.  The values are exact integers, held in
    float32 when sums of ``max_run`` of them stay exact in float32.  The
    ranks of integer rows are a workspace array.
    """
    n_rows, n = x.shape
    if _is_int(x):
        lo_span = _row_span(x)
        if lo_span is not None:
            dtype = np.float32 if max_run * n < _F32_EXACT else np.float64
            ranks = _WS.get("r.ranks", x.shape, dtype)
            ss = _counting_blocks(x, lo_span[0], lo_span[1], None, n, ranks)
            return ranks, ss
    ranks = stats.rankdata(x, method="average", axis=-1)
    ranks *= 2.0
    ranks -= n + 1
    return ranks, np.einsum("ij,ij->i", ranks, ranks)


def _weighted_centred_ranks(x: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Twice the centred average ranks of rows ``x`` whose samples count ``w`` times.

    Equals :func:`_centred_ranks` of each row with sample ``k`` repeated
    ``w[k]`` times, read at the samples.  Returns the ranks (float64) and
    their weighted row sums of squares.
    """
    n_rows, m = x.shape
    n = int(w.sum())
    wf = w.astype(np.float64)
    if _is_int(x):
        lo_span = _row_span(x)
        if lo_span is not None:
            wt = _WS.get("w.wt", x.shape, np.float64)
            wt[...] = wf
            ranks = _WS.get("w.ranks", x.shape, np.float64)
            _counting_blocks(x, lo_span[0], lo_span[1], wt, n, ranks)
            return ranks, _weighted_squares(ranks, wf)
    order = np.argsort(x, axis=-1, kind="stable")
    xs = np.take_along_axis(x, order, axis=-1)
    ws = wf[order]
    cw = np.cumsum(ws, axis=-1)
    pos = np.arange(m)
    new = np.ones(x.shape, dtype=bool)
    new[:, 1:] = xs[:, 1:] != xs[:, :-1]
    start = np.maximum.accumulate(np.where(new, pos, 0), axis=-1)
    last = np.ones(x.shape, dtype=bool)
    last[:, :-1] = new[:, 1:]
    end = np.minimum.accumulate(np.where(last, pos, m - 1)[:, ::-1], axis=-1)[:, ::-1]
    below = np.take_along_axis(cw - ws, start, axis=-1)
    total = np.take_along_axis(cw, end, axis=-1) - below
    ranks = np.empty(x.shape)
    np.put_along_axis(ranks, order, 2.0 * below + total - n, axis=-1)
    return ranks, _weighted_squares(ranks, wf)


def _weighted_squares(x: np.ndarray, wf: np.ndarray) -> np.ndarray:
    """``sum_k w_k x[:, k]^2`` per row, through a workspace array."""
    sq = _WS.get("sq", x.shape, np.float64)
    np.multiply(x, x, out=sq)
    return sq @ wf


# -------------------------------------------------------------- correlations
def _scaled_flat(ss: np.ndarray, peak: np.ndarray, n: int) -> np.ndarray:
    """The reference's flatness test: the centred sum of squares of the row
    scaled by its power-of-two peak is at most ``n`` tol^2 (:func:`~.descriptors.pearson`)."""
    _, e = np.frexp(np.where(peak > 0, peak, 1.0))
    scale = np.ldexp(1.0, e)
    return ss / (scale * scale) <= n * _FLAT2


def _finite_rows(x: np.ndarray) -> np.ndarray:
    return np.isfinite(x).all(axis=-1) if x.size else np.ones(x.shape[:-1], dtype=bool)


def _ratio(num: np.ndarray, den_a: np.ndarray, den_b: np.ndarray) -> np.ndarray:
    den = den_a * den_b
    out = np.zeros(np.broadcast_shapes(num.shape, den.shape))
    np.divide(num, den, out=out, where=den > 0)
    return out


def _check_pair_shapes(s: np.ndarray, t_s: np.ndarray, v: np.ndarray, t_v: np.ndarray) -> None:
    if s.ndim != 3 or v.ndim != 3 or s.shape[0] != v.shape[0]:
        raise SignalError(f"s and v must be (n_cells, channels, samples) with the same n_cells; "
                          f"got {s.shape} and {v.shape}")
    if np.shape(t_s) != (s.shape[2],) or np.shape(t_v) != (v.shape[2],):
        raise SignalError(f"time stamps do not match samples: {np.shape(t_s)} vs {s.shape}, "
                          f"{np.shape(t_v)} vs {v.shape}")


def held_correlations(s: np.ndarray, t_s_ns: np.ndarray, v: np.ndarray, t_v_ns: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pearson and Spearman correlation of every S channel with every held V channel.

    The cells share one fast and one slow time base.  Equal (to rounding)
    to :func:`held_correlations_reference`, which holds V onto the fast time
    base and calls :func:`~.descriptors.pearson` and
    :func:`~.descriptors.spearman` on the expanded series (eq. 4-5, 9-10).

    Parameters
    ----------
    s : array_like, shape (n_cells, n_s, n_fast)
        Vibration samples S.
    t_s_ns : array_like of int64, shape (n_fast,)
    v : array_like, shape (n_cells, n_v, n_slow)
        Deformation samples V.
    t_v_ns : array_like of int64, shape (n_slow,)

    Returns
    -------
    lin, nonlin : numpy.ndarray, shape (n_cells, n_s, n_v)
        Pearson r and Spearman rho.
    quality : numpy.ndarray of uint32, shape (n_cells,)
        OR of the :class:`~.descriptors.Quality` flags of every pair.
    """
    s = _no_bool(np.asarray(s))
    v = _no_bool(np.asarray(v))
    _check_pair_shapes(s, t_s_ns, v, t_v_ns)
    t_s = np.asarray(t_s_ns, dtype=np.int64)
    t_v = np.asarray(t_v_ns, dtype=np.int64)
    return _held_correlations(s, t_s, v, t_v, hold_runs(t_v, t_s), None)


def held_correlations_reference(s: np.ndarray, t_s_ns: np.ndarray, v: np.ndarray, t_v_ns: np.ndarray
                                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The straightforward computation: expand V by zero-order hold, then correlate.

    Same parameters and returns as :func:`held_correlations`.  Builds the
    ``(n_cells, n_s, n_v, n_paired)`` broadcast pairs and ranks the expanded
    series (the package's implementation before the fast path; kept as the
    reference for tests and ``tactile bench``).
    """
    s = np.asarray(s)
    v = np.asarray(v)
    _check_pair_shapes(s, t_s_ns, v, t_v_ns)
    idx = hold_indices(np.asarray(t_v_ns, dtype=np.int64), np.asarray(t_s_ns, dtype=np.int64))
    paired = idx >= 0
    if v.shape[2] == 0:
        paired[:] = False
    s_p = s[:, :, paired]
    v_p = v[:, :, idx[paired]]
    r, qr = pearson(s_p[:, :, None, :], v_p[:, None, :, :], return_quality=True)
    rho, qn = spearman(s_p[:, :, None, :], v_p[:, None, :, :], return_quality=True)
    quality = np.bitwise_or.reduce((qr | qn).reshape(s.shape[0], -1), axis=1).astype(np.uint32)
    return r, rho, quality


def _pair_cross(a: np.ndarray, b: np.ndarray, n_cells: int) -> np.ndarray:
    """``sum_k a[c, i, k] b[c, j, k]`` for rows (cells x channels, n_runs): (cells, i, j)."""
    a3 = a.reshape(n_cells, -1, a.shape[-1])
    b3 = b.reshape(n_cells, -1, b.shape[-1])
    return _rowdot(a3[:, :, None, :], b3[:, None, :, :])


def _held_correlations(s: np.ndarray, t_s: np.ndarray, v: np.ndarray, t_v: np.ndarray, runs: HoldRuns,
                       s_prep: _Prepared | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fast path of :func:`held_correlations` (``s_prep``: all S samples prepared)."""
    n_cells, n_s, n_fast = s.shape
    n_v = v.shape[1]
    n = runs.n_paired
    if n < 3 or v.shape[2] == 0 or n_cells == 0 or n_s == 0 or n_v == 0:
        # Degenerate windows: the reference sets every flag; it is cheap here.
        return held_correlations_reference(s, t_s, v, t_v)
    first = runs.first
    s_rows = s.reshape(n_cells * n_s, n_fast)[:, first:]
    vk = _WS.get("c.vk", (n_cells, n_v, runs.slow_index.size), v.dtype)
    np.take(v, runs.slow_index, axis=2, out=vk, mode="wrap")
    vk_rows = vk.reshape(n_cells * n_v, -1)  # the held samples, one per run
    w = runs.weights
    wf = w.astype(np.float64)
    shape_s, shape_v = (n_cells, n_s, 1), (n_cells, 1, n_v)

    # ---- Pearson (eq. 4): run sums of S against the held V samples
    prep_s = s_prep if (s_prep is not None and first == 0) else _prepare(s_rows, "c.xf")
    peak_vk = _peak(vk_rows) if _is_int(vk_rows) else np.inf
    bad_s = np.zeros(n_cells * n_s, dtype=bool)
    bad_v = np.zeros(n_cells * n_v, dtype=bool)
    if prep_s.exact and exact_integer_ok(n, peak_vk) and exact_integer_ok(n, prep_s.peak, peak_vk):
        vf = _ws_cast("c.vf", vk_rows, np.float64)
        # run sums in the narrowest exact integer type: less memory traffic than float64
        acc = np.int32 if int(w.max()) * prep_s.peak < 2**31 else np.int64
        run_s = _ws_cast("c.runs64", _run_sums(s_rows, runs, "c.runs", acc), np.float64)
        sv = _as_i64(_pair_cross(run_s, vf, n_cells))
        v1 = _as_i64(vf @ wf)
        v2 = _as_i64(_weighted_squares(vf, wf))
        s1, q = _as_i64(prep_s.s1), _as_i64(prep_s.q)
        num = n * sv - s1.reshape(shape_s) * v1.reshape(shape_v)
        den_s = (n * q - s1 * s1).astype(np.float64)
        den_v = (n * v2 - v1 * v1).astype(np.float64)
        flat_s, flat_v = den_s == 0, den_v == 0
        lin = _ratio(num.astype(np.float64), np.sqrt(den_s).reshape(shape_s), np.sqrt(den_v).reshape(shape_v))
    else:
        xf = np.array(prep_s.xf, dtype=np.float64, copy=True)
        bad_s = ~_finite_rows(xf)
        xf[bad_s] = 0.0
        vf = np.array(vk_rows, dtype=np.float64, copy=True)
        bad_v = ~_finite_rows(vf)
        vf[bad_v] = 0.0
        peak_s = np.max(np.abs(xf), axis=-1)
        peak_v = np.max(np.abs(vf), axis=-1)
        xf -= xf.mean(axis=-1, keepdims=True)
        xf -= xf.mean(axis=-1, keepdims=True)
        vf -= (vf @ wf / n)[:, None]
        vf -= (vf @ wf / n)[:, None]
        ss = np.einsum("ij,ij->i", xf, xf)
        sv2 = _weighted_squares(vf, wf)
        flat_s = _scaled_flat(ss, peak_s, n)
        flat_v = _scaled_flat(sv2, peak_v, n)
        sv = _pair_cross(_run_sums(xf, runs, "c.runs"), vf, n_cells)
        lin = _ratio(sv, np.sqrt(ss).reshape(shape_s), np.sqrt(sv2).reshape(shape_v))
    flat_pair = flat_s.reshape(shape_s) | flat_v.reshape(shape_v)
    bad_pair = bad_s.reshape(shape_s) | bad_v.reshape(shape_v)
    lin[flat_pair | bad_pair] = 0.0
    np.clip(lin, -1.0, 1.0, out=lin)

    # ---- Spearman (eq. 5): Pearson of average ranks; held V ranked with run-length weights
    s_src, v_src = s_rows, vk_rows
    if bad_s.any() or not _is_int(s_rows):
        s_src = np.array(s_rows, dtype=np.float64, copy=True)
        s_src[bad_s] = 0.0
    if bad_v.any() or not _is_int(vk_rows):
        v_src = np.array(vk_rows, dtype=np.float64, copy=True)
        v_src[bad_v] = 0.0
    rs, rss = _centred_ranks(s_src, int(w.max()))
    rv, rvv = _weighted_centred_ranks(v_src, w)
    run_r = _ws_cast("c.rruns64", _run_sums(rs, runs, "c.rruns"), np.float64)
    cross = _pair_cross(run_r, rv, n_cells)
    rflat = (rss == 0).reshape(shape_s) | (rvv == 0).reshape(shape_v)
    nonlin = _ratio(cross, np.sqrt(rss).reshape(shape_s), np.sqrt(rvv).reshape(shape_v))
    nonlin[rflat | bad_pair] = 0.0
    np.clip(nonlin, -1.0, 1.0, out=nonlin)

    quality = np.zeros((n_cells, n_s, n_v), dtype=np.uint32)
    quality[(flat_pair | rflat) & ~bad_pair] |= _U_FLAT
    quality[bad_pair] |= _U_NONFINITE
    return lin, nonlin, np.bitwise_or.reduce(quality.reshape(n_cells, -1), axis=1)


# ------------------------------------------------------------- accelerator
_ACCEL_LOCK = threading.Lock()
_ACCEL: dict = {"resolved": False, "kernel": None, "forced": None, "load_s": None, "error": None}


def _kernel():
    """The compiled kernel module, or None (numpy only)."""
    if _ACCEL["resolved"]:
        return _ACCEL["kernel"]
    with _ACCEL_LOCK:
        if not _ACCEL["resolved"]:
            kernel = None
            if _ACCEL["forced"] != "numpy" and os.environ.get("TACTILE_NO_NUMBA", "") in ("", "0"):
                t0 = time.perf_counter()
                try:
                    from . import _numba_kernel as kernel
                except ImportError as exc:  # numba missing or broken: the numpy kernel serves
                    _ACCEL["error"] = f"{type(exc).__name__}: {exc}"
                    kernel = None
                _ACCEL["load_s"] = time.perf_counter() - t0
            _ACCEL["kernel"] = kernel
            _ACCEL["resolved"] = True
    return _ACCEL["kernel"]


def accelerator() -> str:
    """``"numba"`` when the compiled kernel serves integer data, else ``"numpy"``.

    numba is optional: without it (or with ``TACTILE_NO_NUMBA=1`` in the
    environment, read at first use) the numpy kernel computes everything.
    """
    return "numba" if _kernel() is not None else "numpy"


def set_accelerator(name: str | None) -> str:
    """Force ``"numpy"`` or ``"numba"``, or ``None`` for the default; return the previous choice.

    Raises
    ------
    ImportError
        ``"numba"`` when numba cannot be imported.
    SignalError
        Any other name.
    """
    if name not in (None, "numpy", "numba"):
        raise SignalError(f"accelerator must be 'numpy', 'numba' or None, got {name!r}")
    previous = accelerator()
    with _ACCEL_LOCK:
        _ACCEL["forced"] = name
        _ACCEL["resolved"] = False
        if name == "numba":
            from . import _numba_kernel as kernel

            _ACCEL["kernel"], _ACCEL["resolved"] = kernel, True
    return previous


def warm_up() -> dict:
    """Load (or compile) the accelerator's code now; return what it took.

    The first call of each compiled function in a process loads it from the
    on-disk cache, or compiles it (a few seconds) when the cache is empty or
    stale.  Returns ``{"accelerator", "import_s", "first_call_s", "cache_dir"}``.
    """
    t0 = time.perf_counter()
    kernel = _kernel()
    import_s = time.perf_counter() - t0
    info = {"accelerator": accelerator(), "import_s": import_s, "first_call_s": 0.0, "cache_dir": None,
            "error": _ACCEL["error"]}
    if kernel is None:
        return info
    t1 = time.perf_counter()
    for dtype in (np.int32, np.int64):
        rng = np.random.default_rng(0)
        s = rng.integers(0, 50, (2, 2, 40)).astype(dtype)
        v = rng.integers(0, 50, (2, 3, 10)).astype(dtype)
        t_s = np.arange(40, dtype=np.int64) * 1_000_000
        t_v = np.arange(10, dtype=np.int64) * 4_000_000
        cell_quantities(s, t_s, v, t_v, 1000.0, 250.0)
        cell_bounds(s)
        kernel.central_moments(s.reshape(4, 40), np.empty((4, 5)))  # the statistics feature group
    info["first_call_s"] = time.perf_counter() - t1
    info["cache_dir"] = kernel.CACHE_DIR
    return info


def cell_bounds(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Smallest and largest value of each cell of integer data (n_cells, channels, samples)."""
    kernel = _kernel()
    xc = _compiled_int(x) if kernel is not None and x.ndim == 3 and x.shape[1] * x.shape[2] else None
    if xc is None:
        return x.min(axis=(1, 2)), x.max(axis=(1, 2))
    lo = np.empty(x.shape[0], dtype=np.int64)
    hi = np.empty(x.shape[0], dtype=np.int64)
    kernel.cell_bounds(xc.reshape(x.shape[0], -1), lo, hi)
    return lo, hi


def _compiled_int(x: np.ndarray) -> np.ndarray | None:
    """``x`` as C-contiguous int32 or int64 for the compiled kernel (None for unsigned 64-bit)."""
    if x.dtype == np.int32 or x.dtype == np.int64:
        return np.ascontiguousarray(x)
    if x.dtype.itemsize < 4 or x.dtype == np.uint8:
        return x.astype(np.int32)
    if x.dtype == np.uint32:
        return x.astype(np.int64)
    return None


def _quantities_compiled(kernel, s: np.ndarray, ts: np.ndarray, v: np.ndarray, tv: np.ndarray, fs_s: float,
                         fs_v: float) -> tuple[np.ndarray, ...] | None:
    """:func:`cell_quantities` by the compiled kernel, or None where the numpy kernel must decide.

    Integer data within :func:`exact_integer_ok` bounds (the numpy kernel's
    exact paths) only: every sum is then the same integer in both kernels,
    and the compiled code takes the quantities from them with the numpy
    kernel's floating-point operations in the same order, so the results
    are identical (the tests compare both kernels bit for bit).  Float data,
    huge integers, degenerate windows and unsorted stamps go to numpy.
    """
    if not (_is_int(s) and _is_int(v)) or min(s.shape) == 0 or min(v.shape) == 0 \
            or s.shape[2] < 3 or v.shape[2] < 3:
        return None
    s_c, v_c = _compiled_int(s), _compiled_int(v)
    if s_c is None or v_c is None:
        return None
    ts2 = np.ascontiguousarray(ts[None, :] if ts.ndim == 1 else ts)
    tv2 = np.ascontiguousarray(tv[None, :] if tv.ndim == 1 else tv)
    status, *out = kernel.quantities(s_c, ts2, v_c, tv2, fs_s, fs_v, _U_FLAT,
                                     max(4 * s.shape[2], 1 << 16))
    return tuple(out) if status == kernel.OK else None


# ------------------------------------------------------------- whole batch
def _check_batch(s: np.ndarray, ts: np.ndarray, v: np.ndarray, tv: np.ndarray) -> None:
    if s.ndim != 3 or v.ndim != 3 or s.shape[0] != v.shape[0]:
        raise SignalError(
            f"vibration and deformation must be (n_cells, channels, samples) with the same n_cells; "
            f"got {s.shape} and {v.shape}")
    n_cells = s.shape[0]
    if ts.shape not in ((s.shape[2],), (n_cells, s.shape[2])) or \
            tv.shape not in ((v.shape[2],), (n_cells, v.shape[2])):
        raise SignalError(
            f"time stamps do not match samples: {ts.shape} vs {s.shape}, {tv.shape} vs {v.shape}")


def cell_quantities(s: np.ndarray, t_s_ns: np.ndarray, v: np.ndarray, t_v_ns: np.ndarray,
                    rate_s_hz: float, rate_v_hz: float, *, chunk_samples: int = CHUNK_SAMPLES
                    ) -> tuple[np.ndarray, ...]:
    """Every per-cell quantity of eq. 1-5 for a batch of cells, fast and exact.

    The kernel behind :func:`~.aggregation.cell_features` (same parameters;
    returns the fields of :class:`~.aggregation.CellFeatures` in order:
    ``act_s, mob_s, com_s, act_v, mob_v, com_v, lin, nonlin, quality``).
    Cells with identical time bases are correlated together; cells are
    processed in chunks of about ``chunk_samples`` fast samples.

    Parameters
    ----------
    s : array_like, shape (n_cells, n_s, n_fast)
    t_s_ns : array_like of int64, shape (n_fast,) or (n_cells, n_fast)
    v : array_like, shape (n_cells, n_v, n_slow)
    t_v_ns : array_like of int64, shape (n_slow,) or (n_cells, n_slow)
    rate_s_hz, rate_v_hz : float
    chunk_samples : int
        Work unit (tuning only; results do not depend on it).

    Returns
    -------
    tuple of numpy.ndarray
    """
    s = _no_bool(np.asarray(s))
    v = _no_bool(np.asarray(v))
    ts = np.asarray(t_s_ns, dtype=np.int64)
    tv = np.asarray(t_v_ns, dtype=np.int64)
    _check_batch(s, ts, v, tv)
    fs_s, fs_v = _check_rate(rate_s_hz), _check_rate(rate_v_hz)
    n_cells, n_s, n_fast = s.shape
    n_v = v.shape[1]
    kernel = _kernel()
    if kernel is not None and n_cells:
        res = _quantities_compiled(kernel, s, ts, v, tv, fs_s, fs_v)
        if res is not None:
            return res
    out_shapes = [(n_cells, n_s)] * 3 + [(n_cells, n_v)] * 3 + [(n_cells, n_s, n_v)] * 2
    out = [np.zeros(shape) for shape in out_shapes] + [np.zeros(n_cells, dtype=np.uint32)]
    if n_cells == 0:
        return tuple(out)
    step = max(1, int(chunk_samples) // max(1, n_s * n_fast))
    for cells, t_fast, t_slow in _time_groups(ts, tv, n_cells):
        runs = hold_runs(t_slow, t_fast)
        for lo in range(0, cells.size, step):
            sel = cells[lo:lo + step]
            part = slice(int(sel[0]), int(sel[-1]) + 1) if sel.size == sel[-1] - sel[0] + 1 else sel
            res = _chunk_quantities(s[part], t_fast, v[part], t_slow, runs, fs_s, fs_v)
            for arr, val in zip(out, res):
                arr[part] = val
    return tuple(out)


def _time_groups(ts: np.ndarray, tv: np.ndarray, n_cells: int):
    """Cells sharing both time bases: (cell indices, fast stamps, slow stamps)."""
    if ts.ndim == 1 and tv.ndim == 1:
        yield np.arange(n_cells), ts, tv
        return
    ts2 = np.broadcast_to(ts, (n_cells, ts.shape[-1]))
    tv2 = np.broadcast_to(tv, (n_cells, tv.shape[-1]))
    if bool((ts2 == ts2[0]).all()) and bool((tv2 == tv2[0]).all()):
        yield np.arange(n_cells), ts2[0], tv2[0]
        return
    groups: dict[tuple[bytes, bytes], list[int]] = {}
    for c in range(n_cells):
        groups.setdefault((ts2[c].tobytes(), tv2[c].tobytes()), []).append(c)
    for cells in groups.values():
        yield np.asarray(cells), ts2[cells[0]], tv2[cells[0]]


def _chunk_quantities(s: np.ndarray, t_fast: np.ndarray, v: np.ndarray, t_slow: np.ndarray, runs: HoldRuns,
                      fs_s: float, fs_v: float) -> tuple[np.ndarray, ...]:
    n_cells, n_s, n_fast = s.shape
    prep_s = _prepare(s.reshape(n_cells * n_s, n_fast), "s.xf") if n_fast and n_s else None
    if prep_s is not None and prep_s.exact and n_fast >= 3:
        hs = Hjorth(*(a.reshape(n_cells, n_s) for a in _hjorth_from_moments(prep_s, fs_s)))
    else:
        hs = hjorth(s, fs_s)
    hv = hjorth_fast(v, fs_v)
    lin, nonlin, qc = _held_correlations(s, t_fast, v, t_slow, runs, prep_s)
    quality = np.bitwise_or.reduce(hs.quality, axis=1) | np.bitwise_or.reduce(hv.quality, axis=1)
    return (hs.activity, hs.mobility, hs.complexity, hv.activity, hv.mobility, hv.complexity,
            lin, nonlin, quality | qc)


def cell_quantities_reference(s: np.ndarray, t_s_ns: np.ndarray, v: np.ndarray, t_v_ns: np.ndarray,
                              rate_s_hz: float, rate_v_hz: float) -> tuple[np.ndarray, ...]:
    """The straightforward computation behind :func:`cell_quantities` (same contract).

    :func:`~.descriptors.hjorth` on every channel and
    :func:`held_correlations_reference` (V expanded by zero-order hold,
    ``n_s x n_v`` broadcast pairs, ranks of the expanded series) per group of
    cells sharing time bases.  Kept for tests and ``tactile bench``.
    """
    s = np.asarray(s)
    v = np.asarray(v)
    ts = np.asarray(t_s_ns, dtype=np.int64)
    tv = np.asarray(t_v_ns, dtype=np.int64)
    _check_batch(s, ts, v, tv)
    n_cells = s.shape[0]
    hs = hjorth(s, rate_s_hz)
    hv = hjorth(v, rate_v_hz)
    quality = np.bitwise_or.reduce(hs.quality, axis=1) | np.bitwise_or.reduce(hv.quality, axis=1)
    lin = np.zeros((n_cells, s.shape[1], v.shape[1]))
    nonlin = np.zeros_like(lin)
    if n_cells:
        for cells, t_fast, t_slow in _time_groups(ts, tv, n_cells):
            r, rho, q = held_correlations_reference(s[cells], t_fast, v[cells], t_slow)
            lin[cells], nonlin[cells] = r, rho
            quality[cells] |= q
    return (hs.activity, hs.mobility, hs.complexity, hv.activity, hv.mobility, hv.complexity,
            lin, nonlin, quality)


def main(argv: list[str] | None = None) -> int:
    """Compile (or load) the descriptor kernel now and say where it is cached.

    ``make setup`` runs it, so the nodes find the compiled kernel at their
    first start instead of compiling it for about 30 s.
    """
    import argparse
    import sys

    parser = argparse.ArgumentParser(prog="tactile_descriptors_ros.core.fast.main", description=main.__doc__)
    parser.parse_args(argv)
    print("descriptor kernel: compiling into its cache (about 30 s the first time) ...", file=sys.stderr, flush=True)
    info = warm_up()
    if info["accelerator"] != "numba":
        print(f"descriptor kernel: numpy only ({info['error'] or 'numba disabled'}); nothing to compile",
              file=sys.stderr, flush=True)
        return 0
    print(f"descriptor kernel: ready in {info['import_s'] + info['first_call_s']:.1f} s, cached in "
          f"{info['cache_dir']}", file=sys.stderr, flush=True)
    return 0
