"""Hjorth parameters and correlations: the per-signal quantities of the descriptor.

Kaboli, Cheng et al., "Robust Tactile Descriptors for Discriminating Objects
From Textural Properties via Artificial Robotic Skin", IEEE T-RO 2018,
section II:

* Activity ``Act(S) = var(S)`` (eq. 1), population variance, mean removed.
* Mobility ``Mob(S) = sqrt(Act(S') / Act(S))`` (eq. 2; the paper prints the
  exponent as -1/2, Hjorth's definition and the text take the square root of
  the ratio, and so do we).  ``S'`` is the derivative *per second*,
  ``diff(S) * fs``, so Mobility is an angular frequency in rad/s and the same
  physical signal gives the same value at any sampling rate.
* Complexity ``Com(S) = Mob(S') / Mob(S)`` (eq. 3), 1 for a pure sine.
* Linear correlation ``L`` (eq. 4, 9): Pearson's r.
* Nonlinear correlation ``N`` (eq. 5, 10): Spearman's rho, computed as
  Pearson's r of average ranks so that ties (quantised 12-bit data tie a lot)
  are handled exactly; eq. 5 is exact only without ties.
* Per cell (:func:`cell_quantities`): all of the above for every vibration
  channel S and deformation channel V of a batch of cells, the slow V held
  onto S's time base (zero-order hold, :mod:`.alignment`) for eq. 4-5.

This module is the readable reference of the descriptor's maths.  The hot
path (:func:`.fast.cell_quantities`, a compiled kernel) computes the same
numbers from exact integer sums; property tests keep the two equal.

Numerics (see ``docs/numerics.md``): inputs are converted to float64, scaled
by their largest magnitude (so amplitudes from 1e-30 to 1e300 neither
underflow nor overflow), centred with a refined two-pass mean, and every
degenerate case returns a documented value with a :class:`Quality` flag
instead of NaN, inf or a warning.
"""

from __future__ import annotations

import enum
from typing import NamedTuple

import numpy as np
from scipy import stats

from ..errors import SignalError
from .alignment import hold_indices

__all__ = [
    "Quality",
    "Hjorth",
    "hjorth",
    "pearson",
    "spearman",
    "average_ranks",
    "held_correlations",
    "cell_quantities",
    "check_cell_batch",
    "FLAT_RELATIVE_TOLERANCE",
    "COUNTING_RANK_MAX_BINS",
]

#: A signal whose standard deviation is at most this fraction of its largest
#: magnitude is treated as flat: that is the level of float64 rounding.
FLAT_RELATIVE_TOLERANCE: float = 64.0 * float(np.finfo(np.float64).eps)

#: Integer data whose value range times row count fits in this many bins is
#: ranked by counting (one ``bincount``) instead of sorting.
COUNTING_RANK_MAX_BINS: int = 1 << 25

_FLOAT_MAX = float(np.finfo(np.float64).max)


class Quality(enum.IntFlag):
    """Quality flags attached to every descriptor value (bit mask).

    The numbers equal the ``QUALITY_*`` constants of
    ``tactile_descriptors_msgs/Descriptor``.
    """

    OK = 0
    #: Too few samples (Hjorth needs 3, a correlation 3): value 0.
    SHORT = 1
    #: The signal (or its derivative) has no variation: Mobility/Complexity or
    #: correlation 0; Activity is still the (tiny) variance.
    FLAT = 2
    #: NaN or inf samples: every value of that signal is 0.
    NONFINITE = 4
    #: Samples at the ADC limits (set by callers who know the ADC range).
    SATURATED = 8
    #: No cell of the body part in contact: values 0.
    NO_CONTACT = 16
    #: Activity exceeded the float64 range and was clipped to its maximum.
    OVERFLOW = 32
    #: Invalid samples (parity errors, lost frames) were excluded.
    INVALID = 64
    #: The window has a gap in time.
    GAP = 128


class Hjorth(NamedTuple):
    """Hjorth parameters of one or many signals (paper eq. 1-3).

    Attributes
    ----------
    activity : numpy.ndarray
        Variance, in the signal's units squared.
    mobility : numpy.ndarray
        Mean angular frequency estimate, rad/s.
    complexity : numpy.ndarray
        Bandwidth estimate, dimensionless (1 for a sine).
    quality : numpy.ndarray of uint32
        :class:`Quality` bit mask per signal.
    """

    activity: np.ndarray
    mobility: np.ndarray
    complexity: np.ndarray
    quality: np.ndarray


