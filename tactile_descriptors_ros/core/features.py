"""Feature groups' values: the computations behind the groups of :mod:`.groups`, over one window's cells.

Each function takes a stack of cells (``(n_cells, n_channels, n_samples)``)
and returns one row of values per cell in the order of
:func:`.groups.group_labels`; :mod:`.aggregation` averages the rows over the
cells of a body part in contact.  ``paper`` and ``per_channel`` come from the
descriptor kernel (:mod:`.fast`); ``bands`` from :func:`band_hjorth`,
``statistics`` from :func:`statistics_values` (both over the vibration's
:func:`power_spectrum`), ``levels`` from :func:`level_values`, ``plain`` from :func:`plain_values`,
``rocket`` from :func:`rocket_values` (:mod:`.rocket`).
:func:`piece_summary` summarises a selection over the pieces of a window.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np
from scipy import fft as sfft

from . import fast
from .cell_types import CellType
from .groups import deformation_bands, level_channels, parse_group, vibration_bands
from .scaling import activity_mask, log_activity

__all__ = [
    "spectral_length",
    "power_spectrum",
    "band_hjorth",
    "moments",
    "band_powers",
    "statistics_values",
    "level_values",
    "piece_summary",
    "plain_values",
    "rocket_values",
]


#: numpy.fft.rfft writes into a given array since numpy 2.0 (pocketfft, as scipy.fft; the same values).
_RFFT_OUT = np.lib.NumpyVersion(np.__version__) >= "2.0.0"


def spectral_length(n: int) -> int:
    """Samples of an ``n``-sample window the spectral features use: the largest fast FFT length ``L <= n``.

    ``L`` is :func:`scipy.fft.prev_fast_len` of ``n`` (its default
    definition: no prime factor above 11, lengths pocketfft transforms
    without its slow generic passes); the spectrum is that of the window's
    last ``L`` samples.  The windows the robots and the evaluation cut (2 s:
    2000 and 500 samples for a skin cell, 4400 and 200 for a BioTac; 1 s
    blocks; 0.5-6 s touches of a BioTac in steps of 0.5 s) are such lengths
    and lose nothing; another length loses its oldest samples, at most 2.2 %
    of a window of 1000 samples or more and 6 % of one of 100 to 1000
    (501 -> 500, 2003 -> 2000), and its FFT costs 2-8 ns a sample instead of
    up to 30 (a length with a large prime factor: 501 = 3 x 167 costs 8.5
    times 500).  ``n < 1`` gives 0.
    """
    return int(sfft.prev_fast_len(int(n))) if n >= 1 else 0


def power_spectrum(x: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """One-sided power spectrum of each signal (last axis), scaled so that a band's sum is its variance share.

    Over the signal's last ``L = spectral_length(n)`` samples (:func:`spectral_length`):
    ``P_k = w_k |X_k|^2 / L^2`` with ``X = rfft`` of those samples
    (pocketfft through :func:`numpy.fft.rfft`, as :func:`scipy.fft.rfft`) and ``P_0 = 0`` (the mean removed),
    ``w_k = 2`` for bins that stand for a conjugate pair and 1 for the DC and
    Nyquist bins: ``sum_k P_k`` is the variance of those samples (Parseval),
    and the sum over a band is their variance band-limited to it (an ideal
    band-pass over the window, taken as one period).

    Parameters
    ----------
    x : array_like, shape (..., n)
    out : numpy.ndarray, optional
        Filled with the spectrum and returned (float64, shape as below);
        a new array otherwise.

    Returns
    -------
    numpy.ndarray, shape ``x.shape[:-1] + (L // 2 + 1,)``
    """
    x = np.asarray(x)
    full = x.shape[-1]
    n = spectral_length(full)
    m = n // 2 + 1
    kernel = fast.kernel_module() if n and x.size and (x.dtype.kind in "biu" or x.dtype == np.float64) else None
    if kernel is not None:  # one compiled pass, the same operations as below (the live path's cost)
        if out is None:
            out = np.empty(x.shape[:-1] + (m,), dtype=np.float64)
        rows, flat = x.reshape(-1, full)[:, full - n:], out.reshape(-1, m)  # a view of a contiguous x
        # a block of signals at a time, as float64 and their transform in reused buffers small enough to stay
        # in a core's cache: each signal's transform is its own, so the values are those of one call on all
        step = _spectrum_block_rows(n, m)
        xf = fast.scratch("features.spectrum.x", (min(step, rows.shape[0]), n), np.float64)
        X = fast.scratch("features.spectrum.X", xf.shape[:1] + (m,), np.complex128)
        weights = _pair_weights(n)
        for r0 in range(0, rows.shape[0], step):
            r1 = min(r0 + step, rows.shape[0])
            xb, Xb = xf[: r1 - r0], X[: r1 - r0]
            np.copyto(xb, rows[r0:r1])
            if _RFFT_OUT:
                np.fft.rfft(xb, axis=-1, out=Xb)
            else:  # numpy < 2 has no out: scipy's transform (the same pocketfft) into a new array
                Xb = sfft.rfft(xb, axis=-1, overwrite_x=True)
            kernel.power_spectrum(Xb.view(np.float64), weights, flat[r0:r1])
        return out
    X = sfft.rfft(x[..., full - n:], axis=-1)
    # |X|^2 from the interleaved real and imaginary parts, in place; the mean only moves the DC bin, which
    # is set to 0 instead of centring every sample
    v = X.view(np.float64 if X.dtype == np.complex128 else np.float32)
    np.square(v, out=v)
    p = v[..., 0::2] + v[..., 1::2]
    p[..., 0] = 0.0
    p *= _pair_weights(n)
    if out is not None:
        out[...] = p
        return out
    return p


#: Bytes of the compiled spectrum's working buffers per block of signals (the float64 samples and their
#: transform): within a core's L2 cache.  A NAO window's 348 accelerometer signals of 2,000 samples in one
#: block (11 MB of buffers) took 0.5-0.7 ms longer to describe, in a stream of fresh windows, than in blocks
#: of 32 signals; a node's first window paged in the whole 11 MB.
SPECTRUM_BLOCK_BYTES = 1 << 20


def _spectrum_block_rows(n: int, m: int) -> int:
    """Signals per block of :func:`power_spectrum`'s compiled path: a multiple of 8 (pocketfft transforms
    several signals at once with vector instructions), at least 8."""
    per_row = 8 * n + 16 * m
    return max(8, SPECTRUM_BLOCK_BYTES // per_row // 8 * 8)


@functools.lru_cache(maxsize=64)
def _pair_weights(n: int) -> np.ndarray:
    w = np.full(n // 2 + 1, 2.0 / (float(n) * n))
    w[0] = 1.0 / (float(n) * n)
    if n % 2 == 0:
        w[-1] = 1.0 / (float(n) * n)
    return w


@functools.lru_cache(maxsize=256)
def _band_bins(n: int, rate_hz: float, bands: tuple[tuple[float, float], ...]) -> tuple[tuple[int, int], ...]:
    """``[k_lo, k_hi)`` of the rfft bins with ``lo <= f_k < hi`` (``f_k = k rate / n``); a band reaching Nyquist includes it."""
    out = []
    for lo, hi in bands:
        k_lo = int(np.ceil(lo * n / rate_hz - 1e-9))
        k_hi = n // 2 + 1 if hi >= rate_hz / 2 else int(np.ceil(hi * n / rate_hz - 1e-9))
        out.append((min(k_lo, n // 2 + 1), min(max(k_hi, k_lo), n // 2 + 1)))
    return tuple(out)


def _band_sums(p: np.ndarray, bins: tuple[tuple[int, int], ...]) -> np.ndarray:
    """Sums of ``p`` over each band's bins (last axis), shape ``p.shape[:-1] + (n_bands,)``."""
    out = np.zeros(p.shape[:-1] + (len(bins),))
    contiguous = all(bins[i][1] == bins[i + 1][0] for i in range(len(bins) - 1))
    if bins and contiguous and all(lo < hi for lo, hi in bins):
        # one pass: np.add.reduceat over the band starts of the bins up to the last band's end
        out[...] = np.add.reduceat(p[..., :bins[-1][1]], [lo for lo, _ in bins], axis=-1)
        return out
    for b, (lo, hi) in enumerate(bins):
        if hi > lo:
            out[..., b] = p[..., lo:hi].sum(axis=-1)
    return out


