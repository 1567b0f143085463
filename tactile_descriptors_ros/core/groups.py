"""Feature groups by name: what a descriptor selection is made of, what each group reads and is labelled.

A robot's descriptor is a *selection* of feature groups (``descriptor.groups``
in the robot description, the window node's ``descriptor.groups``
parameter, ``tactile evaluate --mode``).  Each group is computed per cell from
the channels its cell type declares (:func:`group_channels`), then averaged
over the cells of a body part that are in contact (eq. 13-15, 19-26), like
the paper's quantities.  Labels are ``<group>/<label>`` in a body part
(``<body part>/<group>/<label>`` in the whole-robot descriptor), so a
descriptor tells which selection made it and a model refuses descriptors of
another selection.

This module is the catalogue: the groups' names, the channels each reads,
their labels, and the checks of a selection against a cell type that the
robot description (:mod:`.robot`) runs at load time.  It computes nothing;
the values come from :mod:`.features` (and the descriptor kernel,
:mod:`.fast`, for the kernel groups), put together by :mod:`.aggregation`.
A new group is a name in :data:`GROUPS`, its channels in
:data:`GROUP_READS`, its labels in :func:`group_labels`, and its values in
:mod:`.features`.

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
    moments of one FFT per channel (:func:`.features.band_hjorth`).
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
    of the window's power spectrum summed over a band, :func:`.features.band_powers`)
    of each vibration channel in :func:`vibration_bands` and of each
    deformation channel in :func:`deformation_bands` (``logvar_pac``,
    ``skew_e3``, ``kurt_ax``, ``logbp_pac_20-50Hz``, ``logbp_e1_0-2Hz``).
``plain``
    Plain statistics of every channel over the window: mean, standard
    deviation, minimum and maximum (``avg_pac``, ``std_e3``, ``min_tdc``,
    ``max_proximity``): the floor a selection must beat.
``rocket``
    Random-convolution features (MiniRocket, :mod:`.rocket`): proportions of
    positive values of the vibration signal's and the slow channels'
    (deformation, tare subtracted as for ``levels``, and extra channels)
    convolutions with MiniRocket's 84 kernels at several dilations, against
    biases fitted on training recordings (``ppv_vibration_0000``,
    ``ppv_slow_0000``, ...).  The fitted transforms of a cell type are read
    from ``config/rocket/<cell type>.json`` (:func:`rocket_parameters`;
    ``tactile fit-rocket`` writes it); a cell type without that file cannot
    feed the group.
"""

from __future__ import annotations

import functools
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

from ..errors import ConfigError, SignalError
from .cell_types import CellType
from .yamlreader import config_dir

__all__ = [
    "GROUPS",
    "GROUP_READS",
    "KERNEL_GROUPS",
    "CHANNEL_MODE_GROUPS",
    "VIBRATION_BANDS_HZ",
    "DEFORMATION_BANDS_HZ",
    "groups_of_channels",
    "parse_group",
    "check_groups",
    "group_channels",
    "level_channels",
    "feedable_groups",
    "check_present",
    "vibration_bands",
    "deformation_bands",
    "body_part_layout",
    "group_labels",
    "selection_labels",
    "selection_name",
    "groups_in_labels",
    "ROCKET_SIGNALS",
    "rocket_parameters_path",
    "rocket_parameters",
    "fitted",
]

#: Every feature group and what it reads: ``"signals"`` (every vibration and
#: deformation channel) or ``"slow"`` (the deformation and extra channels, or
#: the channels a ``<group>:<ch>,<ch>`` token names), in the order the
#: evaluation's feature bank stores them.
GROUP_READS: dict[str, str] = {"paper": "signals", "per_channel": "signals", "bands": "signals",
                               "levels": "slow", "statistics": "signals", "plain": "all", "rocket": "all"}

#: The signals of the ``rocket`` group, in label order: the vibration channels, then the slow channels.
ROCKET_SIGNALS: tuple[str, ...] = ("vibration", "slow")

#: Every feature group, in the order of :data:`GROUP_READS`.
GROUPS: tuple[str, ...] = tuple(GROUP_READS)

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
    if GROUP_READS[name] != "slow":
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