def _as_float_last(x: np.ndarray | list, axis: int, name: str) -> np.ndarray:
    """Return ``x`` as a float64 array with ``axis`` moved last (a copy)."""
    arr = np.asarray(x)
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise SignalError(f"{name} must be numeric, got dtype {arr.dtype}")
    if np.issubdtype(arr.dtype, np.complexfloating):
        raise SignalError(f"{name} must be real, got dtype {arr.dtype}")
    if arr.ndim == 0:
        raise SignalError(f"{name} must have at least one dimension (a signal), got a scalar")
    try:
        arr = np.moveaxis(arr, axis, -1)
    except np.exceptions.AxisError as exc:
        raise SignalError(f"{name}: {exc}") from None
    return np.array(arr, dtype=np.float64, copy=True)


def _sanitize(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Zero rows that hold a non-finite sample; return them and the row mask."""
    finite = np.isfinite(x).all(axis=-1)
    if not finite.all():
        x[~finite] = 0.0
    return x, ~finite


def _scale_rows(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Divide each row by its largest magnitude (a power of two, so exactly).

    Returns the scaled rows (in place) and the scale per row (1 for zero rows).
    Scaling by a power of two keeps every sample's mantissa, so results do not
    depend on the amplitude beyond the float64 exponent range.
    """
    if x.shape[-1] == 0:
        return x, np.ones(x.shape[:-1])
    peak = np.max(np.abs(x), axis=-1)
    _, exponent = np.frexp(np.where(peak > 0, peak, 1.0))
    # 2**1024 is not a float64: cap the scale at 2**1023 (rows then span [-2, 2]).
    scale = np.ldexp(1.0, np.minimum(exponent, 1023))
    x /= scale[..., None]
    return x, scale


def _centre(x: np.ndarray) -> np.ndarray:
    """Subtract each row's mean, with one refinement pass (two-pass algorithm)."""
    if x.shape[-1] == 0:
        return x
    x -= x.mean(axis=-1, keepdims=True)
    x -= x.mean(axis=-1, keepdims=True)
    return x


def _variance_of_centred(x: np.ndarray) -> np.ndarray:
    n = x.shape[-1]
    if n == 0:
        return np.zeros(x.shape[:-1])
    return np.einsum("...i,...i->...", x, x) / n


def _safe_ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    """``num / den`` where ``den > 0``, else 0, without warnings."""
    out = np.zeros(np.broadcast_shapes(num.shape, den.shape))
    np.divide(num, den, out=out, where=den > 0)
    return out


def hjorth(x: np.ndarray, fs_hz: float, axis: int = -1) -> Hjorth:
    """Hjorth Activity, Mobility and Complexity (paper eq. 1-3).

    Parameters
    ----------
    x : array_like
        Signal(s), real, any numeric dtype; the samples run along ``axis``
        and every other axis indexes independent signals.
    fs_hz : float
        Sampling rate in Hz.  The derivative is ``diff(x) * fs_hz``, so
        Mobility is in rad/s: a sine of frequency ``f`` gives
        ``2 sin(pi f / fs) fs``, which tends to ``2 pi f`` for ``f << fs``.
    axis : int, default -1
        Axis along which the samples run.

    Returns
    -------
    Hjorth
        ``activity`` (units squared), ``mobility`` (rad/s), ``complexity``
        (dimensionless) and ``quality`` (:class:`Quality` mask), each of the
        shape of ``x`` without ``axis``.

    Notes
    -----
    Degenerate input gives documented values, never NaN, inf or a warning:

    * fewer than 3 samples: Mobility = Complexity = 0, flag ``SHORT``
      (Activity is the variance when there is at least one sample, else 0);
    * a flat signal (std at most :data:`FLAT_RELATIVE_TOLERANCE` of its
      magnitude): Mobility = Complexity = 0, flag ``FLAT``; a signal whose
      derivative is flat (a ramp): Complexity = 0, flag ``FLAT``;
    * any NaN or inf sample: all three 0, flag ``NONFINITE``;
    * Activity beyond the float64 range: the largest float64, flag
      ``OVERFLOW``.

    Examples
    --------
    >>> fs = 1000.0
    >>> t = np.arange(2000) / fs
    >>> h = hjorth(np.sin(2 * np.pi * 10 * t), fs)
    >>> round(float(h.mobility), 3), round(float(h.complexity), 3)
    (62.821, 1.0)
    """
    fs = float(fs_hz)
    if not np.isfinite(fs) or fs <= 0:
        raise SignalError(f"fs_hz must be a positive finite rate, got {fs_hz!r}")
    x = _as_float_last(x, axis, "x")
    shape = x.shape[:-1]
    n = x.shape[-1]
    quality = np.zeros(shape, dtype=np.uint32)
    x, nonfinite = _sanitize(x)
    quality[nonfinite] |= np.uint32(Quality.NONFINITE)
    x, scale = _scale_rows(x)
    x = _centre(x)
    var_x = _variance_of_centred(x)  # of the scaled signal
    activity = _activity_from_scaled(var_x, scale, quality)

    mobility = np.zeros(shape)
    complexity = np.zeros(shape)
    if n < 3:
        quality |= np.uint32(Quality.SHORT)
        activity[nonfinite] = 0.0
        return Hjorth(activity, mobility, complexity, quality)

    flat = var_x <= FLAT_RELATIVE_TOLERANCE**2
    dx = np.diff(x, axis=-1)
    dx = _centre(dx)
    var_dx = _variance_of_centred(dx)
    ddx = _centre(np.diff(dx, axis=-1))
    var_ddx = _variance_of_centred(ddx)
    # Mobility of S and of S' without the fs factor, which cancels in Complexity.
    mob_x = np.sqrt(_safe_ratio(var_dx, np.where(flat, 0.0, var_x)))
    # The derivative is judged flat in the same scaled units as S: rounding
    # noise of diff() on a ramp riding on a large offset is not signal.
    flat_dx = var_dx <= FLAT_RELATIVE_TOLERANCE**2
    mob_x = np.where(flat_dx, 0.0, mob_x)
    mob_dx = np.sqrt(_safe_ratio(var_ddx, np.where(flat_dx, 0.0, var_dx)))
    mobility = np.asarray(mob_x * fs, dtype=np.float64)
    complexity = _safe_ratio(mob_dx, np.where(flat | flat_dx, 0.0, mob_x))
    quality[(flat | flat_dx) & ~nonfinite] |= np.uint32(Quality.FLAT)
    for arr in (activity, mobility, complexity):
        arr[nonfinite] = 0.0
    return Hjorth(activity, mobility, complexity, quality)


def _activity_from_scaled(var_scaled: np.ndarray, scale: np.ndarray, quality: np.ndarray) -> np.ndarray:
    """Undo the power-of-two scaling of a variance, clipping overflow with a flag."""
    # var * scale**2 computed in the log domain of the exponent to avoid inf.
    mant, exp = np.frexp(var_scaled)
    _, sexp = np.frexp(scale)
    total_exp = exp + 2 * (sexp - 1)
    over = (total_exp > 1023) & (var_scaled > 0)  # a zero variance never overflows
    activity = np.asarray(np.ldexp(mant, np.minimum(total_exp, 1023)), dtype=np.float64)
    if over.any():
        activity[over] = _FLOAT_MAX
        quality[over] |= np.uint32(Quality.OVERFLOW)
    return activity


def _prepare_pair(a: np.ndarray, b: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray]:
    a = _as_float_last(a, axis, "a")
    b = _as_float_last(b, axis, "b")
    if a.shape[-1] != b.shape[-1]:
        raise SignalError(
            f"signals must have the same number of samples along axis {axis}: "
            f"{a.shape[-1]} != {b.shape[-1]} (align them first, e.g. with zero_order_hold)"
        )
    try:
        shape = np.broadcast_shapes(a.shape[:-1], b.shape[:-1])
    except ValueError:
        raise SignalError(
            f"leading shapes {a.shape[:-1]} and {b.shape[:-1]} do not broadcast"
        ) from None
    n = a.shape[-1]
    return (np.broadcast_to(a, shape + (n,)).copy(), np.broadcast_to(b, shape + (n,)).copy())


def _checked_pair(a: np.ndarray, b: np.ndarray, axis: int
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Validated float64 rows of a pair, non-finite rows zeroed and flagged ``NONFINITE``."""
    a, b = _prepare_pair(a, b, axis)
    quality = np.zeros(a.shape[:-1], dtype=np.uint32)
    a, bad_a = _sanitize(a)
    b, bad_b = _sanitize(b)
    bad = bad_a | bad_b
    quality[bad] |= np.uint32(Quality.NONFINITE)
    return a, b, quality, bad


def _pearson_rows(a: np.ndarray, b: np.ndarray, quality: np.ndarray) -> np.ndarray:
    """Pearson r of float64 rows of equal shape (rows already finite)."""
    n = a.shape[-1]
    shape = a.shape[:-1]
    if n < 3:
        quality |= np.uint32(Quality.SHORT)
        return np.zeros(shape)
    a, _ = _scale_rows(a)
    b, _ = _scale_rows(b)
    a = _centre(a)
    b = _centre(b)
    saa = np.einsum("...i,...i->...", a, a)
    sbb = np.einsum("...i,...i->...", b, b)
    sab = np.einsum("...i,...i->...", a, b)
    tol = n * FLAT_RELATIVE_TOLERANCE**2
    flat = (saa <= tol) | (sbb <= tol)
    quality[flat] |= np.uint32(Quality.FLAT)
    den = np.sqrt(np.where(flat, 0.0, saa)) * np.sqrt(np.where(flat, 0.0, sbb))
    r = _safe_ratio(sab, den)
    return np.asarray(np.clip(r, -1.0, 1.0), dtype=np.float64)


def pearson(a: np.ndarray, b: np.ndarray, axis: int = -1, *, return_quality: bool = False):
    """Pearson's linear correlation coefficient (paper eq. 4, 9).

    Parameters
    ----------
    a, b : array_like
        Signals with the same number of samples along ``axis``; the other
        axes broadcast against each other.
    axis : int, default -1
        Axis along which the samples run.
    return_quality : bool, default False
        Also return the :class:`Quality` mask.

    Returns
    -------
    r : numpy.ndarray
        Correlation in [-1, 1], of the broadcast shape without ``axis``.
    quality : numpy.ndarray of uint32, optional
        ``SHORT`` (fewer than 3 samples), ``FLAT`` (a constant signal) or
        ``NONFINITE`` (a NaN or inf sample in either signal); r is 0 for each.
    """
    a, b, quality, bad = _checked_pair(a, b, axis)
    r = _pearson_rows(a, b, quality)
    r[bad] = 0.0
    quality[bad] &= ~np.uint32(Quality.FLAT)
    return (r, quality) if return_quality else r


def _is_integral(x: np.ndarray) -> bool:
    return bool(np.issubdtype(x.dtype, np.integer) or x.dtype == bool)


def average_ranks(x: np.ndarray, axis: int = -1) -> np.ndarray:
    """Ranks 1..N along ``axis`` with ties given their average rank.

    Integer data with a small value range (12-bit ADC counts) are ranked by
    counting: one ``bincount`` over all rows, no sort; other data with
    :func:`scipy.stats.rankdata`.  Both give the same numbers.

    Parameters
    ----------
    x : array_like
        Finite data.
    axis : int, default -1
        Axis along which to rank.

    Returns
    -------
    numpy.ndarray of float64
        Average ranks, same shape as ``x``.
    """
    arr = np.asarray(x)
    if _is_integral(arr) and arr.size:
        moved = np.moveaxis(arr, axis, -1)
        rows = moved.reshape(-1, moved.shape[-1])
        if rows.dtype == bool:
            rows = rows.astype(np.int64)
        lo = rows.min(axis=1, keepdims=True)
        # The span in float64 first: int64 data spanning more than 2^63 (or uint64
        # above it) would overflow ``rows - lo``.  Off by at most a few thousand
        # near 2^63, so a small float span means a small exact one.
        span_f = float(np.max(rows.max(axis=1, keepdims=True).astype(np.float64) - lo.astype(np.float64)))
        if rows.shape[0] * (span_f + 1.0) <= COUNTING_RANK_MAX_BINS / 2:
            v = (rows - lo).astype(np.int64)  # exact: the span is small, in rows' own dtype
            span = int(v.max()) + 1
            if rows.shape[0] * span <= COUNTING_RANK_MAX_BINS:
                return np.moveaxis(_counting_ranks(v, span).reshape(moved.shape), -1, axis)
    if arr.size == 0:
        return np.zeros(arr.shape)
    return stats.rankdata(arr, method="average", axis=axis).astype(np.float64)


def _counting_ranks(v: np.ndarray, span: int) -> np.ndarray:
    """Average ranks of non-negative integer rows ``v`` (values < ``span``) by counting."""
    n_rows, n = v.shape
    offset = (np.arange(n_rows, dtype=np.int64) * span)[:, None]
    counts = np.bincount((v + offset).ravel(), minlength=n_rows * span).reshape(n_rows, span)
    below = np.cumsum(counts, axis=1) - counts  # samples strictly smaller
    avg = below + (counts + 1) * 0.5
    return np.take_along_axis(avg, v, axis=1)


def spearman(a: np.ndarray, b: np.ndarray, axis: int = -1, *, return_quality: bool = False):
    """Spearman's rank correlation, ties by average rank (paper eq. 5, 10).

    Computed as Pearson's r of average ranks, which equals eq. 5 when there
    are no ties and stays exact when there are.

    Parameters
    ----------
    a, b : array_like
        Signals with the same number of samples along ``axis``; the other
        axes broadcast.
    axis : int, default -1
        Axis along which the samples run.
    return_quality : bool, default False
        Also return the :class:`Quality` mask.

    Returns
    -------
    rho : numpy.ndarray
        Rank correlation in [-1, 1]; 0 with a flag for the cases listed in
        :func:`pearson`.
    quality : numpy.ndarray of uint32, optional
    """
    a_arr = np.asarray(a)
    b_arr = np.asarray(b)
    a_f, b_f, quality, bad = _checked_pair(a_arr, b_arr, axis)
    n = a_f.shape[-1]
    if n < 3:
        quality |= np.uint32(Quality.SHORT)
        rho = np.zeros(a_f.shape[:-1])
        return (rho, quality) if return_quality else rho
    ra = _ranks_of(a_arr, a_f, axis)
    rb = _ranks_of(b_arr, b_f, axis)
    ra, rb = np.broadcast_arrays(ra, rb)
    rho = _pearson_rows(ra.copy(), rb.copy(), quality)
    rho[bad] = 0.0
    quality[bad] &= ~np.uint32(Quality.FLAT)
    return (rho, quality) if return_quality else rho


def _ranks_of(original: np.ndarray, as_float: np.ndarray, axis: int) -> np.ndarray:
    """Ranks along the last axis, using the integer fast path when possible."""
    if _is_integral(original):
        return average_ranks(np.moveaxis(original, axis, -1), axis=-1)
    return average_ranks(as_float, axis=-1)


# ------------------------------------------------------------------ per cell
def check_cell_batch(s: np.ndarray, t_s_ns: np.ndarray, v: np.ndarray, t_v_ns: np.ndarray) -> None:
    """Check the shapes of a batch of cells: (n_cells, channels, samples) and their stamps.

    Raises
    ------
    SignalError
        When S and V differ in ``n_cells``, or a stamp array matches neither
        ``(samples,)`` (shared by all cells) nor ``(n_cells, samples)``.
    """
    if s.ndim != 3 or v.ndim != 3 or s.shape[0] != v.shape[0]:
        raise SignalError(
            f"vibration and deformation must be (n_cells, channels, samples) with the same n_cells; "
            f"got {s.shape} and {v.shape}")
    n_cells = s.shape[0]
    if np.shape(t_s_ns) not in ((s.shape[2],), (n_cells, s.shape[2])) or \
            np.shape(t_v_ns) not in ((v.shape[2],), (n_cells, v.shape[2])):
        raise SignalError(f"time stamps do not match samples: {np.shape(t_s_ns)} vs {s.shape}, "
                          f"{np.shape(t_v_ns)} vs {v.shape}")


def held_correlations(s: np.ndarray, t_s_ns: np.ndarray, v: np.ndarray, t_v_ns: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pearson and Spearman correlation of every S channel with every V channel held on S (eq. 4-5, 9-10).

    V is held onto S's time base (zero-order hold); S samples before the
    first V sample have no partner and are left out.

    Parameters
    ----------
    s : array_like, shape (n_cells, n_s, n_fast)
        Vibration samples S of cells sharing one fast time base.
    t_s_ns : array_like of int64, shape (n_fast,)
    v : array_like, shape (n_cells, n_v, n_slow)
        Deformation samples V (one slow time base).
    t_v_ns : array_like of int64, shape (n_slow,)

    Returns
    -------
    lin, nonlin : numpy.ndarray, shape (n_cells, n_s, n_v)
        Pearson r and Spearman rho.
    quality : numpy.ndarray of uint32, shape (n_cells,)
        OR of the :class:`Quality` flags of every pair.
    """
    s = np.asarray(s)
    v = np.asarray(v)
    if np.ndim(t_s_ns) != 1 or np.ndim(t_v_ns) != 1:
        raise SignalError("held_correlations takes one fast and one slow time base (1-D stamps)")
    check_cell_batch(s, t_s_ns, v, t_v_ns)
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


def cell_quantities(s: np.ndarray, t_s_ns: np.ndarray, v: np.ndarray, t_v_ns: np.ndarray,
                    rate_s_hz: float, rate_v_hz: float) -> tuple[np.ndarray, ...]:
    """Every per-cell quantity of eq. 1-5 for a batch of cells, computed as the paper states it.

    :func:`hjorth` of every channel, and :func:`held_correlations` per
    group of cells sharing their time bases.

    Parameters
    ----------
    s : array_like, shape (n_cells, n_s, n_fast)
    t_s_ns : array_like of int64, shape (n_fast,) or (n_cells, n_fast)
    v : array_like, shape (n_cells, n_v, n_slow)
    t_v_ns : array_like of int64, shape (n_slow,) or (n_cells, n_slow)
    rate_s_hz, rate_v_hz : float

    Returns
    -------
    tuple of numpy.ndarray
        ``act_s, mob_s, com_s`` (n_cells, n_s), ``act_v, mob_v, com_v``
        (n_cells, n_v), ``lin, nonlin`` (n_cells, n_s, n_v) and ``quality``
        (n_cells,) uint32, the OR of every flag of the cell: the fields of
        :class:`~.aggregation.CellFeatures` in order.
    """
    s = np.asarray(s)
    v = np.asarray(v)
    ts = np.asarray(t_s_ns, dtype=np.int64)
    tv = np.asarray(t_v_ns, dtype=np.int64)
    check_cell_batch(s, ts, v, tv)
    n_cells = s.shape[0]
    hs = hjorth(s, rate_s_hz)
    hv = hjorth(v, rate_v_hz)
    quality = np.bitwise_or.reduce(hs.quality, axis=1) | np.bitwise_or.reduce(hv.quality, axis=1)
    lin = np.zeros((n_cells, s.shape[1], v.shape[1]))
    nonlin = np.zeros_like(lin)
    for cells, t_fast, t_slow in _time_groups(ts, tv, n_cells):
        r, rho, q = held_correlations(s[cells], t_fast, v[cells], t_slow)
        lin[cells], nonlin[cells] = r, rho
        quality[cells] |= q
    return (hs.activity, hs.mobility, hs.complexity, hv.activity, hv.mobility, hv.complexity,
            lin, nonlin, quality.astype(np.uint32))


def _time_groups(ts: np.ndarray, tv: np.ndarray, n_cells: int):
    """Cells sharing both time bases: (cell indices, fast stamps, slow stamps)."""
    if n_cells == 0:
        return
    ts2 = np.broadcast_to(ts, (n_cells, ts.shape[-1]))
    tv2 = np.broadcast_to(tv, (n_cells, tv.shape[-1]))
    groups: dict[tuple[bytes, bytes], list[int]] = {}
    for c in range(n_cells):
        groups.setdefault((ts2[c].tobytes(), tv2[c].tobytes()), []).append(c)
    for cells in groups.values():
        yield np.asarray(cells), ts2[cells[0]], tv2[cells[0]]