@functools.lru_cache(maxsize=256)
def _bin_edges(bins: tuple[tuple[int, int], ...]) -> tuple[np.ndarray, np.ndarray]:
    """The first and end bins of :func:`_band_bins` as int64 arrays (for the compiled kernel)."""
    return (np.array([lo for lo, _ in bins], dtype=np.int64), np.array([hi for _, hi in bins], dtype=np.int64))


@functools.lru_cache(maxsize=64)
def _difference_gain(n: int, rate_hz: float) -> np.ndarray:
    """``|2 sin(pi k / n) rate|^2``: the power gain of the first difference times the rate at bin k."""
    return (2.0 * rate_hz * np.sin(np.pi * np.arange(n // 2 + 1) / n)) ** 2


def band_hjorth(vibration: np.ndarray, rate_hz: float, spectrum: np.ndarray | None = None) -> np.ndarray:
    """The ``bands`` group of a stack of cells: Hjorth parameters per vibration band, from one FFT.

    Each channel is band-limited to each band of :func:`vibration_bands` by
    an ideal band-pass over the window (the window taken as one period:
    only the FFT bins of the band kept), and Hjorth Activity, Mobility and
    Complexity (eq. 1-3) are those of the band-limited signal with the
    derivative taken as the circular first difference times the rate.  All
    come from the spectral moments of one power spectrum
    (:func:`power_spectrum`, over the window's last ``L`` samples,
    :func:`spectral_length`): with ``G_k = |2 sin(pi k / L) rate|^2`` the
    gain of that difference, ``var(y) = sum P_k``, ``var(y') = sum P_k G_k``,
    ``var(y'') = sum P_k G_k^2`` over the band's bins.  Equal (float
    rounding) to the time-domain computation on ``irfft`` of the masked
    spectrum; one FFT per channel instead of a filter per band (the
    descriptor's live cost, lab/docs/performance.md).

    Parameters
    ----------
    vibration : array_like, shape (n_cells, n_channels, n_samples)
    rate_hz : float
    spectrum : numpy.ndarray, optional
        :func:`power_spectrum` of ``vibration`` when already computed.

    Returns
    -------
    numpy.ndarray, shape (n_cells, 3 * n_channels * n_bands)
        In the order of :func:`group_labels` (quantity, channel, band).
        A band without power has Mobility and Complexity 0 (as
        :func:`.descriptors.hjorth` for a flat signal).
    """
    x = np.asarray(vibration)
    n_cells, n_ch, _ = x.shape
    n = spectral_length(x.shape[-1])
    p = power_spectrum(x) if spectrum is None else spectrum
    bins = _band_bins(n, float(rate_hz), vibration_bands(rate_hz))
    g = _difference_gain(n, float(rate_hz))
    kernel = fast.kernel_module() if p.dtype == np.float64 and p.size and bins else None
    if kernel is not None:  # one compiled pass over the spectrum
        m = p.shape[-1]
        sums = np.empty((p.size // m, len(bins), 3))
        lo, hi = _bin_edges(bins)
        kernel.band_moments(np.ascontiguousarray(p).reshape(-1, m), g, lo, hi, sums)
        sums = sums.reshape(p.shape[:-1] + (len(bins), 3))
        s0, s1, s2 = sums[..., 0], sums[..., 1], sums[..., 2]
    else:
        pg = p * g
        s0 = _band_sums(p, bins)
        s1 = _band_sums(pg, bins)
        pg *= g
        s2 = _band_sums(pg, bins)
    with np.errstate(divide="ignore", invalid="ignore"):
        mob = np.where(s0 > 0, np.sqrt(s1 / np.where(s0 > 0, s0, 1.0)), 0.0)
        mob_d = np.where(s1 > 0, np.sqrt(s2 / np.where(s1 > 0, s1, 1.0)), 0.0)
        com = np.where(mob > 0, mob_d / np.where(mob > 0, mob, 1.0), 0.0)
    # (cell, channel, band) x quantity -> (cell, quantity, channel, band)
    return np.stack([s0, mob, com], axis=1).reshape(n_cells, -1)


def moments(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Log variance (``log1p``), skewness and excess kurtosis along the last axis.

    Skewness ``m3 / m2**1.5`` and kurtosis ``m4 / m2**2 - 3`` from the
    biased central moments, as :func:`scipy.stats.skew` and
    :func:`scipy.stats.kurtosis` with their defaults; computed here (integer
    counts by the compiled kernel when numba is installed, two passes
    without temporaries) because the live path needs them for every channel
    of every cell of a 116-cell skin within milliseconds.  A flat signal
    (variance at most 1e-12 of its squared magnitude) has no shape: skewness
    and kurtosis 0, never NaN.
    """
    x = np.asarray(x)
    kernel = fast.kernel_module() if x.dtype in (np.int32, np.int64) and x.size and x.shape[-1] else None
    if kernel is not None:  # integer counts (live and recorded data): the compiled two-pass sums
        out = np.empty((x.size // x.shape[-1], 5))
        kernel.central_moments(np.ascontiguousarray(x).reshape(-1, x.shape[-1]), out)
        out = out.reshape(x.shape[:-1] + (5,))
        m2, m3, m4, peak = out[..., 1], out[..., 2], out[..., 3], out[..., 4]
    else:
        x = np.asarray(x, dtype=np.float64)
        d = x - x.mean(axis=-1, keepdims=True)
        d2 = d * d
        m2 = d2.mean(axis=-1)
        m3 = np.einsum("...i,...i->...", d2, d) / x.shape[-1]
        m4 = np.einsum("...i,...i->...", d2, d2) / x.shape[-1]
        peak = np.abs(x).max(axis=-1)
    flat = m2 <= 1e-12 * np.maximum(1.0, peak) ** 2
    safe = np.where(flat, 1.0, m2)
    with np.errstate(all="ignore"):
        skew = np.where(flat, 0.0, m3 / safe**1.5)
        kurt = np.where(flat, 0.0, m4 / safe**2 - 3.0)
    return np.log1p(m2), skew, kurt


def band_powers(x: np.ndarray, rate_hz: float, bands: Sequence[tuple[float, float]],
                spectrum: np.ndarray | None = None) -> np.ndarray:
    """Log band powers (``log1p``) along the last axis, from the window's power spectrum.

    The power of a band ``[lo, hi)`` is the sum of :func:`power_spectrum`
    over its bins (a band reaching Nyquist includes it): the variance of the
    signal's last ``L`` samples (:func:`spectral_length`) band-limited to
    it, so the powers of bands covering the spectrum add up to their
    variance.

    Returns
    -------
    numpy.ndarray, shape ``x.shape[:-1] + (len(bands),)``
    """
    x = np.asarray(x)
    p = power_spectrum(x) if spectrum is None else spectrum
    return np.log1p(_band_sums(p, _band_bins(spectral_length(x.shape[-1]), float(rate_hz), tuple(bands))))


def statistics_values(vibration: np.ndarray, vibration_rate_hz: float, deformation: np.ndarray,
                      deformation_rate_hz: float, vibration_spectrum: np.ndarray | None = None) -> np.ndarray:
    """The ``statistics`` group of a stack of cells.

    Parameters
    ----------
    vibration : array_like, shape (n_cells, n_s, n_fast)
    vibration_rate_hz : float
    deformation : array_like, shape (n_cells, n_v, n_slow)
    deformation_rate_hz : float
    vibration_spectrum : numpy.ndarray, optional
        :func:`power_spectrum` of ``vibration`` when already computed (the
        ``bands`` group shares it).

    Returns
    -------
    numpy.ndarray, shape (n_cells, n_values)
        In the order of :func:`group_labels`.
    """
    s = np.asarray(vibration)
    v = np.asarray(deformation)
    n = s.shape[0]
    lv_s, sk_s, ku_s = moments(s)
    lv_v, sk_v, ku_v = moments(v)
    bp_s = band_powers(s, vibration_rate_hz, vibration_bands(vibration_rate_hz), vibration_spectrum)
    bp_v = band_powers(v, deformation_rate_hz, deformation_bands(deformation_rate_hz))
    return np.concatenate([lv_s, lv_v, sk_s, sk_v, ku_s, ku_v, bp_s.reshape(n, -1), bp_v.reshape(n, -1)], axis=1)


def level_values(cell_type: CellType, group: str, deformation: np.ndarray, deformation_tare: np.ndarray,
                 extra: np.ndarray) -> np.ndarray:
    """The ``levels`` group (or ``levels:<ch>,...``) of a stack of cells.

    Parameters
    ----------
    cell_type : CellType
    group : str
        ``"levels"`` or ``"levels:<ch>,<ch>"``.
    deformation : array_like, shape (n_cells, n_v, n_slow)
    deformation_tare : array_like, shape (n_cells, n_v)
        Subtracted from the deformation means (zeros when untared).
    extra : array_like, shape (n_cells, n_extra, n_slow)
        The extra channels (float, NaN where a sample is missing).

    Returns
    -------
    numpy.ndarray, shape (n_cells, n_values)
        Means over the window; NaN for a channel without any finite sample
        (the caller flags the body part ``INVALID``).
    """
    v = np.asarray(deformation)
    if v.dtype.kind in "iu" and v.dtype.itemsize <= 4 and v.shape[-1] < 1 << 22:
        # counts: the integer sum is exact, and so is the float sum of their mean (every partial sum is an
        # integer below 2**53), so the same means without a float copy of the window
        mean = np.add.reduce(v, axis=-1, dtype=np.int64) / v.shape[-1]
    else:
        mean = np.asarray(v, dtype=np.float64).mean(axis=-1)
    means = [mean - np.asarray(deformation_tare, dtype=np.float64)]
    e = np.asarray(extra, dtype=np.float64)
    if e.shape[1]:
        ok = np.isfinite(e)
        cnt = ok.sum(axis=-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            means.append(np.where(cnt > 0, np.where(ok, e, 0.0).sum(axis=-1) / np.maximum(cnt, 1), np.nan))
    allv = np.concatenate(means, axis=1)
    _, chans = parse_group(group)
    if chans is None:
        return allv
    slow = level_channels(cell_type)
    return allv[:, [slow.index(c) for c in chans]]


def piece_summary(values: np.ndarray, labels: Sequence[str]) -> tuple[np.ndarray, tuple[str, ...]]:
    """Mean and standard deviation over the successive pieces of a window.

    Parameters
    ----------
    values : array_like, shape (n_windows, n_pieces, n_values)
        A selection's values for each piece of each window.
    labels : sequence of str
        Their labels; Activity values (``A_...``) enter as ``log1p``
        (:func:`.scaling.log_activity`), so one loud piece does not dominate.

    Returns
    -------
    summary : numpy.ndarray, shape (n_windows, 2 * n_values)
        The means, then the standard deviations (how steady the texture is
        over the slide: stick-slip, uneven weave).
    labels : tuple of str
        ``mean_<label>`` then ``sd_<label>``.
    """
    v = np.asarray(values, dtype=np.float64)
    v = log_activity(v.reshape(-1, v.shape[-1]), activity_mask(labels)).reshape(v.shape)
    return (np.concatenate([v.mean(axis=1), v.std(axis=1)], axis=1),
            tuple([f"mean_{lab}" for lab in labels] + [f"sd_{lab}" for lab in labels]))


def plain_values(vibration: np.ndarray, deformation: np.ndarray, extra: np.ndarray) -> np.ndarray:
    """The ``plain`` group of a stack of cells: mean, standard deviation, minimum, maximum of every channel.

    Parameters
    ----------
    vibration : array_like, shape (n_cells, n_s, n_fast)
    deformation : array_like, shape (n_cells, n_v, n_slow)
    extra : array_like, shape (n_cells, n_extra, n_slow)
        NaN where a sample is missing (a channel without any finite sample gives NaN).

    Returns
    -------
    numpy.ndarray, shape (n_cells, 4 * n_channels)
        In the order of :func:`group_labels`: the statistic, then the channel.
    """
    s = np.asarray(vibration, dtype=np.float64)
    v = np.asarray(deformation, dtype=np.float64)
    e = np.asarray(extra, dtype=np.float64)
    out = []
    for q in (np.mean, np.std, np.min, np.max):
        parts = [q(s, axis=-1), q(v, axis=-1)]
        if e.shape[1]:
            parts.append(q(e, axis=-1) if np.isfinite(e).all() else _nan_stat(q, e))
        out.append(np.concatenate(parts, axis=1))
    return np.concatenate(out, axis=1)


def _nan_stat(q, e: np.ndarray) -> np.ndarray:
    """``nan<q>`` of rows, NaN (without a warning) for a row with no finite sample."""
    out = np.full(e.shape[:-1], np.nan)
    for idx in np.ndindex(*e.shape[:-1]):
        row = e[idx][np.isfinite(e[idx])]
        if row.size:
            out[idx] = q(row)
    return out


def rocket_values(cell_type: CellType, vibration: np.ndarray, deformation: np.ndarray,
                  deformation_tare: np.ndarray, extra: np.ndarray) -> np.ndarray:
    """The ``rocket`` group of a stack of cells (:mod:`.rocket`, transforms of :func:`rocket_parameters`).

    Parameters
    ----------
    cell_type : CellType
    vibration : array_like, shape (n_cells, n_s, n_fast)
    deformation : array_like, shape (n_cells, n_v, n_slow)
    deformation_tare : array_like, shape (n_cells, n_v)
        Subtracted from the deformation samples (as ``levels`` does).
    extra : array_like, shape (n_cells, n_extra, n_slow)

    Returns
    -------
    numpy.ndarray, shape (n_cells, n_values)
        The vibration transform's features, then the slow channels'; NaN for
        a cell whose signal holds a non-finite sample (a missing extra value).
    """
    from . import rocket
    from .groups import rocket_parameters

    params = rocket_parameters(cell_type)
    v = np.asarray(deformation, dtype=np.float64) - np.asarray(deformation_tare, dtype=np.float64)[..., None]
    slow = np.concatenate([v, np.asarray(extra, dtype=np.float64)], axis=1)
    return np.concatenate([rocket.transform(np.asarray(vibration), params["vibration"]),
                           rocket.transform(slow, params["slow"])], axis=1)
