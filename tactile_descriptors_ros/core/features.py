"""Feature groups: the pieces a descriptor is made of, over one window's cell signals.

A robot's descriptor is a *selection* of feature groups (``descriptor.groups``
in the robot description, the window node's ``descriptor.groups``
parameter, ``tactile evaluate --mode``).  Each group is computed per cell from
every channel its cell type declares, then averaged over the cells of a body
part that are in contact (eq. 13-15, 19-26), like the paper's quantities.
Labels are ``<group>/<label>`` in a body part (``<body part>/<group>/<label>``
in the whole-robot descriptor), so a descriptor tells which selection made
it and a model refuses descriptors of another selection.

Groups (labels for a BioTac: S = ``pac``, V = ``e1..e19``, extra channels
``pdc tdc tac``; for a skin cell: S = ``ax ay az``, V = ``f1 f2 f3``, extra
``proximity temperature``):

``paper``
    The paper's descriptor, eq. 11 / 17 / 28: Hjorth Activity, Mobility and
    Complexity of S and V (eq. 1-3), Pearson and Spearman correlation of S
    with V (eq. 4-5), channels averaged per axis -- ``A_pac A_E M_pac M_E
    C_pac C_E L_pac_E N_pac_E`` (8 values per BioTac, 18 per skin cell).
    This is the robot description's legacy ``channels: averaged``.
``per_channel``
    The same quantities per channel (``A_e7``, ``L_pac_e7``, ...; 98 per
    BioTac, 36 per skin cell); the legacy ``channels: per_channel``.
``bands``
    Hjorth Activity, Mobility, Complexity (eq. 1-3) of each vibration
    channel band-limited to each band of :func:`vibration_bands`
    (``A_pac_20-50Hz``, ``M_ax_100-200Hz``, ...): how the texture's
    vibration energy and its frequency spread are distributed over the
    spectrum (multi-band Hjorth, as in EEG analysis).  From the spectral
    moments of one FFT per channel (:func:`band_hjorth`).
``levels``
    Mean of every slow channel over the window: the deformation channels
    (minus their tare, when the driver reports one) and the extra channels
    (``level_e1``, ``level_pdc``, ``level_temperature``, ...): static
    deformation, contact force, proximity and thermal state.
    ``levels:<ch>,<ch>`` restricts the group to the named channels (for
    example ``levels:f1,f2,f3,proximity``); a channel the cell type does not
    declare is a :class:`~tactile_descriptors_ros.errors.ConfigError` at
    load time.
``statistics``
    The hand-made features of the related work (Fishel & Loeb 2012; Jamali &
    Sammut 2011): log variance (``log1p``), skewness and excess kurtosis of
    each vibration and deformation channel, and log band powers (``log1p``
    of the window's power spectrum summed over a band, :func:`band_powers`)
    of each vibration channel in :func:`vibration_bands` and of each
    deformation channel in :func:`deformation_bands` (``logvar_pac``,
    ``skew_e3``, ``kurt_ax``, ``logbp_pac_20-50Hz``, ``logbp_e1_0-2Hz``).

``paper`` and ``per_channel`` come from the descriptor kernel
(:mod:`.fast`, :mod:`.aggregation`); the other groups from the functions of
this module over the cells' stacked signals.
"""

from __future__ import annotations

import functools
from collections.abc import Iterable, Mapping, Sequence

import numpy as np
from scipy import fft as sfft

from ..errors import ConfigError
from . import fast
from .robot import CellType

__all__ = [
    "GROUPS",
    "KERNEL_GROUPS",
    "CHANNEL_MODE_GROUPS",
    "VIBRATION_BANDS_HZ",
    "DEFORMATION_BANDS_HZ",
    "groups_of_channels",
    "parse_group",
    "check_groups",
    "group_channels",
    "feedable_groups",
    "check_present",
    "vibration_bands",
    "deformation_bands",
    "group_labels",
    "selection_labels",
    "selection_name",
    "groups_in_labels",
    "power_spectrum",
    "band_hjorth",
    "moments",
    "band_powers",
    "statistics_values",
    "level_values",
    "piece_summary",
]

#: Every feature group, in the order the evaluation's feature bank stores them.
GROUPS: tuple[str, ...] = ("paper", "per_channel", "bands", "levels", "statistics")

#: Groups computed by the descriptor kernel, and the kernel's channel mode for each.
KERNEL_GROUPS: dict[str, str] = {"paper": "averaged", "per_channel": "per_channel"}

#: The legacy ``descriptor.channels`` modes as group selections.
CHANNEL_MODE_GROUPS: dict[str, tuple[str, ...]] = {"averaged": ("paper",), "per_channel": ("per_channel",)}

