"""Cell types: the sensing modalities of a kind of cell, as data (paper eq. 11, 17, 28).

A *cell type* (a BioTac, a skin cell, anything a robot description declares
under ``cell_types``) has a vibration modality S and a deformation modality
V, each a list of axes and each axis a list of channels; the general 24-value
descriptor is three axes of each, the BioTac's eq. 17 one PAC axis and one
axis of 19 electrodes, the skin cell's eq. 28 three accelerometer axes and
one axis of three force sensors.  A cell type without a ``vibration``
section senses pressure only (a capacitive taxel pad): S is empty, and only
the groups that describe V alone (``paper``, ``levels``, ``statistics``) can
be selected for it.  Besides S and V a cell type may declare
*extra channels* (``extra_channels``): slow signals sampled with V that enter
only the feature groups that use them (:mod:`.groups`).

This module is the bottom of the description: the feature-group catalogue
(:mod:`.groups`) checks a selection against a cell type, and the robot
description (:mod:`.robot`) is made of cell types and body parts.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

from ..errors import ConfigError
from .yamlreader import YamlReader

__all__ = ["Modality", "ForceSpec", "CellType", "parse_cell_type"]


@dataclass(frozen=True)
class Modality:
    """One sensing modality of a cell type (vibration S or deformation V).

    Attributes
    ----------
    symbol : str
        Short name used in descriptor labels (``"pac"``, ``"E"``, ``"a"``, ``"F"``).
    rate_hz : float
        Nominal sampling rate.
    adc_bits : int
        ADC resolution; values are integer counts in ``[0, 2**bits)``, or
        ``[-2**(bits-1), 2**(bits-1))`` when ``signed``.
    signed : bool
        Whether counts are signed.
    unit : str
        SI unit after scaling (``"Pa"``, ``"m/s^2"``, ``"N"``, or ``"count"``).
    si_per_count : float
        Scale from counts to ``unit``.
    axes : tuple of tuple of str
        Channels grouped by axis; values are averaged over the channels of an
        axis (paper eq. 6-10) and kept per axis.
    axis_names : tuple of str
        One name per axis (``""`` for a single axis, ``"x"``, ``"y"``, ``"z"``).
    """

    symbol: str
    rate_hz: float
    adc_bits: int
    signed: bool
    unit: str
    si_per_count: float
    axes: tuple[tuple[str, ...], ...]
    axis_names: tuple[str, ...]

    @property
    def channels(self) -> tuple[str, ...]:
        """All channels, axis by axis."""
        return tuple(ch for axis in self.axes for ch in axis)

    @property
    def adc_range(self) -> tuple[int, int]:
        """Smallest and largest count the ADC can report."""
        if self.signed:
            half = 1 << (self.adc_bits - 1)
            return (-half, half - 1)
        return (0, (1 << self.adc_bits) - 1)


@dataclass(frozen=True)
class ForceSpec:
    """How a cell's normal force is measured, for the contact gate (eq. 13, 16, 27).

    Attributes
    ----------
    channels : tuple of str
        Channels averaged to give the force (BioTac ``pdc``; skin ``f1 f2 f3``).
    n_per_count : float
        Newtons per count after taring.
    rate_hz : float
        Sampling rate of the force channels.
    """

    channels: tuple[str, ...]
    n_per_count: float
    rate_hz: float


@dataclass(frozen=True)
class CellType:
    """A kind of sensing cell: BioTac, skin cell, or anything declared in YAML."""

    name: str
    vibration: Modality
    deformation: Modality
    force: ForceSpec
    correlate: str  # "each_with_all" (S axis with every V axis) or "pairwise" (axis i with i)
    extra_channels: tuple[str, ...] = ()  # slow channels sampled with V (levels only)

    def __hash__(self) -> int:
        # The hash of the fields, as the dataclass's own, computed once: a cell type keys the caches that
        # every window's description reads (3 us a hash, two Modality and a ForceSpec hashed again each time).
        h = self.__dict__.get("_hash")
        if h is None:
            h = hash(tuple(getattr(self, f.name) for f in fields(self)))
            object.__setattr__(self, "_hash", h)
        return h

    def __getstate__(self) -> dict:
        # without the cached hash: strings hash differently in another process
        return {k: v for k, v in self.__dict__.items() if k != "_hash"}

    @property
    def has_vibration(self) -> bool:
        """False for a cell type declared without a vibration modality (pressure only)."""
        return bool(self.vibration.axes)

    @property
    def channels(self) -> tuple[str, ...]:
        """Every channel the cell type declares: S, V, then the extra channels."""
        return self.vibration.channels + self.deformation.channels + self.extra_channels

    def correlation_pairs(self) -> tuple[tuple[int, int], ...]:
        """(vibration axis, deformation axis) pairs whose correlations are averaged (eq. 9-10)."""
        n_s, n_v = len(self.vibration.axes), len(self.deformation.axes)
        if self.correlate == "pairwise":
            return tuple((i, i) for i in range(n_s))
        return tuple((i, j) for i in range(n_s) for j in range(n_v))


# --------------------------------------------------------------------------- parsing


def _reader(data, key: str, source: str) -> YamlReader:
    """Typed access to a YAML mapping that reports the dotted key on error (:class:`ConfigError`)."""
    return YamlReader(data, key, source, error=ConfigError)


def _parse_modality(r: YamlReader) -> Modality:
    bits = int(r.number("adc_bits", 12, positive=True))
    if not 1 <= bits <= 24:
        raise r.error("adc_bits", f"must be between 1 and 24, got {bits}")
    raw_axes = r.get("axes", kind=list)
    if not raw_axes:
        raise r.error("axes", "needs at least one axis")
    axes, names = [], []
    seen: set[str] = set()
    for i, raw in enumerate(raw_axes):
        ar = _reader(raw, r.path(f"axes[{i}]"), r.source)
        channels = ar.get("channels", kind=list)
        if not channels or not all(isinstance(c, str) and c for c in channels):
            raise ar.error("channels", "needs a non-empty list of channel names")
        for ch in channels:
            if ch in seen:
                raise ar.error("channels", f"channel {ch!r} is listed twice")
            seen.add(ch)
        axes.append(tuple(channels))
        names.append(str(ar.get("name", "", str)))
        ar.check_unknown()
    modality = Modality(
        symbol=str(r.get("symbol", kind=str)),
        rate_hz=r.number("rate_hz", positive=True),
        adc_bits=bits,
        signed=bool(r.get("signed", False, bool)),
        unit=str(r.get("unit", "count", str)),
        si_per_count=r.number("si_per_count", 1.0, positive=True),
        axes=tuple(axes),
        axis_names=tuple(names),
    )
    r.check_unknown()
    if modality.rate_hz > 1e6:
        raise r.error("rate_hz", f"{modality.rate_hz} Hz is not a plausible tactile sampling rate")
    return modality


def parse_cell_type(name: str, r: YamlReader) -> CellType:
    """Validate one entry of a robot description's ``cell_types`` section.

    Parameters
    ----------
    name : str
        The cell type's name (its key in ``cell_types``).
    r : YamlReader
        The entry (``cell_types.<name>``).

    Returns
    -------
    CellType

    Raises
    ------
    ConfigError
        Naming the offending key: bad axes or channels, an impossible rate,
        an unknown ``correlate`` mode, a vibration slower than the deformation.
        Without a ``vibration`` section the cell type senses pressure only (S empty).
    """
    dfm = _parse_modality(r.child("deformation"))
    if "vibration" in r.data:
        vib = _parse_modality(r.child("vibration"))
    else:  # pressure only (a capacitive taxel pad): no vibration channel, S is empty
        vib = Modality(symbol="", rate_hz=dfm.rate_hz, adc_bits=dfm.adc_bits, signed=False, unit="count",
                       si_per_count=1.0, axes=(), axis_names=())
    fr = r.child("force")
    force_channels = fr.get("channels", kind=list)
    if not force_channels:
        raise fr.error("channels", "needs at least one force channel")
    force = ForceSpec(tuple(force_channels), fr.number("n_per_count", positive=True), fr.number("rate_hz", positive=True))
    fr.check_unknown()
    correlate = r.get("correlate", "each_with_all", str)
    if correlate not in ("each_with_all", "pairwise"):
        raise r.error("correlate", f"must be 'each_with_all' or 'pairwise', got {correlate!r}")
    if correlate == "pairwise" and vib.axes and len(vib.axes) != len(dfm.axes):
        raise r.error("correlate", "'pairwise' needs as many vibration axes as deformation axes")
    if vib.rate_hz < dfm.rate_hz:
        raise r.error("vibration", "the vibration modality must be the faster one (it is the time base for correlations)")
    extra = r.get("extra_channels", [], list)
    if not all(isinstance(c, str) and c for c in extra):
        raise r.error("extra_channels", "needs a list of channel names")
    r.get("sites", None)  # sensing sites: read with the geometry (core.geometry.parse_sites)
    known = set(vib.channels) | set(dfm.channels)
    for i, ch in enumerate(extra):
        if ch in known or ch in extra[:i]:
            raise r.error("extra_channels", f"channel {ch!r} is already declared")
    r.check_unknown()
    return CellType(name, vib, dfm, force, correlate, tuple(extra))