def level_channels(cell_type: CellType, chans: tuple[str, ...] | None = None) -> tuple[str, ...]:
    """The slow channels the ``levels`` group reads: V then the extra channels, or ``chans`` when given."""
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
        if name == "rocket":
            rocket_parameters(cell_type, key=key, source=source)
        if GROUP_READS[name] == "slow" and chans is not None:
            slow = level_channels(cell_type)
            missing = [c for c in chans if c not in slow]
            if missing:
                raise ConfigError(f"feature group {token!r} cannot be fed by cell type {cell_type.name!r}: it "
                                  f"declares no slow channel {missing[0]!r} (it has {', '.join(slow)})",
                                  key=key, source=source)
    return groups


def group_channels(cell_type: CellType, group: str) -> tuple[str, ...]:
    """The channels a feature group reads (:data:`GROUP_READS`): S and V, or the slow channels
    (V and the extra channels, or those ``levels:<ch>,...`` names)."""
    name, chans = parse_group(group)
    if GROUP_READS[name] == "slow":
        return level_channels(cell_type, chans)
    if GROUP_READS[name] == "all":
        return cell_type.channels
    return cell_type.vibration.channels + cell_type.deformation.channels


def rocket_parameters_path(cell_type: CellType) -> Path:
    """Where a cell type's fitted transforms of the ``rocket`` group live: ``config/rocket/<cell type>.json``.

    Raises
    ------
    ConfigError
        When the config directory cannot be found.
    """
    return config_dir() / "rocket" / f"{cell_type.name}.json"


def rocket_parameters(cell_type: CellType, *, key: str = "descriptor.groups", source: str | None = None) -> dict:
    """The fitted transforms of the ``rocket`` group for a cell type: ``config/rocket/<cell type>.json``.

    Returns
    -------
    dict of str to :class:`.rocket.RocketParameters`
        ``vibration`` (the vibration channels) and ``slow`` (deformation and
        extra channels), checked against the cell type's channel counts.

    Raises
    ------
    ConfigError
        When the file is missing or does not fit the cell type, naming it
        and how to write it.
    """
    from . import rocket  # the transform and its files (numpy; its kernel loads on first use)

    try:
        path = rocket_parameters_path(cell_type)
    except ConfigError as exc:
        raise ConfigError(f"feature group 'rocket': {exc}", key=key, source=source) from None
    if not path.is_file():
        raise ConfigError(f"feature group 'rocket' cannot be fed by cell type {cell_type.name!r}: no fitted "
                          f"transform {path} (write one with `tactile fit-rocket`)", key=key, source=source)
    params = rocket.load_parameters(path)
    want = {"vibration": len(cell_type.vibration.channels),
            "slow": len(cell_type.deformation.channels) + len(cell_type.extra_channels)}
    for sig in ROCKET_SIGNALS:
        if sig not in params or params[sig].n_channels != want[sig]:
            got = params[sig].n_channels if sig in params else "no"
            raise ConfigError(f"{path}: the {sig!r} transform takes {got} channels, cell type {cell_type.name!r} "
                              f"has {want[sig]}", key=key, source=source)
    return params


def fitted(cell_type: CellType, group: str) -> bool:
    """False for ``rocket`` when the cell type has no fitted transform (every other group needs none)."""
    if parse_group(group)[0] != "rocket":
        return True
    try:
        rocket_parameters(cell_type)
    except ConfigError:
        return False
    return True


def feedable_groups(cell_type: CellType, present: Iterable[str]) -> tuple[str, ...]:
    """The groups of :data:`GROUPS` a recording holding only the channels ``present`` can feed.

    ``levels`` restricted to the present slow channels (``levels:pdc,tdc,tac``)
    stands in for ``levels`` when some slow channel is absent.
    """
    have = set(present)
    out = [g for g in GROUPS if all(c in have for c in group_channels(cell_type, g)) and fitted(cell_type, g)]
    if "levels" not in out:
        slow = [c for c in level_channels(cell_type, None) if c in have]
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


_QUANTITIES = ("A", "M", "C")


def _axis_suffix(name: str) -> str:
    return f"_{name}" if name else ""