#: Vibration bands (Hz) of ``bands`` and ``statistics``, clipped to each
#: rate's Nyquist frequency by :func:`vibration_bands`.  The BioTac's PAC is
#: AC-coupled (nothing below 20 Hz) and sampled at 2.2 kHz.
VIBRATION_BANDS_HZ: tuple[tuple[float, float], ...] = (
    (20.0, 50.0), (50.0, 100.0), (100.0, 200.0), (200.0, 400.0), (400.0, 800.0), (800.0, 1050.0))

#: Deformation bands (Hz) of ``statistics`` (electrodes at 100 Hz); a faster
#: deformation signal gets one more band up to its Nyquist frequency.
DEFORMATION_BANDS_HZ: tuple[tuple[float, float], ...] = ((0.0, 2.0), (2.0, 10.0), (10.0, 50.0))

_NYQUIST_MARGIN = 0.98  # vibration band edges stay below 0.98 x Nyquist


def groups_of_channels(channels: str) -> tuple[str, ...]:
    """The group selection of a legacy channel mode (``averaged`` -> ``(paper,)``).

    Raises
    ------
    ConfigError
        For an unknown channel mode.
    """
    try:
        return CHANNEL_MODE_GROUPS[channels]
    except KeyError:
        raise ConfigError(f"channel mode must be one of {tuple(CHANNEL_MODE_GROUPS)}, got {channels!r}",
                          key="descriptor.channels") from None


def parse_group(token: str, *, key: str = "descriptor.groups",
                source: str | None = None) -> tuple[str, tuple[str, ...] | None]:
    """Split ``"levels:f1,proximity"`` into ``("levels", ("f1", "proximity"))``; ``"bands"`` -> ``("bands", None)``.

    Raises
    ------
    ConfigError
        For an unknown group, or channels given to a group that takes none.
    """
    name, sep, rest = str(token).partition(":")
    name = name.strip()
    if name not in GROUPS:
        raise ConfigError(f"unknown feature group {name!r}; choose from {', '.join(GROUPS)}",
                          key=key, source=source)
    if not sep:
        return name, None
    if name != "levels":
        raise ConfigError(f"feature group {name!r} takes no channel list (only levels:<ch>,<ch> does)",
                          key=key, source=source)
    chans = tuple(c.strip() for c in rest.split(",") if c.strip())
    if not chans or len(set(chans)) != len(chans):
        raise ConfigError(f"{token!r}: needs distinct channel names after 'levels:'", key=key, source=source)
    return name, chans


def vibration_bands(rate_hz: float) -> tuple[tuple[float, float], ...]:
    """:data:`VIBRATION_BANDS_HZ` below ``0.98 x`` Nyquist of ``rate_hz``, upper edges clipped there."""
    top = _NYQUIST_MARGIN * rate_hz / 2.0
    return tuple((lo, min(hi, top)) for lo, hi in VIBRATION_BANDS_HZ if lo < top)


def deformation_bands(rate_hz: float) -> tuple[tuple[float, float], ...]:
    """:data:`DEFORMATION_BANDS_HZ`, plus ``(50, Nyquist)`` when the Nyquist frequency is above 50 Hz."""
    nyq = rate_hz / 2.0
    bands = tuple((lo, min(hi, nyq)) for lo, hi in DEFORMATION_BANDS_HZ if lo < nyq)
    last = DEFORMATION_BANDS_HZ[-1][1]
    return bands + (((last, nyq),) if nyq > last else ())


def _level_channels(cell_type: CellType, chans: tuple[str, ...] | None) -> tuple[str, ...]:
    slow = cell_type.deformation.channels + cell_type.extra_channels
    return slow if chans is None else chans


@functools.lru_cache(maxsize=256)
def check_groups(cell_type: CellType, groups: tuple[str, ...], *, key: str = "descriptor.groups",
                 source: str | None = None) -> tuple[str, ...]:
    """Check that ``cell_type`` can feed every group of a selection; return the selection.

    Raises
    ------
    ConfigError
        Naming the group and the cell type: an unknown group, a group listed
        twice, ``bands`` on a vibration rate without any band below Nyquist,
        ``levels:<ch>`` with a channel the cell type does not declare (or a
        vibration channel, whose mean is an AC offset or gravity, not a level).
    """
    groups = tuple(groups)
    if not groups:
        raise ConfigError("needs at least one feature group", key=key, source=source)
    if len(set(groups)) != len(groups):
        raise ConfigError(f"feature group listed twice in {list(groups)}", key=key, source=source)
    for token in groups:
        name, chans = parse_group(token, key=key, source=source)
        if name == "bands" and not vibration_bands(cell_type.vibration.rate_hz):
            raise ConfigError(f"feature group 'bands' cannot be fed by cell type {cell_type.name!r}: its vibration "
                              f"rate ({cell_type.vibration.rate_hz:g} Hz) has no band of {VIBRATION_BANDS_HZ} "
                              "below Nyquist", key=key, source=source)
        if name == "levels" and chans is not None:
            slow = _level_channels(cell_type, None)
            missing = [c for c in chans if c not in slow]
            if missing:
                raise ConfigError(f"feature group {token!r} cannot be fed by cell type {cell_type.name!r}: it "
                                  f"declares no slow channel {missing[0]!r} (it has {', '.join(slow)})",
                                  key=key, source=source)
    return groups


def group_channels(cell_type: CellType, group: str) -> tuple[str, ...]:
    """The channels a feature group reads: S and V for every group but ``levels``, which reads the slow
    channels (V and the extra channels, or those ``levels:<ch>,...`` names)."""
    name, chans = parse_group(group)
    if name == "levels":
        return _level_channels(cell_type, chans)
    return cell_type.vibration.channels + cell_type.deformation.channels


def feedable_groups(cell_type: CellType, present: Iterable[str]) -> tuple[str, ...]:
    """The groups of :data:`GROUPS` a recording holding only the channels ``present`` can feed.

    ``levels`` restricted to the present slow channels (``levels:pdc,tdc,tac``)
    stands in for ``levels`` when some slow channel is absent.
    """
    have = set(present)
    out = [g for g in GROUPS if all(c in have for c in group_channels(cell_type, g))]
    if "levels" not in out:
        slow = [c for c in _level_channels(cell_type, None) if c in have]
        if slow:
            out.append("levels:" + ",".join(slow))
    return tuple(out)


def check_present(cell_type: CellType, groups: Iterable[str], present: Iterable[str], *, where: str,
                  why: Mapping[str, str] | None = None, key: str = "descriptor.groups") -> None:
    """Refuse a selection with a group that reads a channel the recordings do not hold.

    Parameters
    ----------
    cell_type : CellType
    groups : iterable of str
        The selection.
    present : iterable of str
        Channels the recordings hold (at the cell type's rates).
    where : str
        The recordings (a file), named first in the message.
    why : mapping of str to str, optional
        Why a channel is absent (``"pac"`` -> ``"PAC at 200 Hz, not 2200 Hz"``).

    Raises
    ------
    ConfigError
        Naming the first group that cannot be fed, its missing channel, and
        the groups these recordings can feed.
    """
    have = set(present)
    for g in groups:
        missing = [c for c in group_channels(cell_type, g) if c not in have]
        if missing:
            reason = (why or {}).get(missing[0])
            more = f" (and {len(missing) - 1} more)" if len(missing) > 1 else ""
            able = feedable_groups(cell_type, have)
            raise ConfigError(
                f"{where}: feature group {g!r} needs channel {missing[0]!r}{more}, which these recordings do not "
                f"hold{f' ({reason})' if reason else ''}; the groups they can feed: "
                f"{', '.join(able) if able else 'none'}", key=key)


def _band_name(lo: float, hi: float) -> str:
    return f"{int(lo)}-{int(hi)}Hz"


@functools.lru_cache(maxsize=256)
def group_labels(cell_type: CellType, group: str) -> tuple[str, ...]:
    """Labels of one group's values in a body part, without the ``<group>/`` prefix.

    The kernel groups follow :func:`.aggregation.body_part_layout`; the
    others are documented in this module's docstring.
    """
    from .aggregation import body_part_layout  # the kernel groups' layout lives with the kernel

    name, chans = parse_group(group)
    if name in KERNEL_GROUPS:
        return body_part_layout(cell_type, KERNEL_GROUPS[name])
    vib, dfm = cell_type.vibration.channels, cell_type.deformation.channels
    vbands = [_band_name(lo, hi) for lo, hi in vibration_bands(cell_type.vibration.rate_hz)]
    if name == "bands":
        return tuple(f"{q}_{ch}_{b}" for q in ("A", "M", "C") for ch in vib for b in vbands)
    if name == "levels":
        return tuple(f"level_{ch}" for ch in _level_channels(cell_type, chans))
    dbands = [_band_name(lo, hi) for lo, hi in deformation_bands(cell_type.deformation.rate_hz)]
    both = vib + dfm
    return tuple([f"logvar_{c}" for c in both] + [f"skew_{c}" for c in both] + [f"kurt_{c}" for c in both]
                 + [f"logbp_{c}_{b}" for c in vib for b in vbands]
                 + [f"logbp_{c}_{b}" for c in dfm for b in dbands])