@functools.lru_cache(maxsize=256)
def body_part_layout(cell_type: CellType, channels: str = "averaged") -> tuple[str, ...]:
    """Labels of a body part's values, in eq. 11 order.

    Averaged (eq. 11/17/28): ``A_<S>[_axis]`` per S axis, ``A_<V>[_axis]``
    per V axis, the same for M and C, then ``L_<S>_<V>[_axis]`` and
    ``N_<S>_<V>[_axis]`` per correlation pair.  Per channel: one label per
    S channel, V channel and (S channel, V channel) pair.
    """
    vib, dfm = cell_type.vibration, cell_type.deformation
    pairs = cell_type.correlation_pairs()
    labels: list[str] = []
    if channels == "averaged":
        for q in _QUANTITIES:
            labels += [f"{q}_{vib.symbol}{_axis_suffix(a)}" for a in vib.axis_names]
            labels += [f"{q}_{dfm.symbol}{_axis_suffix(a)}" for a in dfm.axis_names]
        multi_v = len(dfm.axes) > 1 and cell_type.correlate != "pairwise"
        for q in ("L", "N"):
            for i, j in pairs:
                suffix = _axis_suffix(vib.axis_names[i]) + (_axis_suffix(dfm.axis_names[j]) if multi_v else "")
                labels.append(f"{q}_{vib.symbol}_{dfm.symbol}{suffix}")
    elif channels == "per_channel":
        for q in _QUANTITIES:
            labels += [f"{q}_{ch}" for ch in vib.channels]
            labels += [f"{q}_{ch}" for ch in dfm.channels]
        for q in ("L", "N"):
            for i, j in pairs:
                labels += [f"{q}_{sc}_{vc}" for sc in vib.axes[i] for vc in dfm.axes[j]]
    else:
        raise SignalError(f"channels must be 'averaged' or 'per_channel', got {channels!r}")
    return tuple(labels)


def _rocket_sizes(cell_type: CellType, groups: Iterable[str]) -> tuple[int, ...] | None:
    """The fitted ``rocket`` transforms' feature counts when ``groups`` holds the group, else None.

    The labels' caches take it as part of their key: a transform file written
    again (``tactile fit-rocket``), or another one put in its place, gives
    labels of its own size in the same process.
    """
    if not any(parse_group(g)[0] == "rocket" for g in groups):
        return None
    params = rocket_parameters(cell_type)
    return tuple(params[sig].n_features for sig in ROCKET_SIGNALS)


def group_labels(cell_type: CellType, group: str) -> tuple[str, ...]:
    """Labels of one group's values in a body part, without the ``<group>/`` prefix.

    The kernel groups follow :func:`body_part_layout`; the
    others are documented in this module's docstring.
    """
    return _group_labels(cell_type, group, _rocket_sizes(cell_type, (group,)))


@functools.lru_cache(maxsize=256)
def _group_labels(cell_type: CellType, group: str, rocket_sizes: tuple[int, ...] | None) -> tuple[str, ...]:
    name, chans = parse_group(group)
    if name in KERNEL_GROUPS:
        return body_part_layout(cell_type, KERNEL_GROUPS[name])
    vib, dfm = cell_type.vibration.channels, cell_type.deformation.channels
    vbands = [_band_name(lo, hi) for lo, hi in vibration_bands(cell_type.vibration.rate_hz)]
    if name == "bands":
        return tuple(f"{q}_{ch}_{b}" for q in ("A", "M", "C") for ch in vib for b in vbands)
    if name == "levels":
        return tuple(f"level_{ch}" for ch in level_channels(cell_type, chans))
    if name == "plain":
        return tuple(f"{q}_{ch}" for q in ("avg", "std", "min", "max") for ch in cell_type.channels)
    if name == "rocket":
        return tuple(f"ppv_{sig}_{i:04d}" for sig, n in zip(ROCKET_SIGNALS, rocket_sizes) for i in range(n))
    dbands = [_band_name(lo, hi) for lo, hi in deformation_bands(cell_type.deformation.rate_hz)]
    both = vib + dfm
    return tuple([f"logvar_{c}" for c in both] + [f"skew_{c}" for c in both] + [f"kurt_{c}" for c in both]
                 + [f"logbp_{c}_{b}" for c in vib for b in vbands]
                 + [f"logbp_{c}_{b}" for c in dfm for b in dbands])


def selection_labels(cell_type: CellType, groups: tuple[str, ...]) -> tuple[str, ...]:
    """A body part's labels for a selection: ``<group>/<label>`` group after group."""
    return _selection_labels(cell_type, tuple(groups), _rocket_sizes(cell_type, groups))


@functools.lru_cache(maxsize=256)
def _selection_labels(cell_type: CellType, groups: tuple[str, ...],
                      rocket_sizes: tuple[int, ...] | None) -> tuple[str, ...]:
    return tuple(f"{g}/{lab}" for g in groups for lab in _group_labels(cell_type, g, rocket_sizes))


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