@functools.lru_cache(maxsize=256)
def selection_labels(cell_type: CellType, groups: tuple[str, ...]) -> tuple[str, ...]:
    """A body part's labels for a selection: ``<group>/<label>`` group after group."""
    return tuple(f"{g}/{lab}" for g in groups for lab in group_labels(cell_type, g))


def selection_name(groups: Iterable[str]) -> str:
    """``"per_channel+bands+levels+statistics"``: how a selection is named in messages and errors."""
    return "+".join(groups)


def groups_in_labels(labels: Sequence[str]) -> tuple[str, ...]:
    """The feature groups a descriptor's labels come from, in order (``<...>/<group>/<label>``).

    Labels without a group component (descriptors of an older release) give ``"?"``.
    """
    out: dict[str, None] = {}
    for lab in labels:
        parts = lab.split("/")
        group = parts[-2] if len(parts) >= 2 else ""
        out[group if group.partition(":")[0] in GROUPS else "?"] = None
    return tuple(out)


# ------------------------------------------------------------------ groups
def power_spectrum(x: np.ndarray) -> np.ndarray:
    """One-sided power spectrum of each signal (last axis), scaled so that a band's sum is its variance share.

    ``P_k = w_k |X_k|^2 / n^2`` with ``X = rfft(x)`` (:func:`scipy.fft.rfft`) and ``P_0 = 0`` (the mean removed),
    ``w_k = 2`` for bins that stand for a conjugate pair and 1 for the DC and
    Nyquist bins: ``sum_k P_k`` is the variance of ``x`` (Parseval), and the
    sum over a band is the variance of ``x`` band-limited to it (an ideal
    band-pass over the window, taken as one period).

    Returns
    -------
    numpy.ndarray, shape ``x.shape[:-1] + (n // 2 + 1,)``
    """
    x = np.asarray(x)
    n = x.shape[-1]
    X = sfft.rfft(x, axis=-1)
    kernel = fast.kernel_module() if X.size and X.dtype == np.complex128 else None
    if kernel is not None:  # one compiled pass, the same operations as below (the live path's cost)
        out = np.empty(X.shape, dtype=np.float64)
        m = X.shape[-1]
        kernel.power_spectrum(X.reshape(-1, m).view(np.float64), _pair_weights(n), out.reshape(-1, m))
        return out
    # |X|^2 from the interleaved real and imaginary parts, in place (the live path's cost: 348 spectra per
    # NAO window); the mean only moves the DC bin, which is set to 0 instead of centring every sample
    v = X.view(np.float64)
    np.square(v, out=v)
    p = v[..., 0::2] + v[..., 1::2]
    p[..., 0] = 0.0
    p *= _pair_weights(n)
    return p


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
    (:func:`power_spectrum`): with ``G_k = |2 sin(pi k / n) rate|^2`` the
    gain of that difference, ``var(y) = sum P_k``, ``var(y') = sum P_k G_k``,
    ``var(y'') = sum P_k G_k^2`` over the band's bins.  Equal (float
    rounding) to the time-domain computation on ``irfft`` of the masked
    spectrum; one FFT per channel instead of a filter per band (the
    descriptor's live cost, docs/performance.md).

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
    n_cells, n_ch, n = x.shape
    p = power_spectrum(x) if spectrum is None else spectrum
    bins = _band_bins(n, float(rate_hz), vibration_bands(rate_hz))
    g = _difference_gain(n, float(rate_hz))
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
    signal band-limited to it, so the powers of bands covering the spectrum
    add up to the variance.

    Returns
    -------
    numpy.ndarray, shape ``x.shape[:-1] + (len(bands),)``
    """
    x = np.asarray(x)
    p = power_spectrum(x) if spectrum is None else spectrum
    return np.log1p(_band_sums(p, _band_bins(x.shape[-1], float(rate_hz), tuple(bands))))


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
    v = np.asarray(deformation, dtype=np.float64)
    means = [v.mean(axis=-1) - np.asarray(deformation_tare, dtype=np.float64)]
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
    slow = _level_channels(cell_type, None)
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
    from .scaling import activity_mask, log_activity

    v = np.asarray(values, dtype=np.float64)
    v = log_activity(v.reshape(-1, v.shape[-1]), activity_mask(labels)).reshape(v.shape)
    return (np.concatenate([v.mean(axis=1), v.std(axis=1)], axis=1),
            tuple([f"mean_{lab}" for lab in labels] + [f"sd_{lab}" for lab in labels]))
